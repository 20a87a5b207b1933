"""What to do on a network of lines that share one tamping machine: ``trackenv plan NETWORK.yaml`` and
:func:`plan_network`.

A network file (:mod:`trackenv.envs.network_file`) names line files and the machine's line now; :func:`plan_network`
runs a tamping policy on the network for the next ``years`` in ``futures`` sampled futures (each line's future
drawn as :func:`~trackenv_agents.planning.plan_line` draws it, all of them in one vector env of
``trackenv/TampingNetwork-v0``). The policy is a line policy played on every line by
:func:`~trackenv_agents.rules.network.network_play` (the comparisons' way of playing a line policy on the network:
the machine goes where the requested work is worth most), the rule's tuned parameters those of ``scenario``.

The plan is each line's :class:`~trackenv_agents.plan_report.LinePlan` (its sections' shares, state, reasons and
costs, from its part of the network's futures; a section asked for on a line the machine was not working on is
"not done" for the reason ``machine``) and the machine's course: per quarter the share of futures in which it
works on each line or moves, the move costs, and the network's cost forecast.
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .plan_report import (
    GEOMETRY_NOTE,
    MODEL_READING_NOTE,
    LinePlan,
    cost_groups_text,
    counted,
    end_state,
    line_summary,
    recommend_count,
    scenario_note,
    step_date,
    summary_lines,
    years_text,
)
from .planning import (
    DEFAULT_POLICY,
    _run_futures,
    episode_horizon,
    line_limits,
    line_plan,
    line_policy,
    plan_config,
    plan_warnings,
    unmet_reasons,
)
from .rules.choices import CHOICE_RULES
from .rules.line import LINE_HEURISTICS
from .shipped import CHOICE_AGENT_NAME as CHOICE_AGENT

__all__ = ["NetworkPlan", "check_network_policy", "line_fields", "plan_network"]


@dataclass
class NetworkPlan:
    """A network's plan (:func:`plan_network`): the ``network`` (a
    :class:`~trackenv.envs.network_file.NetworkDescription`), each line's :class:`LinePlan` in ``lines`` (its own
    costs, without the machine's moves), the machine's line after each quarter ``machine``, whether it moved in
    it ``moved`` and whether it did track work ``worked`` (futures, quarters), and the network's ``costs`` and
    ``move_costs`` (futures, quarters) k€."""

    network: Any
    policy: str
    years: float
    futures: int
    seed: int
    dates: tuple[str, ...]
    lines: tuple[LinePlan, ...]
    machine: np.ndarray
    moved: np.ndarray
    costs: np.ndarray
    move_costs: np.ndarray
    worked: np.ndarray
    scenario: str = "default"

    def _stays(self, working: bool) -> np.ndarray:
        """(quarters, lines): the share of futures in which the machine is on each line in each quarter without
        moving, and did track work there (``working``) or none."""
        here = (self.machine[:, :, None] == np.arange(len(self.lines))) & ~self.moved[:, :, None]
        return (here & (self.worked if working else ~self.worked)[:, :, None]).mean(axis=0)

    @property
    def works_on(self) -> np.ndarray:
        """(quarters, lines): the share of futures in which the machine works on each line in each quarter (it is
        there, did not move in the quarter and tamps there what the line asks for)."""
        return self._stays(True)

    @property
    def idle_on(self) -> np.ndarray:
        """(quarters, lines): the share of futures in which the machine stands idle on each line in each quarter
        (there, not moving, and tamping nothing: no work asked for that it may do there, and none elsewhere
        worth a move)."""
        return self._stays(False)

    @property
    def moving_to(self) -> np.ndarray:
        """(quarters, lines): the share of futures in which the machine moves to each line in each quarter (it
        works there from the next)."""
        there = self.machine[:, :, None] == np.arange(len(self.lines))
        return (there & self.moved[:, :, None]).mean(axis=0)

    def end_state(self) -> dict[str, float] | None:
        """What the plan leaves on the network, every line's sections together (:func:`end_state`; each line's
        own is its plan's)."""
        return end_state(self.lines)

    def _names(self) -> list[str]:
        return [line.line.name for line in self.lines]

    def to_dict(self, files: Mapping[str, str] | None = None) -> dict[str, Any]:
        """The plan as plain data (JSON-ready): the network, per quarter the machine's course (``works_on`` and
        ``idle_on``: the share of futures per line, in the order of ``lines``; ``moving``, and ``moving_to`` per
        line) and the network's mean cost, the cost forecast, what the plan leaves (``end_state``), and each line's
        plan (:meth:`LinePlan.to_dict`) with the keys a line's plan has in ``trackenv plan LINE.yaml --json``: its
        ``warnings`` (:func:`plan_warnings`) and its ``files``, those of ``files`` (what :meth:`write` returned)
        under ``line<i>/``, keyed as a line's (none without ``files``)."""
        names, total, moves = self._names(), self.costs.sum(axis=1), self.move_costs.sum(axis=1)
        quarters = [{"from": d, "works_on": [float(s) for s in works],
                     "idle_on": [float(s) for s in self.idle_on[q]],
                     "moving": float(self.moved[:, q].mean()), "moving_to": [float(m) for m in self.moving_to[q]],
                     "cost_mean_keur": float(self.costs[:, q].mean()),
                     "move_cost_mean_keur": float(self.move_costs[:, q].mean())}
                    for q, (d, works) in enumerate(zip(self.dates, self.works_on, strict=True))]
        return {
            "network": self.network.name, "as_of": self.network.as_of, "lines": names,
            "machine_now": names[self.network.start_line], "policy": self.policy, "scenario": self.scenario,
            "years": self.years, "futures": self.futures, "seed": self.seed, "quarters": quarters,
            "cost_keur": {"mean": float(total.mean()), "p10": float(np.quantile(total, 0.1)),
                          "p90": float(np.quantile(total, 0.9)), "move_mean": float(moves.mean())},
            "end_state": self.end_state(),
            "line_plans": [{**line.to_dict(), "files": _line_files(files or {}, i),
                            "warnings": plan_warnings(line, alone=False)} for i, line in enumerate(self.lines)],
        }

    def table(self) -> str:
        """The plan as text: the network and its lines, per quarter where the machine works and what it tamps
        there (the sections recommended on each line), the first quarter's decision lines of each line, then the
        cost forecast of each line and of the network."""
        from .evaluation.line_compare import changes_note, engine_note

        d, names = self.to_dict(), self._names()
        first = self.lines[0]
        engine = engine_note({"engine": first.engine, "pass_reuse_tolerance_m": first.pass_reuse_tolerance_m})
        futures = counted(self.futures, "future", "futures")
        out = [f"Network plan for {d['network']} from {d['as_of']}: {self.policy} (scenario {self.scenario}, "
               f"tamping), {years_text(self.years)}, {futures}{engine}{changes_note(first.config_changes)}; the "
               f"machine is on line {self.network.start_line} now"]
        for i, line in enumerate(self.lines):
            out.append(f"line {i}: {line.line.name} ({line.line.source})")
            note = scenario_note(line.scenario, line.line, line.config_changes)  # the file's defects, suspicions
            out += [f"  {text}" for text in [*summary_lines(line_summary(line.line)), *([note] if note else []),
                                             *line.tuning_lines()]]
        out.append(f"{'quarter':<8} {'from':<11} {'cost k€':>8}  machine (share of futures); recommended (in at "
                   f"least {recommend_count(self.futures)} of the {self.futures} futures)")
        guessed = [set(plan["q1_model_sd"]) for plan in d["line_plans"]]
        starred = False
        for q, row in enumerate(d["quarters"]):
            where = [f"line {i} {s:.0%}" for i, s in enumerate(row["works_on"]) if s > 0]
            where += [f"idle on line {i} {s:.0%}" for i, s in enumerate(row["idle_on"]) if s > 0]
            where += [f"moving to line {i} {m:.0%}" for i, m in enumerate(row["moving_to"]) if m > 0]
            tamped = [f"line {i}: {line.tamp_text(q, plan['quarters'][q]['tamp'], guessed[i] if q == 0 else set())}"
                      for i, (plan, line) in enumerate(zip(d["line_plans"], self.lines, strict=True))
                      if plan["quarters"][q]["tamp"]]
            starred |= q == 0 and any(i in guessed[k] for k, plan in enumerate(d["line_plans"])
                                      for i in plan["quarters"][0]["tamp"])
            out.append(f"Q{q + 1:<7} {row['from']:<11} {row['cost_mean_keur']:>8.1f}  {', '.join(where) or '-'}; "
                       f"{'; '.join(tamped) or '-'}")
        if starred:
            out.append(MODEL_READING_NOTE)
        for i, line in enumerate(self.lines):
            decisions = line.decision_lines()
            if decisions:
                out += [f"line {i}, {names[i]}:", *decisions]
        for i, line in enumerate(self.lines):
            out += [f"line {i}: {text}" for text in line.validity_lines()]
        c = d["cost_keur"]
        for i, line in enumerate(self.lines):
            total = line.costs.sum(axis=1)
            out.append(f"cost of line {i} over {years_text(self.years)}: {total.mean():.0f} k€ mean, "
                       f"{np.quantile(total, 0.1):.0f}-{np.quantile(total, 0.9):.0f} k€ over 10-90 % of the futures")
            groups = cost_groups_text({k: float(v.mean()) for k, v in line.parts.items()})
            if groups:
                out.append(f"  {groups}")
            end = line.end_state_line()
            if end is not None:
                out.append(f"  {end}")
        out.append(f"cost of the network over {years_text(self.years)}: {c['mean']:.0f} k€ mean, {c['p10']:.0f}-"
                   f"{c['p90']:.0f} k€ over 10-90 % of the futures (moving the machine {c['move_mean']:.0f} k€)")
        out.append(f"  ({GEOMETRY_NOTE})")
        return "\n".join(out)

    def figure(self) -> Any:
        """The machine's course (per quarter the share of futures in which it works on each line, stands idle there
        (hatched), or moves) above
        the cumulative cost forecast by date (the network's mean and 10-90 % band, each line's mean, the moves): a
        pyplot-free :class:`matplotlib.figure.Figure`."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(10, 6.5), dpi=100)
        FigureCanvasAgg(fig)
        top, bottom = fig.subplots(2, 1, sharex=True)
        quarters = np.arange(len(self.dates))
        below = np.zeros(len(self.dates))
        for i, (share, idle) in enumerate(zip(self.works_on.T, self.idle_on.T, strict=True)):
            top.bar(quarters, share, bottom=below, color=f"C{i}", label=f"line {i}: {self.lines[i].line.name}")
            below += share
            if idle.any():
                top.bar(quarters, idle, bottom=below, color=f"C{i}", alpha=0.3, hatch="//",
                        label=f"idle on line {i}")
                below += idle
        top.bar(quarters, self.moved.mean(axis=0), bottom=below, color="0.7", label="moving")
        top.set_ylim(0, 1)
        top.set_ylabel("share of futures")
        top.set_title(f"{self.network.name}: where the machine works, {self.policy} ({self.scenario}), "
                      f"{self.futures} futures from {self.network.as_of}", fontsize=9)
        top.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.04), ncol=min(len(self.lines) + 1, 4))
        def summed(costs: np.ndarray) -> np.ndarray:  # (futures, quarters+1): from 0 to the end of each quarter
            return np.concatenate([np.zeros((costs.shape[0], 1)), np.cumsum(costs, axis=1)], axis=1)

        edges = np.arange(len(self.dates) + 1) - 0.5  # the quarters' bars sit on their indices
        total = summed(self.costs)
        bottom.fill_between(edges, np.quantile(total, 0.1, axis=0), np.quantile(total, 0.9, axis=0),
                            color="0.85", label="network, 10-90 % of the futures")
        bottom.plot(edges, total.mean(axis=0), color="k", label="network, mean")
        for i, line in enumerate(self.lines):
            bottom.plot(edges, summed(line.costs).mean(axis=0), color=f"C{i}", lw=1, label=f"line {i}")
        bottom.plot(edges, summed(self.move_costs).mean(axis=0), color="0.5", ls="--", lw=1, label="moves")
        bottom.set_ylabel("cost summed to the end of the quarter [k€]")
        step = max(len(self.dates) // 8, 1)
        # a date at the start of its quarter: the cost curve's 0 at as_of, each bar between its quarter's dates
        bottom.set_xticks(edges[:-1][::step], [self.dates[q] for q in quarters[::step]], fontsize=7)
        bottom.set_xlabel("date (each bar: the quarter from its date to the next)")
        bottom.legend(fontsize=7, loc="upper left")
        fig.tight_layout()
        return fig

    def write(self, folder: Path) -> dict[str, str]:
        """Write ``network.csv`` (quarter, date, where the machine works, stands idle and where it moves to, a
        column per line each, shares of futures; the network's mean, p10 and p90 cost and the mean move cost k€)
        and ``network.png`` (:meth:`figure`) into ``folder`` and each line's plan (:meth:`LinePlan.write`) into a
        folder of its own, ``line<i>``; returns the paths."""
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / "network.csv"
        with path.open("w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["quarter", "from", *(f"works_on_line{i}" for i in range(len(self.lines))),
                        *(f"idle_on_line{i}" for i in range(len(self.lines))),
                        *(f"moving_to_line{i}" for i in range(len(self.lines))),
                        "cost_mean_keur", "cost_p10_keur", "cost_p90_keur", "move_cost_mean_keur"])
            for q, (date, works, idle, moving) in enumerate(zip(self.dates, self.works_on, self.idle_on,
                                                               self.moving_to, strict=True)):
                c = self.costs[:, q]
                w.writerow([q + 1, date, *(f"{s:.3f}" for s in works), *(f"{s:.3f}" for s in idle),
                            *(f"{m:.3f}" for m in moving),
                            f"{c.mean():.3f}", f"{np.quantile(c, 0.1):.3f}", f"{np.quantile(c, 0.9):.3f}",
                            f"{self.move_costs[:, q].mean():.3f}"])
        png = folder / "network.png"
        self.figure().savefig(png)
        files = {"network_csv": str(path), "network_plot": str(png)}
        for i, line in enumerate(self.lines):
            files.update({_line_key(i, k): v for k, v in line.write(folder / f"line{i}").items()})
        return files


def _line_key(line: int, key: str) -> str:
    """The key in :meth:`NetworkPlan.write`'s paths of the file ``key`` (a key of :meth:`LinePlan.write`'s) of
    line ``line``."""
    return f"line{line}_{key}"


def _line_files(files: Mapping[str, str], line: int) -> dict[str, str]:
    """Line ``line``'s part of :meth:`NetworkPlan.write`'s paths ``files``, keyed as :meth:`LinePlan.write` keys
    them (``plan_csv``, ``costs_csv``, ``plot``)."""
    prefix = _line_key(line, "")
    return {key.removeprefix(prefix): path for key, path in files.items() if key.startswith(prefix)}


def _tuned(rules: list[Any], lines: list[Any], tune: int, progress: bool, executor: Any = None,
           batch_size: int = 32) -> list[Any]:
    """Each line's :class:`~trackenv_agents.plan_tuning.RuleTuning`: its rule tuned on ``tune`` futures of the
    line alone, once per distinct line config (lines of equal files share it); ``executor`` and ``batch_size``
    as :func:`~trackenv_agents.plan_tuning.tune_plan_rule` takes them."""
    from .plan_tuning import tune_plan_rule

    found: list[tuple[Any, Any]] = []
    out = []
    for i, (rule, cfg) in enumerate(zip(rules, lines, strict=True)):
        known = next((t for c, t in found if c == cfg), None)
        if known is None:
            try:
                known = tune_plan_rule(rule, cfg, tune, progress=progress, desc=f"tune line {i} ({cfg.line.name})",
                                       executor=executor, batch_size=batch_size)
            except ValueError as exc:
                raise ValueError(f"line {i}: {exc}") from None
            known = dataclasses.replace(known, alone=True)
            found.append((cfg, known))
        out.append(known)
    return out


def line_fields(line: Any, config: dict[str, Any]) -> dict[str, Any]:
    """The fields ``config`` given to a network plan as they model its line ``line`` (a description): a
    ``capacity`` there is the machine's, so a line file with its own keeps that (not refused as a change)."""
    return {k: v for k, v in config.items() if not (k == "capacity" and line.capacity is not None)}


def check_network_policy(policy: str) -> None:
    """ValueError for a choice rule (its tamping is tuned with the choices beyond it, and the network's machine tamps
    only). ``cpi-choice-agent`` is accepted: on a line whose action is tamping only it tamps from its network, as
    the leaderboard plays it on the network."""
    if policy in CHOICE_RULES:
        raise ValueError(f"policy {policy!r} uses the choices beyond tamping, and the network's machine tamps only: "
                         f"plan it with a tamping rule ({', '.join(LINE_HEURISTICS)}), cpi-agent or {CHOICE_AGENT}")


def plan_network(network: Any, *, policy: str = DEFAULT_POLICY, years: float = 3.0, futures: int = 8, seed: int = 0,
                 scenario: str = "default", progress: Callable[[int], Any] | None = None, tune: int = 0,
                 episode_years: float | None = None, executor: Any = None, batch_size: int = 32,
                 **config: Any) -> NetworkPlan:
    """Plan tamping on ``network`` (a network file's path or a
    :class:`~trackenv.envs.network_file.NetworkDescription`) for ``years`` from its ``as_of``: the line policy
    ``policy`` (:func:`~trackenv_agents.planning.line_policy`: a tamping rule with the tuned parameters of
    ``scenario``, or a shipped agent: ``cpi-agent``, ``cpi-choice-agent`` tamping only) played on every line by
    :func:`~trackenv_agents.rules.network.network_play`, in ``futures`` futures (seeds ``seed``, ``seed + 1``,
    ...); each line modelled as :func:`~trackenv_agents.planning.plan_config` models it; ``config``: further
    :class:`~trackenv.envs.line_config.LineConfig` fields for every line (a ``capacity`` given here is the
    machine's, over the network file's). ``tune``: where > 0, each line's rule is first tuned on that many
    futures of the line alone (:func:`~trackenv_agents.plan_tuning.tune_plan_rule`: as if it had a machine of its
    own; lines of one config once; its batches of ``batch_size`` episodes run by ``executor``, e.g. on Ray).
    ``episode_years``: the futures' episode length, as
    :func:`~trackenv_agents.planning.plan_line` takes it. ``progress(1)`` after each quarter. ValueError for a
    choice rule (:func:`check_network_policy`) or a policy that cannot play a line (its reason, naming the line)."""
    from gymnasium.vector import AutoresetMode

    from trackenv.envs.network_env import TampingNetworkVectorEnv
    from trackenv.envs.network_file import load_network

    from .rules.network import network_play

    desc = network if not isinstance(network, (str, Path)) else load_network(network)
    check_network_policy(policy)
    # every line modelled as in its own plan (a scenario's hidden parts and observation), the action tamping only
    lines = [plan_config(line, scenario, years=years, **line_fields(line, config)) for line in desc.lines]
    rules = []
    for i, cfg in enumerate(lines):
        try:
            rules.append(line_policy(policy, cfg, scenario, years=years))
        except ValueError as exc:
            raise ValueError(f"line {i} ({desc.lines[i].name}): {exc}") from None
    if tune:
        from .plan_tuning import check_apart

        check_apart(seed, futures, tune)
    tunings = (_tuned(rules, lines, tune, progress is not None, executor=executor, batch_size=batch_size) if tune
               else [None] * len(lines))
    rules = [rule if t is None else t.rule(rule, cfg) for rule, t, cfg in zip(rules, tunings, lines, strict=True)]
    steps = lines[0].horizon_steps
    horizon = episode_horizon(rules[0], episode_years)
    if horizon is not None and horizon != lines[0].horizon_years:  # as plan_line: the plan the episodes' first years
        lines = [cfg.replace(horizon_years=horizon) for cfg in lines]
    net = desc.config(lines, capacity=config.get("capacity"))  # the machine's fields and the dates from the file
    rule = network_play(rules[0]).bind(net, line_rules=rules)
    env = TampingNetworkVectorEnv(futures, net, autoreset_mode=AutoresetMode.NEXT_STEP)
    offsets = net.line_offsets

    def why(want: np.ndarray, codes: np.ndarray, allowed: np.ndarray, measured_sd: np.ndarray,
            info: dict[str, Any]) -> dict[str, np.ndarray]:
        """:func:`unmet_reasons` line by line, the lines the machine did not work on (it moved, or was elsewhere)
        under the reason ``machine``."""
        parts: list[dict[str, np.ndarray]] = []
        for i, cfg in enumerate(net.line_configs):
            at = slice(offsets[i], offsets[i + 1])
            working = (np.asarray(info["machine_line"]) == i) & ~np.asarray(info["moved"], dtype=bool)
            parts.append(unmet_reasons(cfg, want[:, at], codes[:, at], allowed[:, at], measured_sd[:, at],
                                       np.asarray(info["clipped"], dtype=bool) & working, working))
        return {key: np.concatenate([p[key] for p in parts], axis=1) for key in parts[0]}

    def asked(action: np.ndarray) -> np.ndarray:
        """What each line's policy asked for in the step just predicted, before the dispatch."""
        assert rule.last_requests is not None  # set by the predict that made ``action``
        return rule.last_requests

    run = _run_futures(env, rule, steps, [seed + i for i in range(futures)], progress, why, net.line_sections,
                       asked)
    assert env.batch is not None and run.machine is not None  # built at reset; a network's run has its record
    dates = tuple(step_date(desc.as_of, q, net.steps_per_year) for q in range(steps))
    plans = []
    for i, cfg in enumerate(net.line_configs):
        batch, row = env.batch.row(0, i)
        # the file's own description (two files of equal content share one config) on the network's calendar
        line = dataclasses.replace(desc.lines[i], as_of=desc.as_of)
        plans.append(line_plan(line, cfg, run.line(i, slice(offsets[i], offsets[i + 1])),
                               line_limits(batch, row, cfg.n_sections), policy=policy, rule=rules[i], years=years,
                               seed=seed, dates=dates, scenario=scenario, choices=("tamp",), config=config,
                               tuning=tunings[i]))
    env.close()
    return NetworkPlan(desc, policy, float(years), futures, seed, dates, tuple(plans), run.machine.machine,
                       run.machine.moved, run.costs, run.part_costs["move"], run.machine.worked, scenario)
