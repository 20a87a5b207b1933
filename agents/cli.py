"""The ``trackenv`` command: validate, paper, compile, bench, evaluate, leaderboard, train, calibrate, plan.

Each subcommand prints a human summary, or exactly one JSON object on stdout with ``--json`` (progress bars go
to stderr). Results (JSON and PNG) are written under ``results/`` unless ``--out`` says otherwise.

This module imports nothing heavy at the top: ``trackenv --help`` and ``--version`` must answer at once, so
each subcommand imports the physics, numba or torch only when it runs. Bad input (a missing file, a
negative count) ends in one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, NoReturn

from .shipped import CHOICE_AGENT_NAME, LINE_AGENT_NAME, SHIPPED_AGENTS, TRACK60_AGENT_NAME

#: ``trackenv plan --tune``'s largest number of training futures: the training seeds'
#: (``trackenv_agents.evaluation.harness.TRAIN_SEEDS``, not imported here to keep the command's start light)
MAX_TUNE_FUTURES = 100

# = trackenv_agents.learning.tamping.DEFAULT_TRAIN_SEED and DEFAULT_HYPERPARAMS, written out: importing them here would
# load torch for every command (a test keeps them equal)
DEFAULT_TRAIN_SEED = 20_000
DEFAULT_PLAN_POLICY = "grouped-threshold"  # = trackenv_agents.planning.DEFAULT_POLICY
DEFAULT_ENV_ID = "trackenv/Tamping-v1"  # the SB3 trainer's env (= trackenv_agents.learning.tamping.DEFAULT_ENV_ID)
HYPERPARAMS_FILE = Path(__file__).resolve().parent / "learning" / "hyperparams" / "ppo.yml"
# = trackenv.envs.line_config.LINE_ENGINES and MAX_PASS_REUSE_TOLERANCE_M (in mm), written out for the same reason
ENGINES = ("classic", "fast")
MAX_PASS_REUSE_MM = 2.0
# = trackenv_agents.evaluation.line_compare.MAX_EPISODES (the most episodes --seeds may give), for the help text
MAX_EPISODES = 100_000


class UsageError(Exception):
    """Bad input found before any work starts: one line on stderr and exit status 2."""


def installed_version() -> str:
    """The version of the installed ``trackenv`` distribution (its one source: pyproject.toml)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("trackenv")
    except PackageNotFoundError:  # pragma: no cover - a source tree that was never installed
        return "unknown (not installed)"


def _emit(args: argparse.Namespace, payload: dict[str, Any], human: str) -> None:
    if args.json:
        from trackenv._json import json_default

        print(json.dumps(payload, default=json_default))
    else:
        print(human)


def _existing(path: str | None, what: str, *, folder: bool = False) -> None:
    """Refuse a missing file (or folder) up front, before anything slow is imported."""
    if path is None:
        return
    p = Path(path)
    if not (p.is_dir() if folder else p.is_file()):
        raise UsageError(f"{what}: no such {'folder' if folder else 'file'}: {path}")


def _output_folder(path: str | None) -> None:
    """Refuse up front, in one line, an ``--out`` folder that cannot be made (under a file, in a read-only or
    system place), rather than after the work when the results are written: the missing folders are made and
    removed again, so that a command refused later for another reason leaves nothing behind."""
    if path is None:
        return
    if Path(path).exists() and not Path(path).is_dir():
        raise UsageError(f"--out {path}: a file, not a folder")
    missing = []
    folder = Path(path).absolute()
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    try:
        for made in reversed(missing):
            made.mkdir()
    except OSError as exc:
        raise UsageError(f"--out {path}: cannot create the folder ({exc.strerror or exc})") from None
    finally:
        for made in missing:
            if made.is_dir():
                made.rmdir()


def cmd_validate(args: argparse.Namespace) -> int:
    from trackenv_studies.validation import format_checks, run_validation

    out = args.out or "results/validation"
    summary = run_validation(out_dir=out, make_plots=not args.no_plots, progress=not args.json)
    files = ["summary.json", *summary["plots"]]
    human = "\n".join([
        "trackenv validate — track model against closed forms and the paper",
        format_checks(summary["checks"]),
        f"wrote {', '.join(files)} to {out}",
    ])
    _emit(args, summary, human)
    return 0 if all(c["passed"] for c in summary["checks"]) else 1


def cmd_paper(args: argparse.Namespace) -> int:
    from trackenv_studies.paper import format_summary, reproduce_paper

    summary = reproduce_paper(
        out_dir=args.out or "results/paper",
        iterations=args.iterations,
        cycles_per_iteration=args.cycles,
        make_plots=not args.no_plots,
        progress=not args.json,
    )
    _emit(args, summary, format_summary(summary))
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from tqdm.auto import tqdm

    from trackenv_studies.bench import STAGES, format_benchmarks, run_benchmarks

    with tqdm(total=len(STAGES), desc="bench", unit="benchmark", leave=False) as bar:

        def step(name: str) -> None:
            if bar.n or name != STAGES[0]:
                bar.update(1)
            bar.set_postfix_str(name)

        result = run_benchmarks(quick=args.quick, progress=step, line_policy=_tuned_line_rule())
        bar.update(bar.total - bar.n)
    _emit(args, result, format_benchmarks(result))
    return 0


def _tuned_line_rule() -> Any:
    """The default line's grouped threshold with its shipped tuned parameters (the bench's realistic policy; its
    own defaults where none ship)."""
    from trackenv.envs.line_config import scenario
    from trackenv_agents.rules.problems import tuned_rule

    return tuned_rule(scenario("default"), "grouped-threshold")


def cmd_compile(args: argparse.Namespace) -> int:
    """Build every compiled entry of the pass kernel that a call would otherwise compile on first use (numba keeps
    them in its on-disk cache beside the package), one line per entry on stderr."""
    from trackenv.physics.kernels import compile_kernels, kernel_entries, missing_kernels, usable_cores

    t0 = time.perf_counter()
    todo = missing_kernels(args.widths)
    jobs = min(args.jobs or usable_cores(), len({e.width for e in todo}) or 1)
    if not args.json:
        print(f"trackenv compile: {len(todo)} of {len(kernel_entries(args.widths))} pass-kernel entries to compile"
              + (f" (once per install; a few minutes, {jobs} process{'es' * (jobs > 1)} at once)" if todo else ""),
              file=sys.stderr)

    def report(p: Any) -> None:
        if p.seconds is not None and not args.json:
            print(f"  {p}", file=sys.stderr)

    built = compile_kernels(args.widths, progress=report, jobs=jobs)
    if not args.widths:  # the settlement solver and the D1 filter compile on first use too: one step of each problem
        if not args.json:
            print("  warming the settlement solver and the D1 filter (one step of each problem)", file=sys.stderr)
        _one_step_of_each_problem()
    payload = {"compiled": [str(e) for e in built], "entries": [str(e) for e in kernel_entries(args.widths)],
               "missing_after": [str(e) for e in missing_kernels(args.widths)],
               "wall_time_s": time.perf_counter() - t0}
    _emit(args, payload, f"every pass-kernel entry is compiled ({len(built)} built now, "
                         f"{payload['wall_time_s']:.0f} s)")
    return 0 if not payload["missing_after"] else 1


def _one_step_of_each_problem() -> None:
    """A reset and a step of a short 60 m track and a short line: what compiles on first use besides the pass
    kernel (the settlement solver, the D1 filter) is compiled, or loaded from numba's cache, by the same types."""
    import numpy as np

    from trackenv.envs import make_vector_env, scenario

    for config in (scenario("track60", horizon_years=0.25), scenario("small", horizon_years=0.25)):
        env = make_vector_env(config, 1)
        env.reset(seed=0)
        env.step(np.ones((1, config.n_sections), dtype=np.int8))
        env.close()


def shipped_agent_for(env_id: str) -> str:
    """The shipped agent `evaluate` scores on ``env_id`` by default: the agent of the 60 m track
    (``cpi-track60-agent``) there, the agent of the lines with every choice (``cpi-choice-agent``) on an id with
    every choice, else the tamp-or-wait agent (``cpi-agent``)."""
    from .evaluation.line_compare import action_type_of, scenario_of

    if scenario_of(env_id) == "track60":
        return TRACK60_AGENT_NAME
    return CHOICE_AGENT_NAME if action_type_of(env_id) == "choices" else LINE_AGENT_NAME


def _line_policies(args: argparse.Namespace) -> dict[str, Any]:
    """The policies scored next to the line rules: the trained line policy, ``--model`` (named ``cpi-agent``),
    else the shipped agent of the id (:func:`shipped_agent_for`) if its file is there (the same policy on every
    scenario: its network is shared over sections); with ``--policy all``, also the model-predictive planner
    where the preset measures every step without error (the 60 m track)."""
    if args.policy == "rules":
        return {}
    _existing(args.model, "--model", folder=args.model is not None and not Path(args.model).suffix)
    name = LINE_AGENT_NAME if args.model else shipped_agent_for(args.env)
    path = Path(args.model) if args.model else SHIPPED_AGENTS[name]
    out: dict[str, Any] = {}
    if args.model:
        out.update(_trained_model(path, args))
    elif path.exists():
        from .learning.line import load_line_trained

        out[name] = load_line_trained(path, name=name)
    elif args.policy == "agent":
        raise UsageError(f"no trained line policy at {path}; train one (experiments/train_line.py) and pass --model")
    if args.policy == "all":
        from .evaluation.line_compare import env_config
        from .rules.model_predictive import ModelPredictive

        if ModelPredictive.unfit_for(env_config(args.env)) is None:
            out[ModelPredictive.name] = ModelPredictive()
    return out


def model_label(path: Path) -> str:
    """A trained policy's name in the tables: its folder and file (``run1/model``, ``run1/best_model``: the run it
    came from) for a file, the folder's name for an RLlib run; the same however the path is written (relative,
    absolute, ``./model.zip`` in its run's folder)."""
    path = Path(os.path.abspath(path))
    return f"{path.parent.name}/{path.stem}" if path.suffix else path.name


def _trained_model(path: Path, args: argparse.Namespace) -> dict[str, Any]:
    """``--model PATH`` by what the path holds (:func:`~.learning.baselines.baseline_kind`), named by its folder and
    file (:func:`model_label`; a shipped agent's file by the agent's name): a per-section policy (``trackenv train
    --env ID``) runs on any line; a model of ``trackenv train`` (SB3, with its observation statistics) or an RLlib
    run only on the line it was trained on, or a network of that line (else one line saying which fields differ)."""
    from .evaluation.leaderboard import fitting_agents
    from .evaluation.line_compare import env_config
    from .learning.baselines import baseline_kind, load_baseline

    with _refusals_of("--model"):
        kind = baseline_kind(path)
    shipped = next((n for n, p in SHIPPED_AGENTS.items() if Path(p).resolve() == path.resolve()), None)
    policy = load_baseline(path, name=shipped or model_label(path))
    if kind == "line":
        return {policy.name: policy}
    fit, unfit = fitting_agents({policy.name: policy}, env_config(args.env, **engine_overrides(args)))
    if unfit:
        raise UsageError(f"--model {path} cannot be scored on {args.env}: {unfit[policy.name]}")
    return fit


def _executor(args: argparse.Namespace) -> Any:
    """Where `evaluate`, `leaderboard` and `plan --tune` run their batches of episodes: None (here, in turn), or a
    RayExecutor for ``--ray`` (a local Ray) or ``--ray-address`` (agents/evaluation/distributed.py); the caller
    closes it."""
    if not (args.ray or args.ray_address):
        return None
    from .evaluation.distributed import RayExecutor

    return RayExecutor(address=args.ray_address)


def engine_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The config fields ``--set`` (a field of the scenario's config each), ``--engine`` and ``--pass-reuse-mm``
    set (none where they are not given: the preset's, the classic engine without reuse, with which every saved
    result was computed)."""
    given = list(getattr(args, "set", None) or [])
    names = [name.removeprefix("line_config.") for name, _ in given]  # a network's line field, as it is reported
    from .evaluation.line_compare import repeated

    twice = repeated(names)
    if twice:
        raise UsageError(f"--set {', '.join(twice)}: given more than once")
    out: dict[str, Any] = dict(zip(names, (value for _, value in given), strict=True))
    for field, flag in (("engine", args.engine), ("pass_reuse_tolerance_m", args.pass_reuse_mm)):
        if field in out and flag is not None:
            option = "--engine" if field == "engine" else "--pass-reuse-mm"
            raise UsageError(f"--set {field} and {option}: give one of them")
    if args.engine is not None:
        out["engine"] = args.engine
    if args.pass_reuse_mm is not None:
        if args.pass_reuse_mm > MAX_PASS_REUSE_MM:
            raise UsageError(f"--pass-reuse-mm must be in [0, {MAX_PASS_REUSE_MM:g}] mm, got {args.pass_reuse_mm:g}")
        out["pass_reuse_tolerance_m"] = args.pass_reuse_mm * 1e-3
    return out


def cmd_evaluate_line(args: argparse.Namespace) -> int:
    from .evaluation.line_compare import format_line_table, line_comparison, parse_seeds

    t0 = time.perf_counter()
    _scenario(args.env)
    seeds = parse_seeds(args.seeds) if args.seeds else None
    rules = _comma_items(args.rules, "--rules") if args.rules else None
    overrides = engine_overrides(args)
    extra = _line_policies(args)
    if {"horizon_years", "capacity"} & set(overrides):
        from .evaluation.line_compare import env_config, line_of
        from .planning import capacity_cut

        config = env_config(args.env, **overrides)
        _say_horizon_notes("evaluate", extra, {args.env: config.horizon_years})
        line = line_of(config)
        if capacity_cut(overrides, line):
            print(f"trackenv evaluate: note: --set capacity={overrides['capacity']:g} is more than the line file's "
                  f"{line.n_sections} sections: the line's capacity is {line.capacity} (trackenv plan refuses it)",
                  file=sys.stderr)
    executor = _executor(args)
    try:
        with _refusals_of("--rules", "rules"):
            result = line_comparison(args.env, seeds=seeds, rules=rules, n_train=args.n_train or 2,
                                     retune=args.retune, batch_size=args.batch_size, progress=not args.json,
                                     out_dir=args.out or "results/line_compare", extra=extra, executor=executor,
                                     **overrides)
    finally:
        if executor is not None:
            executor.close()
    result["wall_time_s"] = time.perf_counter() - t0
    result["ray"] = args.ray_address or ("local" if args.ray else None)
    _emit(args, result, format_line_table(result))
    return 0


def _leaderboard_policies(text: str, rule_names: Any) -> tuple[list[str] | None, dict[str, str]]:
    """``--policies``: comma-separated ``rules`` (every tuned rule), rule names and the agents of
    :func:`_policy_files`. Returns the rules (None: all tuned; with named ones, ``rules`` and those:
    :func:`~.evaluation.leaderboard.scored_rules`) and the agents by name -> path; an unknown name, a
    missing path, one that holds no trained policy, an item given twice or one policy given twice (the same file
    by two paths, or a baseline both by path and by ``baselines``: it would be scored twice) is a UsageError."""
    rules: list[str] = []
    agents: dict[str, str] = {}
    files: dict[Path, str] = {}  # each policy's file (resolved) -> the item that gave it
    every_rule = False
    for item in _comma_items(text, "--policies"):
        if item == "rules":
            every_rule = True
        elif item in rule_names:
            rules.append(item)
        else:
            for name, path in _policy_files(item, list(rule_names), agents).items():
                _once(files, path, item)
                agents[name] = path
    if not (every_rule or rules):
        raise UsageError("--policies names no rule: the normalised score's zero is the best tuned rule; add 'rules' "
                         "or a rule name")
    if every_rule:  # ("rules" and named rules: a named rule a scenario lacks is listed there as not scored)
        return (["rules", *rules] if rules else None), agents
    return rules, agents


def _policy_files(item: str, rule_names: list[str], agents: dict[str, str]) -> dict[str, str]:
    """The agents of one ``--policies`` item by name -> path: ``cpi-agent`` (the shipped agent),
    ``cpi-choice-agent`` (the shipped agent of the lines with every choice), ``cpi-track60-agent`` (the shipped
    agent of the 60 m track, scored where its planner advisor can plan), ``model-predictive`` (the planner, scored
    where a scenario measures every step without error; its name for a path), ``baselines`` (the committed
    baselines of experiments/saved/baselines/) or the path of a trained policy (a .zip of stable-baselines3, a
    folder of experiments/train_rllib.py; the kind is told by the files there,
    :func:`~trackenv_agents.learning.baselines.baseline_kind`), named by :func:`model_label` (by its absolute path
    where a rule, a shipped agent or one of ``agents`` has that name), or ``NAME=PATH``: that path named NAME."""
    from .rules.model_predictive import ModelPredictive

    if item in SHIPPED_AGENTS:
        _existing(str(SHIPPED_AGENTS[item]), f"--policies {item}")
        return {item: str(SHIPPED_AGENTS[item])}
    if item == ModelPredictive.name:  # no file: built where it is loaded
        return {item: item}
    if item == "baselines":
        from .learning.baselines import SAVED_BASELINES, saved_baselines

        found = saved_baselines()
        if not found:
            raise UsageError(f"--policies baselines: no trained baseline in {SAVED_BASELINES}")
        cwd = Path.cwd()  # shown (and saved in the leaderboard's params) relative to it where under it
        return {p.stem: str(p.relative_to(cwd) if p.is_relative_to(cwd) else p) for p in found}
    label, named, path = item.partition("=")
    if named and label and "/" not in label:  # NAME=PATH: the row's name given
        reserved = {*rule_names, *SHIPPED_AGENTS, *agents, "rules", "baselines", ModelPredictive.name}
        if label in reserved:
            raise UsageError(f"--policies {item}: the name {label!r} is taken (a rule, a shipped policy or another "
                             "item): give each policy a name of its own")
        return {label: next(iter(_policy_files(path, rule_names, agents).values()))}
    if item.endswith(".py"):
        raise UsageError(f"--policies {item}: the command takes trained policies by path (.zip, or a folder of "
                         "experiments/train_rllib.py), not Python code; score a policy object from Python with "
                         "trackenv_agents.evaluation.leaderboard.run_leaderboard(agents={'name': policy})")
    if item.endswith(".zip") or Path(item).exists():
        from .learning.baselines import baseline_kind

        try:
            baseline_kind(item)
        except (FileNotFoundError, ValueError) as err:
            raise UsageError(f"--policies: {err}") from None
        name = model_label(Path(item))  # as trackenv evaluate names it
        taken = name in agents or name in rule_names or name in SHIPPED_AGENTS
        return {os.path.abspath(item) if taken else name: item}
    raise UsageError(f"--policies: unknown policy {item!r}; give 'rules', a rule ({', '.join(rule_names)}), "
                     f"{', '.join(SHIPPED_AGENTS)}, {ModelPredictive.name}, 'baselines' or the path of a trained "
                     "policy (.zip, or a folder of experiments/train_rllib.py)")


def _once(files: dict[Path, str], path: str, item: str) -> None:
    """Record the file of a ``--policies`` item in ``files`` (resolved -> the item), refusing one given before by
    another item (another spelling of its path, or a baseline given by path and by ``baselines``)."""
    if not Path(path).exists():  # the planner: no file
        return
    key = Path(path).resolve()
    if key in files:
        raise UsageError(f"--policies {item}: the same policy as {files[key]} ({key}): give each policy once")
    files[key] = item


def _comma_items(text: str, option: str) -> list[str]:
    """The items of a comma-separated option, stripped; an empty item (a comma too many) or one given twice (it
    would be scored twice) is a UsageError naming ``option``."""
    items = [x.strip() for x in text.split(",")]
    if "" in items:
        raise UsageError(f"{option} {text!r}: an empty item (a comma too many?)")
    from .evaluation.line_compare import repeated

    twice = repeated(items)
    if twice:
        raise UsageError(f"{option} {', '.join(twice)}: given more than once")
    return items


@contextlib.contextmanager
def _refusals_of(option: str, parameter: str | None = None) -> Iterator[None]:
    """Within: a library's ValueError about what ``option`` gives (each one; with ``parameter``, those whose
    message starts with that parameter's name, as "rules must ...") is the command's one-line refusal naming
    ``option`` first ("--rules: rules must ..."); any other passes as it is."""
    try:
        yield
    except ValueError as err:
        if parameter is not None and not str(err).startswith(f"{parameter} "):
            raise
        raise UsageError(f"{option}: {err}") from None


def _scenario(env_id: str) -> str:
    """The preset of ``--env`` (:func:`~.evaluation.line_compare.scenario_of`): an unknown id, a file or an id
    without per-section actions is one line naming ``--env``, before anything slow."""
    from .evaluation.line_compare import scenario_of

    with _refusals_of("--env"):
        return scenario_of(env_id)


@contextlib.contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """Meanwhile file descriptor 1 writes to stderr: the MIP solver behind the hindsight bound (HiGHS, C code)
    prints lines on stdout that Python cannot catch, and stdout carries the summary (``--json``: one JSON
    object) only."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def cmd_leaderboard(args: argparse.Namespace) -> int:
    """`trackenv leaderboard`: every policy on every scenario of the suite, scored against the best tuned rule and
    the hindsight bound (agents/evaluation/leaderboard.py); writes DIR/leaderboard.json and DIR/leaderboard.md."""
    from .evaluation.leaderboard import DEFAULT_SUITE, format_leaderboard, run_leaderboard, write_leaderboard
    from .evaluation.line_compare import parse_seeds
    from .rules.problems import every_rule

    envs = _comma_items(args.env, "--env") if args.env else list(DEFAULT_SUITE)
    for env_id in envs:
        _scenario(env_id)  # an unknown id: one line, before anything slow
    seeds = parse_seeds(args.seeds) if args.seeds else None
    overrides = engine_overrides(args)
    rules, agent_files = _leaderboard_policies(args.policies, list(every_rule()))
    agents: dict[str, Any] = {}
    if agent_files:
        from .learning.baselines import load_baseline
        from .rules.model_predictive import ModelPredictive

        agents = {name: ModelPredictive() if path == ModelPredictive.name else load_baseline(path, name=name)
                  for name, path in agent_files.items()}
    if agents:
        from .evaluation.leaderboard import fitting_agents
        from .evaluation.line_compare import env_config

        configs = {env_id: env_config(env_id, **overrides) for env_id in envs}
        fits = {env_id: fitting_agents(agents, config) for env_id, config in configs.items()}
        if "horizon_years" in overrides:
            for env_id, (here, _) in fits.items():  # each scenario's note for the agents scored there only
                _say_horizon_notes("leaderboard", here, {env_id: configs[env_id].horizon_years})
        for name in agents:  # a policy asked for and scored nowhere: say why where the page only groups it
            if all(name in unfit for _, unfit in fits.values()):
                why = "; ".join(f"{env_id}: {unfit[name]}" for env_id, (_, unfit) in fits.items())
                print(f"trackenv leaderboard: note: {name} is scored on none of the scenarios given ({why})",
                      file=sys.stderr)
    executor = _executor(args)
    out = Path(args.out or "results/leaderboard")
    t0 = time.perf_counter()
    try:
        with _stdout_to_stderr(), _refusals_of("--policies", "rules"):
            payload = run_leaderboard(envs, rules=rules, agents=agents, seeds=seeds, bound=not args.no_bound,
                                      out_dir=out, executor=executor, progress=not args.json, write=False,
                                      **overrides)
    finally:
        if executor is not None:
            executor.close()
    payload["command"] = " ".join(["trackenv leaderboard", *args.argv])
    payload["wall_time_s"] = time.perf_counter() - t0
    payload["ray"] = args.ray_address or ("local" if args.ray else None)
    table = format_leaderboard(payload)
    payload["files"] = write_leaderboard(payload, out)
    _emit(args, payload, f"{table}\nwrote {', '.join(payload['files'])} in {payload['wall_time_s']:.0f} s")
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    """Load the line (or network) first (a fault in it: one line, exit 2, before anything slow), then plan and
    write (with ``--compare``, each policy's plan on the same futures, and the comparison)."""
    from trackenv.envs.line_file import load_line
    from trackenv.envs.network_file import load_network_or_none

    from .planning import check_capacity, line_policy, plan_config

    network = load_network_or_none(args.line)  # the file read once; None: a line file
    lines = network.lines if network is not None else (load_line(args.line),)
    overrides = engine_overrides(args)
    for field, own in (("line", "the line file argument"), ("horizon_years", "--years")):
        if field in overrides:
            raise UsageError(f"--set {field}: the plan takes it from {own}")
    policies = [args.policy]
    if args.compare is not None:
        from .plan_compare import check_compared

        if args.tune:
            raise UsageError("--compare runs each policy with its shipped parameters: tune one policy at a time "
                             "(--policy NAME --tune N)")
        if args.policy != DEFAULT_PLAN_POLICY:
            raise UsageError("give the policies to compare in --compare, not --policy")
        policies = check_compared(_comma_items(args.compare, "--compare"))  # an empty item refused, as elsewhere
    if network is not None:
        from .network_plan import check_network_policy

        for policy in policies:
            check_network_policy(policy)
        network.config(**overrides)  # the lines' dates and the machine's fields, before the fit and the futures
    # an unknown policy or scenario (and what --tune cannot tune) before the fit and the futures
    if network is None:
        config = plan_config(lines[0], args.scenario, years=args.years, **overrides)
        check_capacity(overrides, config)  # (plan_line checks it too, after the start's progress bar)
    else:
        from .network_plan import line_fields

        config = plan_config(lines[0], args.scenario, years=args.years, **line_fields(lines[0], overrides))
    rules = [line_policy(policy, config, args.scenario, years=args.years) for policy in policies]
    if args.tune:
        from .plan_tuning import check_apart, check_tunable

        check_tunable(rules[0], args.tune)
        check_apart(args.seed, args.futures, args.tune)
    else:
        for given, option in ((args.ray, "--ray"), (args.ray_address, "--ray-address"),
                              (args.batch_size, "--batch-size")):
            if given:
                raise UsageError(f"{option} is for --tune's episodes: give --tune N (a plan's own futures run in "
                                 f"one vector env, here)")
    t0 = time.perf_counter()
    out = Path(args.out or "results/plan")
    if args.compare is None:
        executor = _executor(args)
        try:
            plan = _one_plan(args, network, lines, args.policy, overrides, executor=executor)
        finally:
            if executor is not None:
                executor.close()
        notes = _plan_warnings(plan, network)
        _say_warnings(notes)
        files = plan.write(out)
        d = plan.to_dict(files) if network is not None else plan.to_dict()  # a network's lines: their files too
        payload = {**d, "files": files, "warnings": notes, "wall_time_s": time.perf_counter() - t0,
                   "ray": args.ray_address or ("local" if args.ray else None)}
        _emit(args, payload, plan.table() + "\n" + _warnings_line(notes) + "wrote " + ", ".join(files.values()))
        return 0
    return _compare_and_write(args, network, lines, policies, rules, overrides, out, t0)


def _compare_and_write(args: argparse.Namespace, network: Any, lines: Any, policies: list[str], rules: list[Any],
                       overrides: dict[str, Any], out: Path, t0: float) -> int:
    """``trackenv plan --compare``: each of ``policies`` (their bound ``rules``) planned on the same futures (in
    episodes of one length: a trained policy's, where one is compared), their comparison and files; a trained
    policy given by its path is named by its folder and file (:func:`model_label`)."""
    from .plan_compare import compare_plans, format_comparison, write_comparison
    from .planning import trained_horizon_years

    labels = [model_label(Path(p)) if p not in SHIPPED_AGENTS and Path(p).exists() else p for p in policies]
    if len(set(labels)) < len(labels):  # two models of one folder and file name: their paths
        labels = list(policies)
    trained = {name: h for name, rule in zip(labels, rules, strict=True)
               if (h := trained_horizon_years(rule)) is not None}
    if len(set(trained.values())) > 1:
        raise UsageError(f"--compare: the trained policies read the time left in training episodes of different "
                         f"lengths ({', '.join(f'{n} {h:g} years' for n, h in trained.items())}): compare them "
                         f"apart")
    episode = next(iter(trained.values()), None)
    plans, written, notes, folders = {}, {}, [], []
    for k, (policy, label) in enumerate(zip(policies, labels, strict=True)):
        plans[label] = plan = _one_plan(args, network, lines, policy, overrides, f"{label} ({k + 1} of "
                                                                                 f"{len(policies)})", episode)
        notes += [f"{label}: {note}" for note in _plan_warnings(plan, network)]
        folders.append(out / f"{k + 1}-{Path(policy).stem}")
        written[label] = plan.write(folders[-1])
    _say_warnings(notes)
    comparison = compare_plans(plans, episode)
    files = {"compare_csv": write_comparison(comparison, out)}
    payload = {"comparison": comparison, "files": files, "plan_files": written, "warnings": notes,
               "wall_time_s": time.perf_counter() - t0}
    whose = ("each policy's plan in these futures (a rule's own --policy plan runs shorter episodes: other draws)"
             if episode is not None else "each policy's plan (as --policy plans it)")
    _emit(args, payload, f"{format_comparison(comparison)}\n{whose}: {', '.join(map(str, folders))}\n"
                         f"{_warnings_line(notes)}wrote {files['compare_csv']}")
    return 0


#: At most this many of a plan's warnings are printed on stderr (the JSON's "warnings" has every one).
PRINTED_WARNINGS = 8


def _say_horizon_notes(command: str, policies: dict[str, Any], horizons: dict[str, float]) -> None:
    """A note on stderr for each trained policy scored in episodes (``horizons``: env id -> years, a ``--set
    horizon_years``) of another length than it was trained on: its ``time`` feature, the share of the episode gone,
    then runs at another pace than it learnt it (``trackenv plan --compare`` runs such a policy's episodes at its
    own length instead)."""
    from .planning import trained_horizon_years

    for name, policy in policies.items():
        trained = trained_horizon_years(policy)
        for env_id, years in horizons.items():
            if trained is not None and abs(trained - years) > 1e-9:
                print(f"trackenv {command}: note: {name} was trained on {trained:g}-year episodes and is scored "
                      f"here on {years:g}-year ones of {env_id} (--set horizon_years): its time feature, the share "
                      f"of the episode gone, now runs {trained / years:g} times as fast as it learnt it",
                      file=sys.stderr)


def _say_warnings(notes: list[str]) -> None:
    """A plan's warnings on stderr, at most :data:`PRINTED_WARNINGS` (a file in a wrong unit warns for every
    section), the rest counted."""
    for note in notes[:PRINTED_WARNINGS]:
        print(f"trackenv plan: warning: {note}", file=sys.stderr)
    if len(notes) > PRINTED_WARNINGS:
        print(f"trackenv plan: warning: ... and {len(notes) - PRINTED_WARNINGS} more (--json lists every one)",
              file=sys.stderr)


def _warnings_line(notes: list[str]) -> str:
    """The table's line that counts the plan's warnings (stderr has them): "" where there are none."""
    from .plan_report import counted

    return f"{counted(len(notes), 'warning', 'warnings')} on stderr (the JSON's \"warnings\")\n" if notes else ""


def _plan_warnings(plan: Any, network: Any) -> list[str]:
    """The warnings of a line's plan, or of every line of a network's (:func:`~.planning.plan_warnings`)."""
    from .planning import plan_warnings

    lines = plan.lines if network is not None else (plan,)
    return [note for line in lines for note in plan_warnings(line, alone=network is None)]


def _one_plan(args: argparse.Namespace, network: Any, lines: Any, policy: str, overrides: dict[str, Any],
              label: str | None = None, episode_years: float | None = None, executor: Any = None) -> Any:
    """The plan of ``policy`` on the line or ``network`` with the command's options (``label``: what its
    progress bar says it plans, where several run; ``episode_years``: the futures' episode length, as
    :func:`~trackenv_agents.planning.plan_line` takes it; ``executor``: where ``--tune`` runs its batches), with
    its progress bars on stderr (none with ``--json``)."""
    from trackenv.envs.line_fit import FitWarning

    from .planning import plan_line

    progress, bar = None, None
    if not args.json:
        from tqdm import tqdm

        running = f"plan {label} (quarters)" if label else "plan (quarters)"

        def new_bar(desc: str) -> Any:
            return tqdm(total=int(round(args.years * 4)), desc=desc, file=sys.stderr, leave=False)

        # with --tune the tuning's bars show the start, and the quarters' bar starts after them
        bar = None if args.tune else new_bar(_start_text(lines))

        def progress(n: int) -> None:
            nonlocal bar
            if bar is None:
                bar = new_bar(running)
            elif bar.n == 0:  # started: the bar counts the quarters from now on
                bar.set_description(running, refresh=False)
            bar.update(n)
    elif args.tune:
        from .plan_report import counted

        futures = counted(args.tune, "ten-year future", "ten-year futures")
        where = "each line" if network is not None else "the line"
        print(f"trackenv plan: tuning {policy} on {futures} of {where} first (minutes; no progress bars with "
              f"--json)", file=sys.stderr)
    kwargs = dict(policy=policy, years=args.years, futures=args.futures, seed=args.seed, scenario=args.scenario,
                  progress=progress, episode_years=episode_years, **overrides)
    if args.tune:
        kwargs.update(tune=args.tune, executor=executor, batch_size=args.batch_size or 32)
    try:
        with warnings.catch_warnings():  # the fit's notes are said after the progress bar, not inside it
            warnings.simplefilter("ignore", FitWarning)
            # a section beyond the model's validity: the plan names it by its id (the engine's warning, by its row)
            warnings.filterwarnings("ignore", message=".*has left the model's validity", category=RuntimeWarning)
            if network is not None:
                from .network_plan import plan_network

                return plan_network(network, **kwargs)
            return plan_line(lines[0], **kwargs)
    finally:  # an error is said on a line of its own, not after the bar
        if bar is not None:
            bar.close()


def _start_text(lines: Any) -> str:
    """The progress bar's text until the first quarter is done: the plan's start draws every line and fits the
    history of each section that has one (seconds per 100 such sections, either engine: 17 s for five lines of
    430 sections on two cores, minutes on a large network) while the bar stands at 0, so it says what it waits
    for. ``lines``: the plan's line descriptions."""
    sections = sum(len(line.sections) for line in lines)
    fitted = sum(len({m.section for m in line.history}) for line in lines)
    fits = f", fitting the histories of {fitted} sections that have one" if fitted else ""
    what = f"{len(lines)} lines" if len(lines) > 1 else "the line"
    return f"plan: starting {what} ({sections} sections{fits}; once per plan)"


def cmd_calibrate(args: argparse.Namespace) -> int:
    from trackenv_studies.calibration import format_calibration

    from .evaluation.line_compare import parse_seeds, run_calibration

    overrides = {"horizon_years": args.horizon_years} if args.horizon_years is not None else {}
    result = run_calibration(args.scenario, parse_seeds(args.seeds), args.threshold,
                             out_dir=args.out or "results/line_calibration", progress=not args.json, **overrides)
    result.pop("trajectories", None)
    _emit(args, result, format_calibration(result) + f"\nplot: {result['plot']}")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    """`trackenv evaluate`: the tuned rules and the trained agent on held-out episodes of one preset, paired."""
    return cmd_evaluate_line(args)


def _line_payload(path: Path, wall: float, out: Path, note: str = "") -> tuple[dict[str, Any], str]:
    """The JSON payload and the human summary of a line training run (from its summary.json; ``note`` ends its
    last line, :func:`_set_note`), and last a warning where the best held-out evaluation of ``best_model.zip`` (the
    best iteration's, or after a PPO stage, which keeps it from its own evaluations, that stage's best) is dearer
    than the advisor rule (:func:`~.learning.line.dearer_than_advisor`; the payload's ``warning``, else None)."""
    from .evaluation.reporting import ci_text, count_text
    from .learning.line import dearer_than_advisor

    summary = json.loads((out / "summary.json").read_text())
    evals = [it["evaluation"] for it in summary["iterations"] if "evaluation" in it]
    what = "iteration"
    ppo = [e for e in (summary.get("ppo") or {}).get("evaluations") or [] if "vs_baseline" in e]
    if ppo:  # the PPO stage keeps best_model.zip from its own evaluations (its first: the best iteration's policy)
        evals = [{**e, "mean_cost": -e["mean_return"]} for e in ppo]
        what = "evaluation of the PPO stage"
    best = min(evals, key=lambda e: e["mean_cost"]) if evals else None
    warning = None if best is None else dearer_than_advisor(best, what)
    payload = {"model": str(path), "wall_time_s": wall, **summary, "warning": warning}
    human = f"trained -> {path} in {wall:.0f} s"
    if best is not None:
        d = best["vs_baseline"]
        after = f" (after {best['timesteps']} section-steps)" if "timesteps" in best else ""
        human += (f"\nbest held-out {what}{after}: {best['mean_cost']:.1f} k€, vs {d['b']} "
                  f"{d['mean_difference']:+.1f} k€ "
                  f"{ci_text(d['ci_low'], d['ci_high'], d['n_episodes'], signed=True)} on "
                  f"{count_text(d['n_episodes'], 'paired episode')} "
                  f"(best_model.zip; export it with experiments/train_line.py --export)")
    return payload, human + note + ("" if warning is None else f"\n{warning}")


def cmd_train_line(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """`trackenv train --env trackenv/TampingLine-v0`: counterfactual policy iteration (and MaskablePPO for
    --timesteps line-steps) on the line, held-out evaluation paired with the advisor rule."""
    if args.algo:
        raise UsageError("--algo is for the 60 m track (Tamping-v1); the line's learner reads its algorithm from the "
                         "hyper-parameter file")
    from trackenv.envs.line_config import scenario

    from .learning.line import train_line

    name = _scenario(args.env)
    if name == "network":
        raise UsageError(f"--env {args.env}: the learner trains a line's policy; train it on the network's line "
                         "(--env trackenv/TampingLine-v0), and every line of the network plays it (trackenv "
                         f"evaluate --env {args.env} --model PATH)")
    t0 = time.perf_counter()
    out = Path(args.out or "runs/ppo_line")
    config = scenario(name, **overrides) if overrides else name
    path = train_line(config, total_timesteps=args.timesteps, n_envs=args.n_envs, seed=args.seed,
                      out_dir=out, hyperparams=args.hyperparams, progress=not args.json,
                      iterations=args.iterations, verbose=0 if args.json else 1,
                      checkpoint_every_s=args.checkpoint_every)
    payload, human = _line_payload(path, time.perf_counter() - t0, out, _set_note(overrides))
    _emit(args, {**payload, "config_changes": _set_fields(overrides)}, human)
    return 0


def cmd_train_resume(args: argparse.Namespace) -> int:
    """`trackenv train --resume DIR`: continue the run in DIR (either trainer) from its last checkpoint, with the
    settings it was started with; a finished run says so and is left as it is."""
    run_dir = Path(args.resume)
    given = {"--algo": args.algo, "--n-envs": args.n_envs, "--hyperparams": args.hyperparams, "--env": args.env,
             "--iterations": args.iterations,
             "--seed": None if args.seed == DEFAULT_TRAIN_SEED else args.seed,
             "--out": None if args.out is None or Path(args.out).resolve() == run_dir.resolve() else args.out}
    for flag, value in given.items():
        if value is not None:
            raise UsageError(f"--resume continues {run_dir} with the settings it was started with; drop {flag}")
    from .learning.checkpoint import read_checkpoint_info, read_run_meta

    meta = read_run_meta(run_dir)  # FileNotFoundError naming what is missing: one line, status 2
    info = read_checkpoint_info(run_dir)
    line = meta.get("trainer") == "line"
    if line and args.timesteps is not None:
        raise UsageError(f"--resume continues the line's run in {run_dir} to the totals it was started with; drop "
                         "--timesteps")
    total = info["total"] if line or args.timesteps is None else args.timesteps
    if info.get("finished") and info["done"] >= total:
        model = run_dir / "model.zip"
        payload = {"model": str(model), "finished": True, "done": info["done"], "total": total, "unit": info["unit"]}
        _emit(args, payload, f"{run_dir} is finished ({info['done']} of {total} {info['unit']}); nothing to resume. "
                             f"Its model: {model}")
        return 0
    t0 = time.perf_counter()
    common = {"resume": run_dir, "progress": not args.json, "verbose": 0 if args.json else 1,
              "checkpoint_every_s": args.checkpoint_every}
    if line:
        from .learning.line import train_line

        path = train_line(**common)
        _emit(args, *_line_payload(path, time.perf_counter() - t0, run_dir))
        return 0
    from .learning.tamping import train

    path = train(total_timesteps=args.timesteps, workers=args.workers, **common)
    summary = json.loads((run_dir / "summary.json").read_text())
    payload = {"model": str(path), "wall_time_s": time.perf_counter() - t0, **summary}
    _emit(args, payload, f"resumed at {summary['resumed_from_timesteps']} timesteps, trained to "
                         f"{summary['timesteps']} -> {path} in {payload['wall_time_s']:.0f} s")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    _existing(args.hyperparams, "--hyperparams")
    _existing(args.resume, "--resume", folder=True)
    overrides = engine_overrides(args)
    if args.resume is not None:
        if overrides:
            raise UsageError("--engine, --pass-reuse-mm and --set: a resumed run keeps the config it was started "
                             "with")
        return cmd_train_resume(args)
    if args.env is not None and args.env != DEFAULT_ENV_ID:
        return cmd_train_line(args, overrides)
    if args.iterations is not None:
        raise UsageError("--iterations is for a TampingLine --env (its counterfactual policy iteration)")
    if "line" in overrides:
        raise UsageError(f"--set line: a line file trains as a line: --env trackenv/TampingLine-v0 --set "
                         f"line={overrides['line']} (the default --env, {DEFAULT_ENV_ID}, is the 60 m track: one "
                         f"segment of six sections)")
    from .learning.tamping import train

    t0 = time.perf_counter()
    config = None
    if overrides:
        from trackenv.envs.line_config import scenario

        config = scenario("track60", **overrides)  # the preset of DEFAULT_ENV_ID
    path = train(
        algo=args.algo,
        config=config,
        total_timesteps=args.timesteps,
        n_envs=args.n_envs,
        seed=args.seed,
        out_dir=args.out or "runs/ppo",
        progress=not args.json,
        verbose=0 if args.json else 1,  # --json: one JSON object on stdout, no training log
        hyperparams=args.hyperparams,
        workers=args.workers,
        checkpoint_every_s=args.checkpoint_every,
    )
    wall = time.perf_counter() - t0
    payload = {"model": str(path), "wall_time_s": wall, "config_changes": _set_fields(overrides)}
    _emit(args, payload, f"trained -> {path} in {wall:.0f} s{_set_note(overrides)}")
    return 0


def _set_fields(overrides: dict[str, Any]) -> dict[str, Any]:
    """The fields of ``overrides`` besides the engine's options (which the tables name on their own)."""
    from .evaluation.line_compare import without_engine

    return without_engine(overrides)


def _set_note(overrides: dict[str, Any]) -> str:
    from .evaluation.line_compare import changes_note

    return changes_note(_set_fields(overrides))


def _at_most(parse: Callable[[str], Any], high: float) -> Any:
    """An argparse type: what ``parse`` reads, at most ``high``."""

    def bounded(text: str) -> Any:
        value = parse(text)
        if value > high:
            raise argparse.ArgumentTypeError(f"must be at most {high:g}, got {text}")
        return value

    return bounded


def _positive(kind: type, zero: bool = False) -> Any:
    """An argparse type: a number of ``kind`` (int or float) that is finite and > 0 (>= 0 if ``zero``); ``1e5``
    is a whole number."""

    def parse(text: str) -> Any:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not (math.isfinite(value) and (value >= 0 if zero else value > 0)):
            raise argparse.ArgumentTypeError(f"must be a number {'>=' if zero else '>'} 0, got {text}")
        if kind is int:
            if value != int(value):
                raise argparse.ArgumentTypeError(f"must be a whole number, got {text}")
            return int(value)
        return value

    parse.__name__ = f"positive {kind.__name__}"
    return parse


class _HelpFormatter(argparse.HelpFormatter):
    """Appends ``(default: X)`` to an option's help unless the default is None or False or already shown."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "%(default)" in text or action.default in (None, False, argparse.SUPPRESS) or not action.option_strings:
            return text
        return f"{text} (default: %(default)s)"


def _hyperparam_defaults() -> dict[str, Any]:
    """The shipped hyper-parameters' algo, total_timesteps and n_envs (for the help text only; a plain YAML
    read of the RL Zoo entry, no torch)."""
    try:
        import yaml

        entry = yaml.safe_load(HYPERPARAMS_FILE.read_text())[DEFAULT_ENV_ID]
        return {"algo": (entry.get("trackenv") or {}).get("algo", "ppo"),
                "total_timesteps": entry.get("n_timesteps", "n/a"), "n_envs": entry.get("n_envs", "n/a")}
    except Exception:  # pragma: no cover - a broken install; the help still answers
        return {}


def _field_value(text: str) -> tuple[str, Any]:
    """``--set FIELD=VALUE``: the field's name and its value read as YAML (a number, true/false, a list as a
    tuple, else the text); the config checks the name and the value when it is built."""
    import yaml

    name, sep, value = text.partition("=")
    if not sep or not name.strip() or not value.strip():
        raise argparse.ArgumentTypeError(f"expected FIELD=VALUE (e.g. annual_mgt=30), got {text!r}")
    try:
        parsed = _numbers(yaml.safe_load(value))
    except yaml.YAMLError:
        parsed = value
    return name.strip(), tuple(parsed) if isinstance(parsed, list) else parsed


def _numbers(value: Any) -> Any:
    """``value`` with every text that reads as a number a number (YAML 1.1 reads ``1e-3`` as text), inside lists
    and mappings too."""
    if isinstance(value, str):
        for kind in (int, float):
            try:
                return kind(value)
            except ValueError:
                continue
        return value
    if isinstance(value, list):
        return [_numbers(v) for v in value]
    if isinstance(value, dict):
        return {k: _numbers(v) for k, v in value.items()}
    return value


def _widths(text: str) -> list[int]:
    """``--widths``: comma-separated kernel widths, each one of the kernel's (checked when the command runs)."""
    try:
        return [int(w) for w in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None


class _Parser(argparse.ArgumentParser):
    """argparse's parser whose errors (an unknown option, a value out of range) are one line on stderr with exit
    status 2, as every other refusal of the CLI, instead of the usage block and then the error."""

    #: each command's parser by name (the top-level parser's): an unknown option is reported by its command
    commands: Mapping[str, argparse.ArgumentParser]

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")

    def parse_command(self, argv: list[str] | None) -> argparse.Namespace:
        """:meth:`parse_args`, but an unknown option is reported by the command it was given to (whose ``--help``
        lists the options), not by ``trackenv``; ``--seeds -1:3`` is read as ``--seeds=-1:3``
        (:func:`_seeds_joined`)."""
        parsed, extra = self.parse_known_args(_seeds_joined(sys.argv[1:] if argv is None else argv))
        if extra:
            command = self.commands.get(getattr(parsed, "command", None) or "", self)
            command.error(f"unrecognized arguments: {' '.join(extra)}")
        return parsed


def _seeds_joined(argv: list[str]) -> list[str]:
    """``argv`` with ``--seeds -1:3`` written ``--seeds=-1:3``: argparse takes a value that starts with '-' and is
    no plain number for an option ("expected one argument"); joined, the seeds reach
    :func:`~.evaluation.line_compare.parse_seeds`, which says that seeds are >= 0."""
    out: list[str] = []
    for token in argv:
        if out and out[-1] == "--seeds" and token[:1] == "-" and token[1:2].isdigit():
            out[-1] = f"--seeds={token}"
        else:
            out.append(token)
    return out


def build_parser() -> _Parser:
    p = _Parser(
        prog="trackenv", formatter_class=_HelpFormatter,
        description="Railway track tamping on vehicle-track dynamics and ballast settlement: check the model, "
                    "reproduce the paper, time it, score and train maintenance policies.",
        epilog="`trackenv COMMAND --help` lists a command's options. Results go under results/ (runs/ for "
               "training); --json prints one JSON object instead of the summary.")
    p.add_argument("--version", action="version", version=f"%(prog)s {installed_version()}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    p.commands = sub.choices  # each command's parser, by name: its errors name it

    def command(name: str, help: str) -> argparse.ArgumentParser:
        sp = sub.add_parser(name, help=help, description=help, formatter_class=_HelpFormatter)
        sp.add_argument("--json", action="store_true", help="print one JSON object instead of a summary")
        return sp

    def out(sp: argparse.ArgumentParser, default: str) -> None:
        sp.add_argument("--out", default=None, metavar="DIR", help=f"output folder (default: {default})")

    def engine(sp: argparse.ArgumentParser, plan: bool = False) -> None:
        what = ("a field of every line's config (trackenv.envs.LineConfig) but those its file sets (sections, "
                "lengths, speeds, traffic), e.g. --set capacity=4 --set geometry_cost_per_section_year=3"
                if plan else "a field of the scenario's config (trackenv.envs.LineConfig; on the network its own "
                "fields or its line's), e.g. --set annual_mgt=30 --set capacity=4")
        sp.add_argument("--set", type=_field_value, action="append", default=None, metavar="FIELD=VALUE",
                        help=f"change {what}; the tuned rules keep the preset's parameters"
                             f"{' (--tune tunes them on the line)' if plan else ''}, and the JSON records the config")
        sp.add_argument("--engine", choices=ENGINES, default=None,
                        help="how the passes run: classic (every preset's default, with which every saved result "
                             "was computed) or fast (a converged start and shorter windows: a line step's costs "
                             "within a few hundredths of a percent; the documentation's Performance page)")
        sp.add_argument("--pass-reuse-mm", type=_positive(float, zero=True), default=None, metavar="MM",
                        help=f"reuse a segment's last pass while its level has changed by less than MM mm at every "
                             f"sleeper, in [0, {MAX_PASS_REUSE_MM:g}] (0: off, every preset's default; with "
                             f"--engine fast, 1 mm evaluates the default line about 3 times as fast, costs within "
                             f"a quarter of a percent)")

    sp = command("validate", "static, receptance and moving-wheelset checks against closed forms, with plots")
    out(sp, "results/validation")
    sp.add_argument("--no-plots", action="store_true", help="write summary.json only, no PNG figures")
    sp.set_defaults(func=cmd_validate)

    sp = command("paper", "reproduce the paper's settlement scenarios (Fig. 10 and 11)")
    out(sp, "results/paper")
    sp.add_argument("--iterations", type=_positive(int), default=6, metavar="N",
                    help="settlement iterations (one dynamic pass each)")
    sp.add_argument("--cycles", type=_positive(float), default=50_000, metavar="N",
                    help="axle passes (load cycles) per iteration")
    sp.add_argument("--no-plots", action="store_true", help="write paper.json only, no PNG figures")
    sp.set_defaults(func=cmd_paper)

    sp = command("compile", "build every compiled entry of the physics kernel up front (make setup runs it)")
    sp.add_argument("--widths", type=_widths, default=None, metavar="W,W",
                    help="only these batch widths (rows per chunk; default: all)")
    sp.add_argument("--jobs", type=_positive(int), default=None, metavar="N",
                    help="compile up to N widths at once, each in its own process (default: the usable cores)")
    sp.set_defaults(func=cmd_compile)

    sp = command("bench", "speed of the dynamics, the settlement loop and the env")
    sp.add_argument("--quick", action="store_true", help="fewer repeats: rougher figures in a few seconds")
    sp.set_defaults(func=cmd_bench)

    sp = command("evaluate", "score the tuned rules and the trained agent on held-out episodes, paired")
    out(sp, "results/line_compare")
    sp.add_argument("--env", default="trackenv/TampingLine-v0", metavar="ID",
                    help="the preset: trackenv/TampingLine-v0 (default), ...Small-v0, ...Hard-v0, the 60 m track "
                         "trackenv/Tamping-v1, the ids with every choice (trackenv/TampingLine-v1, ...Wet-v0, "
                         "...Defects-v0) or the network trackenv/TampingNetwork-v0")
    sp.add_argument("--seeds", default=None, metavar="A:B",
                    help=f"held-out episodes: A:B (seeds A..B-1) or a,b,c; whole numbers >= 0 (no negative seed), "
                         f"at most {MAX_EPISODES} episodes (default 0:8)")
    sp.add_argument("--policy", choices=("all", "agent", "rules"), default="all",
                    help="which policies to score: all, the tuned rules and the trained agent, with the "
                         "model-predictive planner where the preset measures every step without error (the 60 m "
                         "track); agent, the trained agent (refused where there is none) and the tuned rules it is "
                         "compared with (its paired difference to the best of them; --rules NAMES scores fewer, "
                         "e.g. --rules grouped-threshold); rules, the tuned rules alone")
    sp.add_argument("--model", default=None, metavar="ZIP",
                    help=f"a trained policy: a per-section policy of trackenv train --env ID (any line), a model of "
                         f"trackenv train (the line it was trained on) or a folder of experiments/train_rllib.py "
                         f"(default: the shipped {LINE_AGENT_NAME}, "
                         f"agents/learning/pretrained/ppo_tamping_line.zip; on the ids with every choice "
                         f"{CHOICE_AGENT_NAME}, agents/learning/pretrained/cpi_choice_line.zip; on the 60 m track "
                         f"{TRACK60_AGENT_NAME}, agents/learning/pretrained/cpi_track60.zip)")
    sp.add_argument("--rules", default=None, metavar="NAMES",
                    help="score only these rules, comma-separated (e.g. grouped-threshold,uniform-periodic; "
                         "default: all)")
    sp.add_argument("--retune", action="store_true",
                    help="tune the rules again on the training seeds instead of using the shipped parameters")
    sp.add_argument("--n-train", type=_positive(int), default=None, metavar="N",
                    help="training episodes for --retune (seeds 1000..1000+N-1; default 2)")
    sp.add_argument("--batch-size", type=_positive(int), default=32, metavar="N",
                    help="episodes per batch (one vector env, one task)")
    sp.add_argument("--ray", action="store_true", help="run the batches as tasks on a local Ray (trackenv[ray])")
    sp.add_argument("--ray-address", default=None, metavar="ADDR",
                    help="run the batches on a Ray cluster: 'auto' on a cluster node, or ray://HEAD:10001")
    engine(sp)
    sp.set_defaults(func=cmd_evaluate)

    sp = command("leaderboard", "every policy on every scenario of the suite on fixed held-out seeds, scored "
                                "against the best tuned rule and the hindsight bound")
    out(sp, "results/leaderboard")
    sp.add_argument("--env", default=None, metavar="ID[,ID...]",
                    help="the scenarios, each once (default: the suite of agents/evaluation/leaderboard.py "
                         "DEFAULT_SUITE: the three lines, the 60 m track, the three lines with every choice and the "
                         "network trackenv/TampingNetwork-v0)")
    sp.add_argument("--seeds", default=None, metavar="A:B",
                    help=f"held-out episodes of every scenario: A:B (seeds A..B-1) or a,b,c; whole numbers >= 0 "
                         f"(no negative seed), at most {MAX_EPISODES} episodes (default: each scenario's, "
                         "agents/evaluation/leaderboard.py DEFAULT_SEEDS)")
    sp.add_argument("--policies", default=f"rules,{LINE_AGENT_NAME}", metavar="NAMES",
                    help="comma-separated, each once: 'rules' (every tuned rule), rule names (each scored where "
                         "the scenario's rules include it, listed as not scored elsewhere), "
                         f"{LINE_AGENT_NAME} (the shipped agent), {CHOICE_AGENT_NAME} (the shipped agent of the "
                         f"lines with every choice), {TRACK60_AGENT_NAME} (the shipped agent of the 60 m track, "
                         "scored there only), model-predictive (the planner, scored where a scenario measures every "
                         "step without error), baselines (those committed in "
                         "experiments/saved/baselines/), paths of trained policies (a stable-baselines3 "
                         ".zip, a folder of experiments/train_rllib.py; each scored on the line it was trained on, "
                         "a per-section policy on every line), each named by its folder and file or as NAME=PATH")
    sp.add_argument("--no-bound", action="store_true",
                    help="skip the hindsight bound (the normalised scores are then null)")
    engine(sp)
    sp.add_argument("--ray", action="store_true", help="run the episodes and the bound's searches as tasks on a "
                                                      "local Ray (trackenv[ray])")
    sp.add_argument("--ray-address", default=None, metavar="ADDR",
                    help="run them on a Ray cluster: 'auto' on a cluster node, or ray://HEAD:10001")
    sp.set_defaults(func=cmd_leaderboard)

    sp = command("plan", "what to do on a line (or a network of lines sharing a tamping machine) from its file, "
                         "quarter by quarter, with the cost forecast")
    out(sp, "results/plan")
    sp.add_argument("line", metavar="FILE.yaml", help="a line file, or a network file that lists line files (the "
                    "documentation's page Lines from files); on a network the line policy plays every line and "
                    "the machine goes where the requested work is worth most (tamping only)")
    sp.add_argument("--policy", default=DEFAULT_PLAN_POLICY, metavar="NAME",
                    help="a line rule: no-maintenance, uniform-periodic, section-threshold, grouped-threshold, "
                         "register-periodic, budgeted-worst-first (with its tuned parameters); cpi-agent (the shipped "
                         "agent, at most the 10 years it was trained on), cpi-choice-agent (the shipped agent of the "
                         "lines with every choice; its tamping on a tamping-only line or a network) or the path of a "
                         "trained per-section policy; with a scenario that has every choice (not on a network) also "
                         "choice-threshold, choice-threshold-no-looking and choice-threshold-spot-only")
    sp.add_argument("--scenario", default="default", choices=("default", "choices", "wet", "defects"),
                    help="how the line is modelled beyond its file: default (hidden parts as on the default line, "
                         "tamping only), choices (every intervention and inspection), wet (a wet, poorly drained "
                         "line) or defects (many short defects), each with every choice; a rule takes that "
                         "scenario's tuned parameters")
    sp.add_argument("--years", type=_positive(float), default=3.0, metavar="N", help="years to plan")
    sp.add_argument("--futures", type=_positive(int), default=8, metavar="K",
                    help="sampled futures (what the file does not know drawn again in each)")
    sp.add_argument("--seed", type=_positive(int, zero=True), default=0, metavar="N",
                    help="future i is the episode of seed N + i")
    sp.add_argument("--tune", type=_at_most(_positive(int, zero=True), MAX_TUNE_FUTURES), default=0, metavar="N",
                    help=f"tune the rule's parameters on this line first: its grid and the shipped parameters on N "
                         f"training futures of 10 years (seeds 1000.., apart from the plan's), the cheapest planned "
                         f"with (0, the default: the shipped parameters, tuned on the preset; at most "
                         f"{MAX_TUNE_FUTURES}; 8 is a good start; minutes: each candidate runs N ten-year futures, or "
                         f"half of them where it is clearly dearer; on a network each line's rule, tuned on the line "
                         f"alone)")
    sp.add_argument("--compare", default=None, metavar="A,B,...",
                    help="plan each of these policies (names as --policy takes them) on the same futures and compare "
                         "them: each one's cost, its difference to the first's paired per future with a 95 %% CI, "
                         "and what it leaves at the end; each plan's files under --out, NUMBER-NAME/")
    engine(sp, plan=True)
    sp.add_argument("--ray", action="store_true", help="run --tune's batches of episodes as tasks on a local Ray "
                                                      "(trackenv[ray]); the same tuning")
    sp.add_argument("--ray-address", default=None, metavar="ADDR",
                    help="run --tune's batches on a Ray cluster: 'auto' on a cluster node, or ray://HEAD:10001")
    sp.add_argument("--batch-size", type=_positive(int), default=None, metavar="N",
                    help="--tune's episodes per batch (one vector env, one task); on a cluster fewer spread wider "
                         "(default 32)")
    sp.set_defaults(func=cmd_plan)

    sp = command("calibrate", "TampingLine without tamping and under a threshold rule vs published ranges")
    out(sp, "results/line_calibration")
    sp.add_argument("--scenario", default="default", choices=("small", "default", "hard", "wet", "defects"),
                    help="line scenario")
    sp.add_argument("--seeds", default="2000:2004", metavar="A:B",
                    help=f"episodes: A:B or a,b,c; whole numbers >= 0, at most {MAX_EPISODES} episodes")
    sp.add_argument("--threshold", type=_positive(float), default=2.0,
                    help="SD [mm] at which the rule tamps a section")
    sp.add_argument("--horizon-years", type=_positive(float), default=None,
                    help="shorter or longer episodes (years; default: the scenario's)")
    sp.set_defaults(func=cmd_calibrate)

    hp = _hyperparam_defaults()
    sp = command("train",
                 "train a PPO agent (stable-baselines3), hyper-parameters from agents/learning/hyperparams/ppo.yml")
    out(sp, "runs/ppo")
    sp.add_argument("--algo", choices=("ppo", "maskable_ppo"), default=None,
                    help=f"the 60 m track's algorithm (default: the hyper-parameter file's, {hp.get('algo', 'ppo')}); "
                         f"a line's learner reads its own from the file")
    sp.add_argument("--timesteps", type=_positive(int), default=None, metavar="N",
                    help=f"env steps to train for (default: the hyper-parameter file's, "
                         f"{hp.get('total_timesteps', 'n/a')}); with a TampingLine --env the line-steps of "
                         f"MaskablePPO after the policy iterations (default 0: none)")
    sp.add_argument("--n-envs", type=_positive(int), default=None, metavar="N",
                    help=f"envs stepped together (default: the hyper-parameter file's, {hp.get('n_envs', 'n/a')})")
    sp.add_argument("--workers", type=_positive(int), default=1, metavar="N",
                    help="processes the training envs are split over (the same episodes, the steps' Python in "
                         "parallel; 2 on a 2-core machine: +10-20 %% env steps/s at 32 envs)")
    sp.add_argument("--seed", type=_positive(int, zero=True), default=DEFAULT_TRAIN_SEED, metavar="N",
                    help="env i starts with seed + i, apart from the test, tuning and evaluation seeds")
    sp.add_argument("--checkpoint-every", type=_positive(float, zero=True), default=None, metavar="SECONDS",
                    help="seconds of wall clock between checkpoints (DIR/checkpoint.zip; 0: none; default: the "
                         "hyper-parameter file's, 300); the line's policy iteration keeps one after each iteration")
    sp.add_argument("--resume", default=None, metavar="DIR",
                    help="continue the run in DIR (killed, or finished) from its last checkpoint with the settings it "
                         "was started with; the 60 m track: --timesteps sets a new total")
    sp.add_argument("--hyperparams", default=None, metavar="FILE",
                    help="YAML (RL Zoo form) or flat JSON overriding agents/learning/hyperparams/ppo.yml key by key")
    sp.add_argument("--env", default=None, metavar="ID",
                    help="a TampingLine id: train the line's per-section policy (counterfactual policy iteration, "
                         "then MaskablePPO for --timesteps line-steps; default runs/ppo_line); your line: --env "
                         "trackenv/TampingLine-v0 --set line=PATH.yaml")
    sp.add_argument("--iterations", type=_positive(int), default=None, metavar="N",
                    help="with a TampingLine --env: policy iterations (default: the hyper-parameter file's)")
    engine(sp)
    sp.set_defaults(func=cmd_train)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_command(argv)
    args.argv = list(sys.argv[2:] if argv is None else argv[1:])  # the command as given, for the files it writes
    import trackenv  # noqa: F401  (first, so that its OpenMP wait policy reaches torch too: trackenv._openmp)

    try:
        if getattr(args, "resume", None) is None:  # --resume refuses a different --out itself
            _output_folder(getattr(args, "out", None))
        return int(args.func(args) or 0)
    except (UsageError, ValueError, FileNotFoundError) as exc:
        print(f"trackenv {args.command}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
