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

**Where sections share a physics segment** (``sections_per_segment`` > 1, e.g. the 60 m track, ``"track60"``, six
10 m sections on one segment) a section's tamping lifts its neighbours' track too, so a section cannot be forked
alone. There a decision priced forks its **whole line** (:func:`line_forks`: an exact copy of the line's state and
pre-drawn noise, so both branches see the same future draws): the fork makes the other choice on the section and
the policy's choices on the line's other sections at that step, then the policy decides every section of the fork
from the next step on (its campaigns may move). Both choices are priced at the whole line's cost to go: every
section's costs and the possession, as the env charges them (the annual budget included). The same decisions are
drawn, at the same rates, as one-section forks would draw; a policy with a recurrent state is refused there (a
fork could not tell what it remembers of the other choice).

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

__all__ = ["flipped_choices", "line_forks", "marginal_possession", "section_counterfactuals"]


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
    for name, value in (("focus_rate", focus_rate), ("other_rate", other_rate)):
        if not 0.0 < value <= 1.0:
            raise ValueError(f"{name} must be in (0, 1], got {value!r}")
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
    if c.sections_per_segment > 1:
        return _line_fork_counterfactuals(c, seeds, policy, advisor, choices, extended, names, focus_rate, other_rate,
                                          seed, progress)
    rng = np.random.default_rng(seed)
    env = TampingLineVectorEnv(E, c, autoreset_mode=AutoresetMode.NEXT_STEP, action_type=action_type_for(c))
    obs, _ = env.reset(seed=seeds)
    base = env.batch
    assert base is not None  # made by the reset
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
        if state is not None and not per_section:
            raise ValueError("forks of single sections need a policy without a recurrent state or with one per "
                             f"section ((lines, memory, sections) array; got {type(state).__name__}): a section's "
                             "fork carries only its own section's memory")
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
            ask, other, did, rate = _asked(c, choice, codes, advice, feats, names, allowed & open_[choice], line_work,
                                           rng, focus_rate, other_rate)
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
            for key, v in forks.section_entries(old, t).items():
                seen[key][at, f_sec[old]] = v
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


def _asked(config: Any, choice: str, codes: np.ndarray, advice: np.ndarray | None, features: np.ndarray,
           names: Sequence[str], may_ask: np.ndarray, line_work: np.ndarray, rng: np.random.Generator,
           focus_rate: float, other_rate: float) -> tuple[np.ndarray, ...]:
    """Which decisions ``choice`` of the step's ``codes`` (E, S) to price: ``(ask, other, did, rate)``, each (E, S):
    the decisions drawn from ``rng`` at their rate (:func:`_query_rates`) among those ``may_ask`` allows whose flip
    (:func:`flipped_choices`) changes the code and fits the step's possession with the line's other track work
    (``line_work`` (E, 1): the step's work in tamping-section equivalents; the env's capacity); the other choice;
    whether the policy made the choice; the rate."""
    from trackenv.envs.choices import work_on_sections, work_per_code

    work, lengths = work_per_code(config.choice_work), config.length_factors
    other = flipped_choices(choice, codes, advice)
    did = _made(choice, codes)
    rate = _query_rates(features, names, did, focus_rate, other_rate, choice, advice)
    fits = line_work - work_on_sections(work, codes, lengths) + work_on_sections(work, other, lengths) \
        <= config.capacity + 1e-9
    ask = may_ask & fits & (other != codes) & (rng.random(codes.shape) < rate)
    return ask, other, did, rate


def _made(choice: str, codes: np.ndarray) -> np.ndarray:
    """Bool, shaped like ``codes``: the sections whose codes make the choice ``choice`` (a tamping: a tamping or a
    renewal)."""
    from trackenv.envs.choices import DRAINAGE, SPOT_TAMP

    from .line_policy import tamping_codes

    if choice == "tamp":
        return tamping_codes(codes)
    return np.asarray(codes) == (SPOT_TAMP if choice == "spot_tamp" else DRAINAGE)


def line_forks(config: Any, seeds: Sequence[int], policy: Any,
               choose: Callable[[int, dict[str, np.ndarray], np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
               progress: Callable[[int], Any] | None = None) -> dict[str, np.ndarray]:
    """Run ``policy`` (SB3 ``predict`` on batched line observations, deterministic; bound to ``config``; without a
    recurrent state, or with one that remembers only what it was shown, ``policy.observation_state``) on the
    episodes ``seeds`` of ``config`` (one batch), and fork whole lines of it: at each
    step ``t``, ``choose(t, obs, codes, allowed)`` (the step's observation, the policy's codes and the sections
    that may get track work, each (E, S)) names the lines
    to fork (n,) and each fork's codes at that step (n, S); a fork is an exact copy of its line as it is then
    (:meth:`~trackenv.envs.line_episode.LineBatch.get_state`: its physics and its pre-drawn residuals and
    measurement errors, so both branches see the same future draws), makes those codes at ``t`` and from
    ``t + 1`` on every section of it, the forked one included, does what ``policy`` decides on the fork's line.
    A fork takes the policy's state as its line's run left it at ``t`` (it has seen the same observations; a state
    that remembered the policy's own choices would misremember the fork's, hence the refusal of such a policy).

    Each branch pays what the env charges its whole line (every section's costs and the possession, k€; the
    env's reward with the sign turned), from ``t`` to the horizon. Returns ``line`` and ``step`` (n,) of every
    fork in the order chosen, ``cost`` (n,) the fork's cost to go, ``applied`` (n, S) the codes the env carried
    out at the fork's step (over capacity it drops some), ``to_go`` (H, E) the policy's own line's cost from each
    step on, and ``codes`` (H, E, S) the codes the env carried out on the policy's run. A fork whose codes are
    the policy's at its step costs exactly what the policy's run costs from there.

    Why whole lines: where several sections share a physics segment (``sections_per_segment`` > 1) a section's
    work changes its neighbours' track, so a section cannot be forked alone
    (:meth:`~trackenv.envs.line_episode.LineBatch.copy_rows` refuses)."""
    from gymnasium.vector import AutoresetMode

    from trackenv.envs.choices import action_type_for
    from trackenv.envs.line import TampingLineVectorEnv
    from trackenv.envs.line_episode import LineBatch

    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must not be empty")
    c = config
    E, S, H = len(seeds), c.n_sections, c.horizon_steps
    env = TampingLineVectorEnv(E, c, autoreset_mode=AutoresetMode.NEXT_STEP, action_type=action_type_for(c))
    obs, _ = env.reset(seed=seeds)
    base, keys = env.batch, list(obs)
    assert base is not None  # made by the reset
    forks = LineBatch(c, 4 * E)
    f_line, f_step = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    f_cost, f_applied = np.zeros(0), np.zeros((0, S), dtype=np.int64)
    to_go, base_codes = np.zeros((H, E)), np.zeros((H, E, S), dtype=np.int64)
    state: Any = None  # the policy's recurrent state on its own lines, and on the forks (rows as f_line)
    f_state: Any = None
    for t in range(H):
        codes, state = policy.predict(obs, state=state, episode_start=np.full(E, t == 0))
        if state is not None and not getattr(policy, "observation_state", False):
            raise ValueError("forks of whole lines need a policy without a recurrent state, or one whose state "
                             "remembers only what it was shown (observation_state; got a state of type "
                             f"{type(state).__name__}): a fork could not tell what its policy remembers of the "
                             "other choice")
        codes = np.asarray(codes, dtype=np.int64).reshape(E, S)
        lines, first = choose(t, obs, codes, base.allowed().reshape(E, S))
        lines, first = np.asarray(lines, dtype=np.int64), np.asarray(first, dtype=np.int64).reshape(-1, S)
        if lines.size != len(first):
            raise ValueError(f"choose gave {lines.size} lines and {len(first)} rows of codes")
        old = np.arange(f_line.size)
        forks = _with_room(forks, old.size, old.size + lines.size)
        new = np.arange(old.size, old.size + lines.size)
        for row, line in zip(new, lines, strict=True):
            forks.set_state(int(row), base.get_state(int(line)))
        want = np.zeros((forks.n_lines, S), dtype=np.int64)
        want[new] = first
        if old.size:  # the forks made earlier: their policy decides on their own lines
            seen = [forks.observation(int(b)) for b in old]
            decided, f_state = policy.predict({k: np.stack([o[k] for o in seen]) for k in keys}, state=f_state,
                                              episode_start=np.zeros(old.size, dtype=bool))
            want[old] = np.asarray(decided, dtype=np.int64).reshape(old.size, S)
        if state is not None:  # the new forks carry on their lines' state
            f_state = _state_rows(state, lines) if not old.size else _state_join(f_state, _state_rows(state, lines))
        f_line, f_step = np.concatenate([f_line, lines]), np.concatenate([f_step, np.full(lines.size, t)])
        f_cost = np.concatenate([f_cost, np.zeros(lines.size)])
        live = np.arange(f_line.size)
        if live.size:
            rewards, _, infos = forks.advance(want, live.tolist(), [])
            f_cost -= rewards[live]
            f_applied = np.concatenate([f_applied, np.array([infos[int(b)]["section_choices"] for b in new],
                                                            dtype=np.int64).reshape(-1, S)])
        obs, reward, _, _, info = env.step(codes.astype(np.int8))
        to_go[:t + 1] -= np.asarray(reward, dtype=float)  # summed in the order a fork sums its own
        base_codes[t] = np.asarray(info["section_choices"], dtype=np.int64)
        if progress is not None:
            progress(1)
    env.close()
    return {"line": f_line, "step": f_step, "cost": f_cost, "applied": f_applied,
            "to_go": to_go, "codes": base_codes}


def advice_along_run(advisor: Any) -> Callable[[int, dict[str, np.ndarray], tuple[int, int]], np.ndarray | None]:
    """``advice(t, obs, shape)``: the advisor's codes (``shape``: lines, sections) on the observation of step ``t``
    of a run of lines, asked step after step (None without an advisor). A planner whose state records what it was
    shown (``observation_state``) carries it from call to call; a rule is asked on the observation alone."""
    memory: list[Any] = [None]

    def advice(t: int, obs: dict[str, np.ndarray], shape: tuple[int, int]) -> np.ndarray | None:
        if advisor is None:
            return None
        told = memory[0] if getattr(advisor, "observation_state", False) else None
        codes, memory[0] = advisor.predict(obs, state=told, episode_start=np.full(shape[0], t == 0))
        return np.asarray(codes, dtype=np.int64).reshape(shape)

    return advice


def _state_rows(state: Any, rows: np.ndarray) -> Any:
    """The rows ``rows`` of a recurrent state (an array with the batch first, or a tuple of them), copied."""
    if isinstance(state, tuple):
        return tuple(_state_rows(x, rows) for x in state)
    return np.asarray(state)[rows].copy()


def _state_join(first: Any, then: Any) -> Any:
    """Two recurrent states of the same structure, the rows of ``first`` followed by those of ``then``."""
    if isinstance(first, tuple):
        return tuple(_state_join(a, b) for a, b in zip(first, then, strict=True))
    return np.concatenate([first, then])


def _with_room(forks: Any, used: int, needed: int) -> Any:
    """``forks`` (a LineBatch whose first ``used`` lines are in play) if it has ``needed`` lines, else a batch of
    twice as many (or ``needed``) with those lines copied over exactly."""
    if needed <= forks.n_lines:
        return forks
    from trackenv.envs.line_episode import LineBatch

    grown = LineBatch(forks.config, max(2 * forks.n_lines, needed))
    for line in range(used):
        grown.set_state(line, forks.get_state(line))
    return grown


def _line_fork_counterfactuals(config: Any, seeds: list[int], policy: Any, advisor: Any, choices: tuple[str, ...],
                               extended: bool, names: list[str], focus_rate: float, other_rate: float, seed: int,
                               progress: Callable[[int], Any] | None) -> dict[str, np.ndarray]:
    """:func:`section_counterfactuals` where sections share a segment: each decision priced forks its whole line
    (:func:`line_forks`; the line's other sections make the policy's choices at the step, and from the next step
    on the policy decides every section of the fork), and both choices are priced at the whole line's cost to go
    (every section and the possession), with the same decisions drawn as one-section forks would be."""
    from trackenv.envs.choices import work_on_sections, work_per_code

    from .line_policy import choice_open, section_features

    c = config
    rng = np.random.default_rng(seed)
    work = work_per_code(c.choice_work)
    asked: dict[str, list] = {k: [] for k in ("features", "choice", "did", "weight", "section", "own",
                                                      "first")}

    advice_at = advice_along_run(advisor)

    def choose(t: int, obs: dict[str, np.ndarray], codes: np.ndarray,
               allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        advice = advice_at(t, obs, codes.shape)
        line_work = work_on_sections(work, codes, c.length_factors).sum(axis=1, keepdims=True)
        lines, firsts = [], []
        for k, choice in enumerate(choices):
            feats = section_features(obs, advisor, advice, choice if extended else None)
            may = allowed & (np.ones(codes.shape, bool) if advice is None else choice_open(choice, obs, advice))
            ask, other, did, rate = _asked(c, choice, codes, advice, feats, names, may, line_work, rng, focus_rate,
                                           other_rate)
            b, j = np.nonzero(ask)
            first = codes[b].copy()
            first[np.arange(b.size), j] = other[b, j]
            for key, value in (("features", feats[b, j]), ("choice", np.full(b.size, k)), ("did", did[b, j]),
                               ("weight", 1.0 / rate[b, j]), ("section", j), ("own", codes[b, j]),
                               ("first", other[b, j])):
                asked[key].append(value)
            lines.append(b)
            firsts.append(first)
        return np.concatenate(lines), np.concatenate(firsts)

    run = line_forks(c, seeds, policy, choose, progress)
    d = {k: np.concatenate(v) for k, v in asked.items()}
    line, step, section = run["line"], run["step"], d["section"]
    # a choice the env did not carry out as asked (over capacity), on either branch, is not a sample
    valid = (run["codes"][step, line, section] == d["own"]) \
        & (run["applied"][np.arange(line.size), section] == d["first"])
    did = d["did"].astype(bool)[valid]
    q_policy, q_other = run["to_go"][step, line][valid], run["cost"][valid]
    return {"features": d["features"].astype(np.float32)[valid], "choice": d["choice"].astype(np.int64)[valid],
            "q_do": np.where(did, q_policy, q_other), "q_skip": np.where(did, q_other, q_policy), "did": did,
            "weight": d["weight"][valid], "seed": np.asarray(seeds)[line[valid]], "step": step[valid],
            "section": section[valid]}
