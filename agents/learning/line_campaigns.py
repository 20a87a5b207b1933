"""What a whole campaign is worth where sections share a segment: forks of the whole line with other campaigns at
a step, priced at the line's cost to go, and per-section labels from the cheapest of them.

Why. On a track whose sections share one physics segment (the 60 m track, ``"track60"``) a campaign's possession
(10 k€ on the 60 m track) is shared by every section it takes. One section's other choice, with the other sections
as the policy has them (:func:`~trackenv_agents.learning.line_counterfactual.section_counterfactuals`), prices
that section's marginal part only: where no campaign is called, a section that would pay the whole possession
alone waits, though a campaign of several such sections together would pay; where one is called, each section
that would rather wait can leave it, though all of them leaving would save the possession. Improving on single
flips does not add up to better campaigns.

So a decision priced here is the step's **whole campaign** on one line (:func:`campaign_candidates`): the
policy's own against another (by default one, drawn from: no campaign, the policy's with its marginal section
added or dropped, the campaign a grouped threshold would make now). Each is a fork of the whole line
(:func:`~trackenv_agents.learning.line_counterfactual.line_forks`: an exact copy of the line and its pre-drawn
noise) that makes that campaign at the step and lets the policy decide from the next step on, priced at the
whole line's cost to go (every section and the possession, as the env charges them). Each section that the
branches treat differently then gets one sample: ``q_do``, the cheapest branch in which it is tamped, and
``q_skip``, the cheapest in which it is not (the policy's own branch among them). A network that chooses, per
section, the cheaper of the two reproduces the cheapest branch's codes;
:func:`~trackenv_agents.learning.imitation.fit_choices` weights each by the difference, as it does for single
flips, and the sections of one line-step share its weight (one campaign decision counts once).

What it gives on the 60 m track (the documentation's agents page): a tie with the tuned grouped threshold at
best; one-step campaign deviations from the rule are not cheaper on average, and a per-section network told to
tamp because the whole campaign pays tends to call campaigns of one section.

Scope: tamp-or-wait lines (no advisor's choice codes beyond the tamping); a policy without a recurrent state
(``line_forks`` refuses one).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["CAMPAIGN_INCLUDE_MM", "campaign_candidates", "campaign_counterfactuals"]

#: mm: the projected SD from which a section joins the grouped campaign priced at a step (the 60 m track's tuned
#: grouped threshold includes from 1.0 mm) [assumption: one fixed level, not the advisor's own parameter].
CAMPAIGN_INCLUDE_MM = 1.0


def campaign_candidates(tamped: np.ndarray, allowed: np.ndarray, projected_sd_mm: np.ndarray, work: np.ndarray,
                        capacity: float, include_mm: float = CAMPAIGN_INCLUDE_MM) -> list[np.ndarray]:
    """The campaigns to price on one line at one step, each an (S,) bool of the sections tamped, other than the
    policy's own ``tamped`` (S,) and without repeats: none; the policy's with its marginal sections, the worst
    ``allowed`` section it leaves out added and the least worst it takes dropped (by ``projected_sd_mm``); and
    the campaign a grouped threshold would make now, every allowed section projected at ``include_mm`` or more
    (at least the worst). A campaign whose ``work`` (S,) (a tamping's, in tamping-section equivalents) sums over
    ``capacity`` is left out (the env would not carry it out as asked).

    Why so few: each branch is priced on one sampled future, and the cheapest of many branches is cheap partly by
    luck; a section's two prices (the cheapest branch with it and without) stay comparable only if neither side
    has many more branches to pick from."""
    tamped, allowed = np.asarray(tamped, bool), np.asarray(allowed, bool)
    sd = np.asarray(projected_sd_mm, float)
    options = [np.zeros_like(tamped)]
    left_out = np.nonzero(allowed & ~tamped)[0]
    if left_out.size:
        added = tamped.copy()
        added[left_out[np.argmax(sd[left_out])]] = True
        options.append(added)
    taken = np.nonzero(tamped)[0]
    if taken.size:
        dropped = tamped.copy()
        dropped[taken[np.argmin(sd[taken])]] = False
        options.append(dropped)
    if allowed.any():
        grouped = allowed & (sd >= include_mm)
        grouped[np.nonzero(allowed)[0][np.argmax(sd[allowed])]] = True
        options.append(grouped)
    seen = {tamped.tobytes()}
    kept = []
    for option in options:
        key = option.tobytes()
        if key in seen or work[option].sum() > capacity + 1e-9:
            continue
        seen.add(key)
        kept.append(option)
    return kept


def campaign_counterfactuals(config: Any, seeds: Sequence[int], policy: Any, advisor: Any = None,
                             focus_rate: float = 0.5, other_rate: float = 0.1, seed: int = 0,
                             progress: Callable[[int], Any] | None = None,
                             alternatives: int | None = 1) -> dict[str, np.ndarray]:
    """Run ``policy`` on the episodes ``seeds`` of ``config`` (a tamp-or-wait line; SB3 ``predict``, without a
    recurrent state) and price whole campaigns (:func:`campaign_candidates`) at a random subset of its line-steps:
    each with probability ``focus_rate`` where a campaign is in question (a section of it is, by the single-flip
    rule :func:`~trackenv_agents.learning.line_counterfactual._query_rates`), else ``other_rate``; drawn from
    ``seed``. ``advisor``: the rule whose choice the features carry (as the policy sees it). ``alternatives``: how
    many of the candidates are priced at a line-step, drawn at random (None: every one). With one, a section's two
    prices are its line's own run and one other campaign, each on the same sampled future: an unbiased sample of
    the difference, as a single flip's; with more, the cheapest of several branches is cheap partly by luck
    (it favours the side with more branches).

    Returns arrays over the sections of the priced line-steps that the branches treat differently, in the form
    :func:`~trackenv_agents.learning.line_counterfactual.section_counterfactuals` gives (so
    :func:`~trackenv_agents.learning.imitation.fit_choices` fits them): ``features``, ``choice`` (0: the
    tamping), ``q_do`` and ``q_skip`` (k€ to the horizon of the whole line: the cheapest branch with the section
    tamped, and without), ``did``, ``weight`` (1 / the line-step's probability, shared among its samples), ``seed``,
    ``step``, ``section``;
    and ``branches`` (the number of branches priced at the sample's line-step, the policy's own included)."""
    from trackenv.envs.choices import TAMP, action_type_for, work_on_sections, work_per_code

    from ..evaluation.harness import bind_policy
    from .line_counterfactual import _query_rates, advice_along_run, line_forks
    from .line_policy import FEATURES, section_features, tamping_codes

    c = config
    if alternatives is not None and alternatives < 1:
        raise ValueError(f"alternatives must be >= 1 or None, got {alternatives!r}")
    if action_type_for(c) == "choices":
        raise ValueError("campaign forks price tamp-or-wait lines; this config's actions are choice codes")
    for name, rate in (("focus_rate", focus_rate), ("other_rate", other_rate)):
        if not 0.0 < rate <= 1.0:
            raise ValueError(f"{name} must be in (0, 1], got {rate!r}")
    policy = bind_policy(policy, c)
    advisor = None if advisor is None else bind_policy(advisor, c)
    names = [n for n, _ in FEATURES]
    sd_column = names.index("projected_sd_mm")
    sd_scale = dict(FEATURES)["projected_sd_mm"]  # the feature is the SD over its scale
    rng = np.random.default_rng(seed)
    work = work_on_sections(work_per_code(c.choice_work), np.full(c.n_sections, TAMP), c.length_factors)
    picked: dict[str, list] = {k: [] for k in ("features", "rate", "line", "step")}

    advice_at = advice_along_run(advisor)

    def choose(t: int, obs: dict[str, np.ndarray], codes: np.ndarray,
               allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        E, S = codes.shape
        advice = advice_at(t, obs, (E, S))
        feats = section_features(obs, advisor, advice)
        tamped = tamping_codes(codes)
        rate = _query_rates(feats, names, tamped, focus_rate, other_rate).max(axis=1)
        lines, firsts = [], []
        for b in np.nonzero(rng.random(E) < rate)[0]:
            options = campaign_candidates(tamped[b], allowed[b], feats[b, :, sd_column] * sd_scale, work,
                                          c.capacity)
            if alternatives is not None and len(options) > alternatives:
                options = [options[i] for i in np.sort(rng.choice(len(options), alternatives, replace=False))]
            for option in options:
                lines.append(b)
                firsts.append(np.where(option, TAMP, 0))
            picked["features"].append(feats[b])
            picked["rate"].append(rate[b])
            picked["line"].append(b)
            picked["step"].append(t)
        return (np.asarray(lines, dtype=np.int64),
                np.asarray(firsts, dtype=np.int64).reshape(-1, S))

    run = line_forks(c, seeds, policy, choose, progress)
    return _cheapest_per_section(run, picked, seeds)


def _cheapest_per_section(run: dict[str, np.ndarray], picked: dict[str, list],
                          seeds: Sequence[int]) -> dict[str, np.ndarray]:
    """The samples of :func:`campaign_counterfactuals` from its forks ``run`` (:func:`line_forks`) and the
    line-steps ``picked``: per section, the cheapest branch with it tamped and without, as the env carried the
    branches out (``applied``; the policy's own run is a branch). The sections whose choice differs between the
    branches share the line-step's weight (each gets 1 / their number of it): the cost difference of one
    campaign decision counts once, as a single flip's does, not once per section it moves."""
    from .line_policy import tamping_codes

    out: dict[str, list] = {k: [] for k in ("features", "q_do", "q_skip", "did", "weight", "seed", "step",
                                            "section", "branches")}
    for feats, rate, line, t in zip(picked["features"], picked["rate"], picked["line"], picked["step"],
                                    strict=True):
        mine = np.nonzero((run["step"] == t) & (run["line"] == line))[0]
        own = tamping_codes(run["codes"][t, line])
        tamps = np.vstack([own[None], tamping_codes(run["applied"][mine])])
        costs = np.concatenate([[run["to_go"][t, line]], run["cost"][mine]])
        shared = max(int(np.sum(tamps.any(axis=0) & ~tamps.all(axis=0))), 1)  # the sections the branches move
        for j in range(tamps.shape[1]):
            with_j, without_j = costs[tamps[:, j]], costs[~tamps[:, j]]
            if not (with_j.size and without_j.size):
                continue
            for key, value in (("features", feats[j]), ("q_do", with_j.min()), ("q_skip", without_j.min()),
                               ("did", own[j]), ("weight", 1.0 / rate / shared), ("seed", seeds[line]), ("step", t),
                               ("section", j), ("branches", costs.size)):
                out[key].append(value)
    n = len(out["q_do"])
    return {"features": np.asarray(out["features"], dtype=np.float32).reshape(n, -1),
            "choice": np.zeros(n, dtype=np.int64), "q_do": np.asarray(out["q_do"], float),
            "q_skip": np.asarray(out["q_skip"], float), "did": np.asarray(out["did"], bool),
            "weight": np.asarray(out["weight"], float), "seed": np.asarray(out["seed"], dtype=np.int64),
            "step": np.asarray(out["step"], dtype=np.int64), "section": np.asarray(out["section"], dtype=np.int64),
            "branches": np.asarray(out["branches"], dtype=np.int64)}
