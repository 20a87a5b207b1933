"""What a section's choice is worth: counterfactual replays of one section's other choice, on common random
numbers, for learning a TampingLine planner by policy improvement.

Why. A line's cost is almost a sum over its sections (each is its own physics segment; only the possession of
a campaign is shared), and an episode is a deterministic function of its seed and its actions. So the value of
one section's choice at one step can be *measured*: run a policy on the line, and at a step ``t`` fork one
section's segment, make the other choice, and let the same policy go on deciding for that section (the other
sections as they were) to the horizon. The difference of the two costs-to-go is one exact sample of the
advantage of tamping now over waiting, with the same future (wet-spot onsets, tamping residuals, measurement
errors) on both branches, so none of the noise of the other eleven sections and little of the section's own.
A learner fitted to prefer the cheaper choice in the states it sees is one step of approximate policy iteration
(the greedy improvement of the policy that generated the data; with the data of each new policy added, as
AggreVaTe does with an expert's cost-to-go).

:func:`section_counterfactuals` runs a policy on some episodes, forks the chosen (step, section) decisions and
prices both choices; the samples carry the features the learner sees
(:func:`trackenv_agents.learning.line_policy.section_features`). Costs are k€ from the step to the horizon: the
section's own (tamping or renewal, geometry, speed restriction, immediate action; ``info["section_costs"]``)
plus the possession wherever the section tamps in a step no other section of its line tamps (its marginal
possession). Approximation: the other sections keep what they did on the policy's run (a fork does not move
their campaigns), and a fork ignores the annual budget (the default line has none).

**With every choice** (a config whose action type is the choice codes,
:func:`~trackenv.envs.choices.action_type_for`) a decision priced is one choice of
:data:`~trackenv_agents.learning.line_policy.LEARNABLE_CHOICES` made or not (``choices``: which are priced):

* ``"tamp"``: the policy's tamping (a tamping or a renewal) against its absence; the section's other choice in
  the fork is what the advisor makes of that (:func:`~trackenv_agents.learning.line_policy.compose_choices`:
  without the tamping, the rule's spot tamping, inspection or survey stand);
* ``"spot_tamp"``: a spot tamping against waiting (the rule's inspection or survey, else nothing), where the
  section is neither tamped nor drained;
* ``"drainage"``: a drainage against waiting, whatever else the section got (a drainage comes before a tamping).

Decisions that the flip does not change (the rule drains the section either way) are not priced. Forks apply
every choice as the env does (spot tamping, drainage, surveys, inspections at the end of the step) and pay each
its price. A policy with a recurrent state per section (the choice rules' memory of their track work,
(batch, k, S)) gets its own on each fork: the line's, with the fork's section's own.

A section's possession is its marginal one: what the line's possession of the step costs with the section's
choice over what it costs with nothing there, by the env's rule (a step with spot tamping alone pays
``spot_possession_share`` of it: :func:`~trackenv.envs.choices.spot_only_steps`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["flipped_choices", "marginal_possession", "section_counterfactuals"]


def marginal_possession(config: Any, codes: np.ndarray, lines: np.ndarray, sections: np.ndarray,
                        own: np.ndarray) -> np.ndarray:
    """(n,) k€: the possession that line ``lines[i]`` of the step's action ``codes`` (n_lines, S) pays with the
    choice ``own[i]`` on its section ``sections[i]``, beyond what it pays with nothing there (the other sections
    as in ``codes``): the whole possession, or ``spot_possession_share`` of it in a step with spot tamping alone
    (:func:`~trackenv.envs.choices.spot_only_steps`, the env's rule), or none while no section works."""
    from trackenv.envs.choices import NOTHING, step_possession

    at = np.arange(len(lines))
    rows = np.array(codes, dtype=np.int64)[lines]
    rows[at, sections] = own
    paid = step_possession(config, rows)
    rows[at, sections] = NOTHING
    return paid - step_possession(config, rows)


def flipped_choices(choice: str, codes: np.ndarray, advice: np.ndarray | None) -> np.ndarray:
    """The action codes with the decision ``choice`` (one of
    :data:`~trackenv_agents.learning.line_policy.LEARNABLE_CHOICES`) of the policy's ``codes`` turned the other
    way, the rest kept (``advice``: the advisor's codes, None: none; see the module docstring); equal to
    ``codes`` where the flip changes nothing."""
    from trackenv.envs.choices import DRAINAGE, INSPECT, NOTHING, SPOT_TAMP, SURVEY, TAMP

    from .line_policy import compose_choices, tamping_codes

    codes = np.asarray(codes, dtype=np.int64)
    acted = tamping_codes(codes)
    if choice == "tamp":
        if advice is None:
            return np.where(acted, NOTHING, TAMP)
        spot = (codes == SPOT_TAMP) | (acted & (advice == SPOT_TAMP))  # under a tamping: the rule's spot tamping
        return compose_choices(~acted, advice, spot, codes == DRAINAGE)
    waiting = np.where(np.isin(codes, (INSPECT, SURVEY)), codes, NOTHING)
    if advice is not None:
        waiting = np.where(np.isin(advice, (INSPECT, SURVEY)) & (waiting == NOTHING), advice, waiting)
    if choice == "spot_tamp":
        free = ~acted & (codes != DRAINAGE)
        return np.where(codes == SPOT_TAMP, waiting, np.where(free, SPOT_TAMP, codes))
    if choice == "drainage":
        return np.where(codes == DRAINAGE, waiting, DRAINAGE)
    raise ValueError(f"choice must be one of 'tamp', 'spot_tamp', 'drainage', got {choice!r}")


#: The share of ``other_rate`` at which a spot tamping is priced where nothing puts it in question (a low peak the
#: advisor leaves alone) [assumption]: it is almost always a waste there and a few samples teach the network that;
#: the forks go where the choice is open. (Drainage is asked about only where it is in question: ``choice_open``.)
OTHER_SHARE_BEYOND_TAMPING = 0.25


def _query_rates(features: np.ndarray, names: Sequence[str], acted: np.ndarray, focus_rate: float,
                 other_rate: float, choice: str = "tamp", advice: np.ndarray | None = None) -> np.ndarray:
    """(E, S) probability of pricing each decision: ``focus_rate`` where the choice is in question, ``other_rate``
    elsewhere (a plain section well within its limits: the learner still needs some of those). In question: the
    policy makes the choice; for the tamping, the section is a known zone or its projected SD or peak is high;
    for spot tamping, its projected peak is high or the advisor spot-tamps it; for drainage, a survey found it wet
    or the advisor drains it. Spot tamping and drainage are priced elsewhere at ``other_rate`` times
    :data:`OTHER_SHARE_BEYOND_TAMPING`."""
    from trackenv.envs.choices import DRAINAGE, SPOT_TAMP

    col = {n: i for i, n in enumerate(names)}
    x = features
    focus = acted.astype(bool)
    if choice == "tamp":
        focus = (focus | (x[..., col["plain"]] < 0.5) | (x[..., col["projected_sd_mm"]] * 2.0 >= 1.5)
                 | (x[..., col["projected_peak_mm"]] * 10.0 >= 8.0))
    elif choice == "spot_tamp":
        focus = focus | (x[..., col["projected_peak_mm"]] * 10.0 >= 6.0) | (advice == SPOT_TAMP)
    else:
        focus = focus | (x[..., col["surveyed_wet"]] > 0.5) | (advice == DRAINAGE)
    return np.where(focus, focus_rate, other_rate * (1.0 if choice == "tamp" else OTHER_SHARE_BEYOND_TAMPING))


def section_counterfactuals(config: Any, seeds: Sequence[int], policy: Any, advisor: Any = None,
                            focus_rate: float = 0.5, other_rate: float = 0.1, seed: int = 0,
                            progress: Callable[[int], Any] | None = None,
                            choices: Sequence[str] = ("tamp",),
                            choice_features: bool | None = None) -> dict[str, np.ndarray]:
    """Run ``policy`` (SB3 ``predict`` on batched line observations, deterministic; bound to ``config``) on the
    episodes ``seeds`` of ``config`` (one batch), and price the other way of a random subset of its decisions
    (each section, step and choice of ``choices`` (:func:`flipped_choices`) whose flip changes the section's code,
    that may get track work, whose other choice fits the possession's capacity with the line's other work and
    where the network decides the choice (:func:`~trackenv_agents.learning.line_policy.choice_open`), with
    probability ``focus_rate`` or ``other_rate``, see :func:`_query_rates`;
    drawn from ``seed``) by a fork continued under ``policy`` itself. ``choice_features``: the samples' features
    end with the choice features (:data:`~trackenv_agents.learning.line_policy.CHOICE_FEATURES`; None: where
    ``choices`` go beyond ``("tamp",)``), which need a choice rule as ``advisor``.

    Returns arrays over the priced decisions: ``features`` (N, F) as the learner sees the section then (with
    ``advisor``'s choice as the last features and, with the choice features, the choice asked about; see
    :func:`~trackenv_agents.learning.line_policy.section_features`), ``choice`` (the index in ``choices`` of the
    choice priced), ``q_do`` and ``q_skip`` (k€ to the horizon for making that choice now and for not making it,
    each then under ``policy``), ``did`` (the policy's choice: it made it), ``weight`` (1 / the probability of
    pricing it: sums over the samples estimate sums over every decision), ``seed``, ``step``, ``section``."""
    from gymnasium.vector import AutoresetMode

    from trackenv.envs.choices import (
        INSPECT,
        IS_TRACK_WORK,
        NOTHING,
        action_type_for,
        work_on_sections,
        work_per_code,
    )
    from trackenv.envs.line import TampingLineVectorEnv
    from trackenv.envs.line_episode import LineBatch

    from ..evaluation.harness import bind_policy
    from ..rules.choices import choice_view, remember_work
    from .line_policy import (
        ADVISOR_FEATURES,
        CHOICE_FEATURES,
        FEATURES,
        LEARNABLE_CHOICES,
        choice_open,
        section_features,
    )

    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must not be empty")
    for name, rate in (("focus_rate", focus_rate), ("other_rate", other_rate)):
        if not 0.0 < rate <= 1.0:
            raise ValueError(f"{name} must be in (0, 1], got {rate!r}")
    choices = tuple(choices)
    if not choices or not set(choices) <= set(LEARNABLE_CHOICES) or len(set(choices)) < len(choices):
        raise ValueError(f"choices must name distinct choices of {list(LEARNABLE_CHOICES)}, got {choices!r}")
    extended = choices != ("tamp",) if choice_features is None else bool(choice_features)
    if (extended or choices != ("tamp",)) and advisor is None:
        raise ValueError(f"pricing the choices {choices!r} with the choice features needs a choice rule as advisor")
    c = config
    E, S, H = len(seeds), c.n_sections, c.horizon_steps
    policy = bind_policy(policy, c)
    advisor = None if advisor is None else bind_policy(advisor, c)
    names = [n for n, _ in FEATURES] + (list(ADVISOR_FEATURES) + list(CHOICE_FEATURES) if extended else [])
    rng = np.random.default_rng(seed)
    env = TampingLineVectorEnv(E, c, autoreset_mode=AutoresetMode.NEXT_STEP, action_type=action_type_for(c))
    obs, _ = env.reset(seed=seeds)
    base = env.batch
    room = E * H * len(choices)  # room for every decision of every episode to be priced
    forks = LineBatch(c, room)
    n_forks = 0
    f_line, f_sec, f_step, f_first = (np.zeros(room * S, dtype=np.int64) for _ in range(4))
    f_cost = np.zeros(room * S)
    f_memory: np.ndarray | None = None  # each fork's own recurrent state of its section (a policy with one)
    state: Any = None
    base_cost = np.zeros((H, E, S))  # the policy's own run, per step and section (marginal possession)
    samples: dict[str, list] = {k: [] for k in ("features", "choice", "did", "weight", "row", "valid")}
    every = (np.repeat(np.arange(E), S), np.tile(np.arange(S), E))  # (line, section) of every section
    work, lengths = work_per_code(c.choice_work), c.length_factors
    for t in range(H):
        start = np.full(E, t == 0)
        before = state
        codes, state = policy.predict(obs, state=before, episode_start=start)
        codes = np.asarray(codes, dtype=np.int64).reshape(E, S)
        per_section = isinstance(state, np.ndarray) and state.ndim == 3 and state.shape[::2] == (E, S)
        if per_section and f_memory is None:
            f_memory = np.zeros((room * S, state.shape[1]))
        advice = None if advisor is None else np.asarray(
            advisor.predict(obs, state=before, episode_start=start)[0], dtype=np.int64).reshape(E, S)
        allowed = base.allowed().reshape(E, S)
        peak = choice_view(obs)["section_peak"]
        line_work = work_on_sections(work, codes, lengths).sum(axis=1, keepdims=True)
        open_ = {name: np.ones((E, S), bool) if advice is None else choice_open(name, obs, advice) for name in choices}
        new_rows = []
        for k, choice in enumerate(choices):
            feats = section_features(obs, advisor, advice, choice if extended else None)
            other = flipped_choices(choice, codes, advice)
            did = _made(choice, codes)
            rate = _query_rates(feats, names, did, focus_rate, other_rate, choice, advice)
            # the other choice must fit the step's possession with the line's other track work (the env's capacity)
            fits = line_work - work_on_sections(work, codes, lengths) + work_on_sections(work, other, lengths) \
                <= c.capacity + 1e-9
            ask = allowed & fits & open_[choice] & (other != codes) & (rng.random((E, S)) < rate)
            # forks of this step: copies of the sections as they are now, making the other choice
            b_new, j_new = np.nonzero(ask)
            new = np.arange(n_forks, n_forks + b_new.size)
            forks.copy_rows(new, base, b_new * S + j_new)
            f_line[new], f_sec[new], f_step[new] = b_new, j_new, t
            f_first[new] = other[b_new, j_new]
            if f_memory is not None and b_new.size:
                own = (np.full((b_new.size, f_memory.shape[1]), -np.inf) if before is None
                       else np.asarray(before)[b_new, :, j_new])
                f_memory[new] = remember_work(own[..., None], other[b_new, j_new, None], t,
                                              peak[b_new, j_new, None])[..., 0]
            samples["features"].append(feats[b_new, j_new])
            samples["choice"].append(np.full(b_new.size, k))
            samples["did"].append(did[b_new, j_new])
            samples["weight"].append(1.0 / rate[b_new, j_new])
            samples["row"].append(new)
            new_rows.append((new, b_new, j_new))
            n_forks += b_new.size
        new = np.concatenate([r[0] for r in new_rows])
        live = np.arange(n_forks)
        # every fork's choice now: its first one, or the policy's on the line as it is with the fork's section
        fork_codes = np.zeros(forks.n_lines * S, dtype=np.int64)
        fork_codes[new] = f_first[new]
        old = live[f_step[live] < t]
        if old.size:
            at = np.arange(old.size)
            seen = {k: np.asarray(v)[f_line[old]].copy() for k, v in obs.items()}
            for k, v in forks.section_entries(old, t).items():
                seen[k][at, f_sec[old]] = v
            seen_state = None
            if f_memory is not None:
                seen_state = np.asarray(before)[f_line[old]].copy()
                seen_state[at, :, f_sec[old]] = f_memory[old]
            choice_codes, seen_state = policy.predict(seen, state=seen_state,
                                                      episode_start=np.zeros(old.size, bool))
            choice_codes = np.asarray(choice_codes, dtype=np.int64)[at, f_sec[old]]
            fork_codes[old] = np.where(IS_TRACK_WORK[choice_codes] & ~forks.allowed_rows(t)[old], NOTHING,
                                       choice_codes)
            if f_memory is not None:
                f_memory[old] = np.asarray(seen_state)[at, :, f_sec[old]]
        if live.size:
            f_cost[live] += forks.choice_costs(fork_codes)[live]
            forks.work_rows(fork_codes, t)
            on = np.zeros(forks.n_lines * S, dtype=bool)
            on[live] = True
            forks.traffic_rows(on, t)
            f_cost[live] += forks.section_costs()[live]
            if (t + 1) % c.measurement_interval == 0:
                forks.measure_rows(on, t + 1)  # dates the sections' measurements, as the line's run
            forks.inspect_rows(fork_codes == INSPECT, t + 1)
        # the policy's own step
        obs, _, _, _, info = env.step(codes.astype(np.int8))
        applied = np.asarray(info["section_choices"], dtype=np.int64)
        # a choice the env did not carry out as asked (over capacity) is not the policy's: not a sample
        for _, b_new, j_new in new_rows:
            samples["valid"].append(applied[b_new, j_new] == codes[b_new, j_new])
        base_cost[t] = info["section_costs"] + marginal_possession(c, applied, *every, applied.ravel()).reshape(E, S)
        f_cost[live] += marginal_possession(c, applied, f_line[live], f_sec[live], fork_codes[live])
        if progress is not None:
            progress(1)
    to_go = np.cumsum(base_cost[::-1], axis=0)[::-1]  # (H, E, S): the policy's cost from each step on
    valid = np.concatenate(samples["valid"]).astype(bool)
    rows = np.concatenate(samples["row"]).astype(np.int64)[valid]
    did = np.concatenate(samples["did"]).astype(bool)[valid]
    q_policy = to_go[f_step[rows], f_line[rows], f_sec[rows]]
    q_other = f_cost[rows]
    return {"features": np.concatenate(samples["features"]).astype(np.float32)[valid],
            "choice": np.concatenate(samples["choice"]).astype(np.int64)[valid],
            "q_do": np.where(did, q_policy, q_other), "q_skip": np.where(did, q_other, q_policy),
            "did": did, "weight": np.concatenate(samples["weight"])[valid],
            "seed": np.asarray(seeds)[f_line[rows]], "step": f_step[rows], "section": f_sec[rows]}


def _made(choice: str, codes: np.ndarray) -> np.ndarray:
    """Bool, shaped like ``codes``: the sections whose codes make the choice ``choice`` (a tamping: a tamping or a
    renewal)."""
    from trackenv.envs.choices import DRAINAGE, SPOT_TAMP

    from .line_policy import tamping_codes

    if choice == "tamp":
        return tamping_codes(codes)
    return np.asarray(codes) == (SPOT_TAMP if choice == "spot_tamp" else DRAINAGE)
