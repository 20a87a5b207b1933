"""The per-section policy of TampingLine: one small network decides for every section, from its features.

Why this shape. A line's step is one decision per section, and almost all of a section's costs are its own:
its geometry, speed restrictions, immediate actions, tamping and renewal depend only on its own schedule (the
sections are physically independent); only the possession of a campaign is shared. So one network with shared
weights decides for every section, from that section's features and a summary of the line: the policy learns
one rule for a section, runs on lines of any length (the small, default and hard scenarios: 6, 12 and 24
sections), and a learner can credit each section's choice with that section's own costs (see
:class:`trackenv_agents.learning.sb3_vec.SectionAgentsVecEnv` and :mod:`trackenv_agents.learning.line_counterfactual`).

* :func:`section_features` — the (batch, S, F) features of a batched line observation: the section's measured
  state and what the measurement history says beyond it (whether it was tamped since the recording run, its
  growth since its last tamping, its SD and peak projected to now), its register and tamping history, the
  line's context (time, measurement age, the other sections' projected SD: whether a campaign is likely to be
  called anyway), each over a fixed scale and clipped, so the policy does not depend on the line it was trained
  on; and optionally a rule's choice (an *advisor*: the learner has the rule exactly and learns where to depart
  from it).
* :class:`LineAgent` — a trained section policy (any SB3 policy over these features with ``Discrete(2)``
  actions) with SB3's ``predict`` on raw line observations: it tamps the sections whose probability of tamping
  is above one half, never one the env would drop, at most ``capacity`` (the most probable). With a choice rule
  as its advisor (:data:`~trackenv_agents.rules.choices.CHOICE_RULES`) it answers in choice codes: the network
  decides where and when to tamp, the rule the other choices (:func:`compose_choices`); a network trained with
  the choice features (:data:`CHOICE_FEATURES`) also decides spot tamping and drainage
  (:data:`LEARNABLE_CHOICES`), asked about each choice in turn.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from trackenv.envs.choices import (
    DRAINAGE,
    INSPECT,
    NOTHING,
    RENEW,
    SPOT_TAMP,
    SURVEY,
    TAMP,
)
from trackenv.envs.line_config import LineConfig
from trackenv.physics._checks import check_scalar

from ..rules.base import as_batch
from ..rules.choices import fresh_memory, remember_work
from ..rules.line import FRESH_SD_MM, projected_geometry, stale_measurement

__all__ = ["ADVISOR_FEATURES", "CHOICE_FEATURES", "FEATURES", "FEATURE_CLIP", "FRESH_SD_MM", "LEARNABLE_CHOICES",
           "LineAgent", "choice_open", "compose_choices", "is_choice_rule", "may_tamp", "n_features", "remember_work",
           "section_features", "tamping_codes"]

#: Features are clipped to [0, FEATURE_CLIP] after scaling: typical values are O(1), and a rare extreme (a wet
#: spot at 19 mm of SD, a section untended for 12 years) must not drive the network far beyond its training data.
FEATURE_CLIP = 4.0
#: The features, in order, with the scale each is divided by (mm, years, counts; fractions as they are).
FEATURES: tuple[tuple[str, float], ...] = (
    ("measured_sd_mm", 2.0),
    ("measured_peak_mm", 10.0),
    ("stale", 1.0),  # tamped since the recording run: the measurement predates the tamping
    ("growth_mm_per_year", 1.0),  # SD growth since the last tamping, as measured (0 where stale)
    ("projected_sd_mm", 2.0),  # measured SD + growth × measurement age (the fresh SD where stale)
    ("projected_peak_mm", 10.0),  # measured peak scaled like the SD
    ("plain", 1.0), ("transition", 1.0), ("switch_or_crossing", 1.0),
    ("tampings_since_renewal", 8.0),
    ("renewal_due", 1.0),  # the next intervention is a ballast renewal (8 tampings since the last)
    ("tampings", 4.0),
    ("years_since_tamping", 4.0),
    ("time", 1.0),
    ("measurement_age_years", 1.0),
    ("budget_left", 1.0),
    ("line_max_other_projected_sd_mm", 2.0),  # the worst other section: will a campaign be called anyway?
    ("line_mean_projected_sd_mm", 2.0),
    ("line_share_projected_above_2mm", 1.0),
    ("line_share_projected_above_3mm", 1.0),
)
RENEWAL_AFTER = 8  # TampingModel.max_tampings_before_renewal's default; a feature, not a rule of the env


#: With an advisor, two more features, last: whether it tamps the section now, and whether it calls a campaign
#: now (tamps any section of the line). A choice rule's renewal is a tamping here (it replaces the tamping a
#: campaign gives the section); its other choices are not.
ADVISOR_FEATURES = ("advisor_tamps", "advisor_campaign")

#: The choices a network with the choice features decides (the tamping first; inspections, surveys and, where
#: the tamping falls due, the renewal stay the advisor's). Why these: spot tamping and drainage are where the
#: money of the lines with every choice lies besides the tamping (the documentation's choices page).
LEARNABLE_CHOICES = ("tamp", "spot_tamp", "drainage")
#: With the choice features, five more, after the advisor's: the advisor spot-tamps the section now, it drains the
#: section now, a survey found the section wet; and which choice the network is asked about (one-hot over the
#: choices of :data:`LEARNABLE_CHOICES` after the tamping; both 0: the tamping). One network with the choice as
#: an input answers for every choice (the data of each choice is little; the section's state is shared), and a
#: network trained on the tamping alone carries over with zero weights on the new inputs.
CHOICE_FEATURES = ("advisor_spot_tamps", "advisor_drains", "surveyed_wet", "asks_spot_tamp", "asks_drainage")


def tamping_codes(codes: np.ndarray) -> np.ndarray:
    """Bool, shaped like ``codes`` (action codes, or a tamp-or-wait 0/1 action): the tamping kind of track work,
    a tamping or a ballast renewal (which replaces the tamping of the section)."""
    return np.isin(np.asarray(codes), (TAMP, RENEW))


def is_choice_rule(rule: Any) -> bool:
    """Whether ``rule`` is one of the choice rules (:data:`~trackenv_agents.rules.choices.CHOICE_RULES`), which
    answer in choice codes and remember their own track work in SB3's recurrent ``state``."""
    from ..rules.choices import CHOICE_RULES

    return getattr(rule, "name", None) in CHOICE_RULES


def compose_choices(tamp: np.ndarray, advice: np.ndarray, spot: np.ndarray | None = None,
                    drain: np.ndarray | None = None) -> np.ndarray:
    """The action codes of a section policy that decides where and when to tamp (``tamp``, bool) with an advisor
    rule's choice codes ``advice`` (same shape) for the rest, by the rule's own precedence (the choice rules'
    ``_wanted``): a drainage the rule asks for stands whatever the tamping decision (it comes before a tamping
    there); a renewal stands where the policy tamps (it replaces that tamping) and lapses where it waits; the
    rule's spot tamping, inspection and survey stand where the policy waits (the rule gives them only to
    sections it does not tamp) and give way to the policy's tamping; the rule's own tamping lapses where the
    policy waits. ``spot`` and ``drain`` (bool, same shape): the policy's own spot tamping and drainage in place
    of the rule's (None: the rule's), with the same precedence (drainage, then the tamping, then spot tamping,
    then the rule's inspection or survey). Requests only: masks and the possession's capacity come after
    (:meth:`LineAgent.predict`)."""
    tamp = np.asarray(tamp, dtype=bool)
    advice = np.asarray(advice, dtype=np.int64)
    drain = advice == DRAINAGE if drain is None else np.asarray(drain, dtype=bool)
    spot = advice == SPOT_TAMP if spot is None else np.asarray(spot, dtype=bool)
    looks = np.where(np.isin(advice, (INSPECT, SURVEY)), advice, NOTHING)
    when_waiting = np.where(spot, SPOT_TAMP, looks)
    return np.where(drain, DRAINAGE, np.where(tamp, np.where(advice == RENEW, RENEW, TAMP), when_waiting))


def choice_open(choice: str, obs: Mapping[str, Any], advice: np.ndarray) -> np.ndarray:
    """(batch, S) bool: where the network decides the choice ``choice`` (:data:`LEARNABLE_CHOICES`); elsewhere the
    advisor's answer stands. The tamping and spot tamping: everywhere. Drainage: where a survey found the section
    wet or the advisor drains it, the sections where drainage is in question: elsewhere a drainage removes no wet
    cause, and as it comes before the tamping, one asked in a section the forks seldom priced would take the
    place of a tamping."""
    advice = np.asarray(advice)
    if choice != "drainage":
        return np.ones(advice.shape, dtype=bool)
    survey = np.asarray(obs.get("section_survey", np.full(advice.shape, -1))).reshape(advice.shape)
    return (survey == 1) | (advice == DRAINAGE)


def n_features(advisor: Any = None, choices: bool = False) -> int:
    """How many features :func:`section_features` gives (two more with an advisor, and five more with the choice
    features)."""
    return (len(FEATURES) + (len(ADVISOR_FEATURES) if advisor is not None else 0)
            + (len(CHOICE_FEATURES) if choices else 0))


def section_features(obs: Mapping[str, Any], advisor: Any = None, advice: np.ndarray | None = None,
                     ask: str | None = None) -> np.ndarray:
    """(batch, S, :func:`n_features`) float32 features of a batched TampingLine observation (see the module
    docstring and :data:`FEATURES`). ``advisor``: a rule bound to the line's config (SB3 ``predict``) whose
    choice is two more features, last (:data:`ADVISOR_FEATURES`: it tamps the section now; it calls a campaign
    now): a learner then has the rule exactly and learns where to depart from it (residual policy learning).
    ``advice``: the advisor's (batch, S) codes where the caller has them already (a rule with a recurrent
    state answers with it: :meth:`LineAgent.predict`); else they are asked of ``advisor`` on ``obs`` alone.
    ``ask``: a choice of :data:`LEARNABLE_CHOICES` (with an advisor): the choice features follow
    (:data:`CHOICE_FEATURES`), asking about that choice; None: none."""
    o = {k: np.asarray(v, dtype=np.float64) for k, v in obs.items()}
    sd, peak = o["section_sd"], o["section_peak"]
    B, S = sd.shape
    age = o["measurement_age"].reshape(B, 1)
    stale = np.asarray(stale_measurement(o), dtype=bool)
    growth, projected, projected_peak = projected_geometry(o)
    reg = np.rint(o["register"]).astype(int).clip(0, 2)
    count = o["tampings_since_renewal"]
    # the worst projected SD among the *other* sections: the largest, or the second largest for the worst one
    top2 = -np.sort(-projected, axis=1)[:, :2] if S > 1 else np.concatenate([projected, np.zeros((B, 1))], 1)
    other_max = np.where(projected >= top2[:, :1], top2[:, 1:2], top2[:, :1])
    cols = [
        sd, peak, stale, growth, projected, projected_peak,
        reg == 0, reg == 1, reg == 2,
        count, count >= RENEWAL_AFTER, o["tampings"], o["years_since_tamping"],
        np.broadcast_to(o["time"].reshape(B, 1), (B, S)),
        np.broadcast_to(age, (B, S)),
        np.broadcast_to(o["budget_left"].reshape(B, 1), (B, S)),
        other_max,
        np.broadcast_to(projected.mean(axis=1, keepdims=True), (B, S)),
        np.broadcast_to((projected >= 2.0).mean(axis=1, keepdims=True), (B, S)),
        np.broadcast_to((projected >= 3.0).mean(axis=1, keepdims=True), (B, S)),
    ]
    scales = np.array([s for _, s in FEATURES])
    x = np.stack([np.asarray(c, dtype=np.float64) for c in cols], axis=-1) / scales
    if advisor is not None:
        if advice is None:
            advice = np.asarray(advisor.predict({k: np.asarray(v) for k, v in obs.items()})[0])
        tamps = tamping_codes(advice).reshape(B, S).astype(np.float64)
        campaign = np.broadcast_to(tamps.max(axis=1, keepdims=True), (B, S))
        x = np.concatenate([x, tamps[..., None], campaign[..., None]], axis=-1)
        if ask is not None:
            if ask not in LEARNABLE_CHOICES:
                raise ValueError(f"ask must be one of {list(LEARNABLE_CHOICES)} or None, got {ask!r}")
            advice = np.asarray(advice).reshape(B, S)
            wet = np.asarray(obs.get("section_survey", np.full((B, S), -1))).reshape(B, S) == 1
            asks = [np.full((B, S), float(ask == name)) for name in LEARNABLE_CHOICES[1:]]
            x = np.concatenate([x, np.stack([advice == SPOT_TAMP, advice == DRAINAGE, wet, *asks], axis=-1)], axis=-1)
    elif ask is not None:
        raise ValueError("the choice features (ask) need an advisor")
    return np.clip(x, 0.0, FEATURE_CLIP).astype(np.float32)


def may_tamp(obs: Mapping[str, Any], config: LineConfig) -> np.ndarray:
    """(batch, S) bool: the sections of a batched line observation that the env would tamp if asked, as far as
    the observation tells: not tamped within the config's ``min_steps_between_tampings`` (the env's action mask,
    read from ``years_since_tamping``)."""
    gap = config.min_steps_between_tampings / config.steps_per_year  # years: tamped since then, masked
    return np.asarray(obs["years_since_tamping"]) > gap + 1e-3


class LineAgent:
    """A trained section policy (an SB3 policy over :func:`section_features`, ``Discrete(2)`` actions) with SB3's
    ``predict(obs, state=None, episode_start=None, deterministic=True) -> (action, state)`` on raw TampingLine
    observations (one dict or a batched one) of a line of any length: int8 0/1 per section. Deterministic: the
    sections whose probability of tamping is above one half; otherwise each drawn with its probability (``rng``:
    a numpy Generator; None: a fresh unseeded one). Bound to a config (:meth:`bind`, as the evaluation harness
    does), never a section tamped within the config's ``min_steps_between_tampings`` (the env would drop it) and
    at most ``capacity`` sections, the most probable. ``horizon_years``: the episode length it was trained on
    (its ``time`` feature is the share of that horizon gone), where known.

    **Choice mode**: with a choice rule as ``advisor`` (:func:`is_choice_rule`) the agent answers in choice codes
    (:data:`trackenv.envs.choices.CHOICES`): where and when to tamp from its network, spot tamping, drainage,
    renewal, inspections and surveys from the rule (:func:`compose_choices`). Bound to a config, the advisor is
    the rule with that config's tuned parameters (:func:`~trackenv_agents.rules.tuned_params_for`; the rule's
    defaults where none ship, e.g. on a tamping-only id, whose config enables tamping only). The rule's recurrent
    state, its memory of each section's track work (the step of its last track work and last spot tamping, and
    its measured peak when last tamped), is the agent's ``state``, kept for the codes the agent asks for rather
    than for the rule's own. The agent asks for no track work that the env would drop (within
    ``min_steps_between_tampings`` of the section's last) and fits the step's work in ``capacity``, worst measured
    SD first as the env does, so the env applies its codes as asked.

    With a planner whose recurrent state records what it was shown as ``advisor`` (:attr:`observation_state`:
    the model-predictive planner of the 60 m track, which forecasts from the SD history), that state is the
    agent's ``state``, and the planner sees every step's observation whatever the network chose.

    ``choice_features``: the network was trained with the choice features (:data:`CHOICE_FEATURES`; a choice
    rule as advisor); ``learned``: the choices of :data:`LEARNABLE_CHOICES` it decides, each asked in turn, in
    place of the rule's (the tamping always; spot tamping and drainage where listed, which needs the choice
    features), each where :func:`choice_open` opens it.

    ``preset_policies``: networks of the same features and advisor trained on some shipped presets, by preset name
    (:data:`~trackenv.envs.line_config.SCENARIOS`): bound to a config that is one of them
    (:func:`~trackenv_agents.rules.problems.preset_of`), the agent plays that preset's network, elsewhere
    ``policy``. Why: a network trained on the line it runs on can do better there than one trained elsewhere
    (the short-defect line: the documentation's agents page)."""

    def __init__(self, policy: Any, name: str = "ppo", config: LineConfig | None = None,
                 rng: np.random.Generator | None = None, advisor: Any = None,
                 horizon_years: float | None = None, choice_features: bool = False,
                 learned: tuple[str, ...] = ("tamp",), preset_policies: Mapping[str, Any] | None = None) -> None:
        learned = tuple(learned)
        if learned[:1] != ("tamp",) or not set(learned) <= set(LEARNABLE_CHOICES):
            raise ValueError(f"learned must start with 'tamp' and name choices of {list(LEARNABLE_CHOICES)}, "
                             f"got {learned!r}")
        if (choice_features or learned != ("tamp",)) and not (choice_features and is_choice_rule(advisor)):
            raise ValueError("choice_features needs a choice rule as advisor, and learned choices beyond 'tamp' "
                             f"need choice_features=True (advisor {getattr(advisor, 'name', None)!r}, "
                             f"choice_features={choice_features!r}, learned={learned!r})")
        self.choice_features, self.learned = bool(choice_features), learned
        self.default_policy = policy
        self.preset_policies = dict(preset_policies or {})
        self.policy = self._policy_for(config)
        self.name = name
        self.config = config
        self.choices = is_choice_rule(advisor)
        if advisor is not None and config is not None:
            advisor = _tuned_choice_rule(advisor.name, config) if self.choices else advisor.bind(config)
        self.advisor = advisor
        self.params: dict[str, Any] = {}
        self._rng = rng
        self.horizon_years = horizon_years

    @property
    def observation_state(self) -> bool:
        """Whether the agent has a recurrent state that remembers only what it was shown, never what it chose: its
        advisor's, where that is a planner such as :class:`~trackenv_agents.rules.ModelPredictive` (outside choice
        mode). A copy of a line may then carry the state on while it makes other choices (the line forks of the
        policy iteration)."""
        return not self.choices and bool(getattr(self.advisor, "observation_state", False))

    def unfit_for(self, config: Any) -> str | None:
        """Why the agent cannot run on ``config`` (None where it can): its advisor's reason, where the advisor is
        a planner that plans some configs only (the model-predictive planner needs an SD measured every step)."""
        check = getattr(self.advisor, "unfit_for", None)
        return check(config) if callable(check) else None

    def bind(self, config: LineConfig) -> LineAgent:
        """This agent with ``config``'s possession capacity and tamping gap (and its advisor bound to it: in
        choice mode, the config's tuned choice rule), playing the network of ``config``'s preset where it has one
        (``preset_policies``)."""
        return LineAgent(self.default_policy, self.name, config, self._rng, self.advisor, self.horizon_years,
                         self.choice_features, self.learned, self.preset_policies)

    def _policy_for(self, config: LineConfig | None) -> Any:
        """The network the agent plays on ``config``: its preset's where ``preset_policies`` has one, else the
        default."""
        if config is None or not self.preset_policies:
            return self.default_policy
        from ..rules.problems import preset_of

        return self.preset_policies.get(preset_of(config) or "", self.default_policy)

    def tamp_probability(self, obs: Mapping[str, Any], advice: np.ndarray | None = None,
                         ask: str = "tamp") -> np.ndarray:
        """(batch, S) probability of tamping each section (batched observation dict of numpy arrays; ``advice``:
        the advisor's codes where the caller has them, see :func:`section_features`); with the choice features,
        of making the choice ``ask`` (:data:`LEARNABLE_CHOICES`)."""
        import torch

        x = section_features(obs, self.advisor, advice, ask if self.choice_features else None)
        B, S, F = x.shape
        self.policy.set_training_mode(False)
        with torch.no_grad():
            t = torch.as_tensor(x.reshape(B * S, F), device=self.policy.device)
            p = self.policy.get_distribution(t).distribution.probs[:, 1]
        return p.cpu().numpy().reshape(B, S)

    def requests(self, observation: Mapping[str, Any], probability: float = 0.5) -> np.ndarray:
        """(batch, S) bool: the sections it asks to tamp when it asks from ``probability`` up instead of above one
        half (a batched observation dict), never one the env would drop and at most ``capacity``, the most
        probable, where bound to a config. What a network lets it do while the machine is on its line
        (:class:`~trackenv_agents.rules.network.NetworkRule`'s ``eager_probability``): tamp now what it would ask
        for soon. Deterministic; not for an agent whose advisor keeps a state (ValueError)."""
        probability = check_scalar("probability", probability, low=0.0, high=1.0, low_inclusive=False)
        if self.observation_state:
            raise ValueError(f"{self.name}: requests() asks the network without the advisor's state, which this "
                             f"agent's advisor ({getattr(self.advisor, 'name', None)}) keeps")
        b, _ = as_batch(dict(observation))
        p = self.tamp_probability(b)
        return self._as_the_env_takes(p >= probability, p, b)

    def _as_the_env_takes(self, want: np.ndarray, p: np.ndarray, obs: Mapping[str, Any]) -> np.ndarray:
        """``want`` without the sections the env would drop and cut to the capacity, the most probable first, where
        bound to a config (else as it is)."""
        if self.config is None:
            return want
        from trackenv.envs.line_episode import keep_worst

        return keep_worst(want & may_tamp(obs, self.config), p, self.config.capacity)

    def _wants(self, p: np.ndarray, deterministic: bool) -> np.ndarray:
        if deterministic:
            return p > 0.5
        if self._rng is None:
            self._rng = np.random.default_rng()
        return self._rng.random(p.shape) < p

    def predict(self, observation: Mapping[str, Any], state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        b, batched = as_batch(dict(observation))
        if self.choices:
            act, state = self._predict_choices(b, state, episode_start, deterministic)
        else:
            advice = None
            if self.observation_state:  # the advisor's recurrent state, a record of what it was shown, is the agent's
                advice, state = self.advisor.predict(b, state=state, episode_start=episode_start)
                advice = np.asarray(advice, dtype=np.int64)
            p = self.tamp_probability(b, advice)
            act = self._as_the_env_takes(self._wants(p, deterministic), p, b).astype(np.int8)
        return (act if batched else act[0]), state

    def _predict_choices(self, b: dict[str, np.ndarray], state: Any, episode_start: Any,
                         deterministic: bool) -> tuple[np.ndarray, np.ndarray]:
        """Choice mode: (batch, S) int8 codes and the advisor's memory of the track work asked for."""
        from ..rules.choices import choice_view

        c = self.config
        if c is None:
            raise ValueError("a line agent with a choice rule as advisor answers once bound to a config (bind)")
        n, S = b["section_sd"].shape
        memory = fresh_memory(state, episode_start, n, S)
        advice = np.asarray(self.advisor.predict(b, state=memory)[0], dtype=np.int64)  # its own memory: not kept
        wants = {name: self._wants(self.tamp_probability(b, advice, name), deterministic) & may_tamp(b, c)
                 for name in self.learned}
        if "drainage" in wants:  # where drainage is not in question, the advisor's answer (no drainage)
            wants["drainage"] = np.where(choice_open("drainage", b, advice), wants["drainage"], advice == DRAINAGE)
        step = np.rint(np.asarray(b["time"], dtype=float)[:, 0] * c.horizon_steps)
        wanted = compose_choices(wants["tamp"], advice, wants.get("spot_tamp"), wants.get("drainage"))
        codes = self.advisor.allowed(wanted, b, step, memory[:, 0])  # as the env applies them
        return codes.astype(np.int8), remember_work(memory, codes, step[:, None], choice_view(b)["section_peak"])

    def reset(self) -> None:
        """Nothing to forget: the policy is stateless (in choice mode its memory, with a planner advisor the
        planner's history, is SB3's ``state``)."""


def _tuned_choice_rule(name: str, config: LineConfig) -> Any:
    """The choice rule ``name`` with ``config``'s tuned parameters (its defaults where none ship), bound to it."""
    from ..rules import tuned_params_for
    from ..rules.choices import CHOICE_RULES

    return CHOICE_RULES[name](**tuned_params_for(config).get(name, {})).bind(config)

