"""Interleaved A/B of a speed figure between two versions of trackenv: which one is faster, on a machine whose
speed drifts.

    python experiments/ab_speed.py --base 782868f                      # the working tree against a commit
    python experiments/ab_speed.py --base main~3 --new main --figure env --pairs 6
    python experiments/ab_speed.py --base 782868f --figure vector --envs 32 --out results/ab_vector32.json
    python experiments/ab_speed.py --base d1499ed --figure line --new-kwargs '{"engine": "fast"}'

A single `trackenv bench` figure moves by ±10–30 % with the machine's load and clock from one minute to the next,
more than most changes it is meant to judge. Here each version runs in its own process, one after the other,
in the order A B B A A B … (so that a drift over the run favours neither), each measuring the figure in a fresh
process after a warm-up; the report gives both medians, the median of the per-pair ratios (new / base) and how
many pairs favour the new version. ``--base`` and ``--new`` are git revisions checked out as temporary worktrees
(``--new`` defaults to the working tree itself); each worktree compiles the kernel the first time it runs (a few
minutes, untimed), and is removed at the end (``--base-dir DIR`` keeps the base's, to be reused). ``--new-kwargs``
(a JSON object) gives the new version's env keyword arguments the base may not know, e.g. an engine option;
``--base-kwargs`` the base's (both on one engine: ``--base-kwargs '{"engine": "fast"}' --new-kwargs '{"engine":
"fast"}'``). Figures (``--figure``):

* ``vector``: env steps per second of the native vector env (``--envs`` envs, random actions, ``--steps``);
* ``sharded``: the same split over ``--workers`` processes (versions that have ``ShardedVectorEnv``);
* ``env``: env steps per second of ``--env-id`` (default ``trackenv/Tamping-v1``; ``--base-env-id`` for a base that
  registered it under another id), random actions;
* ``line``: line-steps per second of ``trackenv/TampingLine-v0`` (random actions);
* ``line_vector``: line-steps per second of the default line's native vector env (``--envs`` lines, random
  actions);
* ``line_rule``, ``line_vector_rule``: the same two, stepping whole episodes (at least ``--steps`` env steps)
  under the grouped-threshold rule with its tuned parameters (:data:`RULE_MM`, written out here so that any
  version runs it): a line's realistic steps, where few sections are tamped at once (random actions tamp up
  to the capacity every step);
* ``seed``: passes per second of the seed pass at dt = 1e-4 (the benchmark's ``seed_pass``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# steps per second of one registered env with random actions (ENV_ID, WARM warm-up steps filled in below)
_GYM_STEPS = """
import time, gymnasium as gym
import trackenv.envs
env = gym.make("ENV_ID"{kwargs}); env.reset(seed=0); env.action_space.seed(0)
for _ in range(WARM): env.step(env.action_space.sample())
t = time.perf_counter()
for _ in range({steps}):
    _, _, te, tr, _ = env.step(env.action_space.sample())
    if te or tr: env.reset()
print({steps} / (time.perf_counter() - t))
"""
#: the grouped-threshold rule's tuned parameters on the default line (trigger, include) [mm]:
#: agents/rules/line_tuned_heuristics.json
RULE_MM = (3.5, 1.75)
# the rule on the observed section SD [mm] (one line or a batch of lines), as agents.rules.line.GroupedThreshold
_RULE = f"""
import numpy as np
def act(obs):
    sd = np.asarray(obs["section_sd"])
    return ((sd >= {RULE_MM[0]}).any(axis=-1, keepdims=True) & (sd >= {RULE_MM[1]})).astype(np.int8)
"""
_SNIPPETS = {
    "vector": """
import time, numpy as np
from trackenv.envs.vector import TampingVectorEnv
env = TampingVectorEnv({envs}); env.reset(seed=0); rng = np.random.default_rng(0)
act = lambda: rng.integers(0, 2, size=(env.num_envs, env.config.n_sections))
for _ in range(3): env.step(act())
t = time.perf_counter()
for _ in range({steps}): env.step(act())
print({envs} * {steps} / (time.perf_counter() - t))
""",
    "sharded": """
import time, numpy as np
from trackenv.envs.sharded import ShardedVectorEnv
from trackenv.envs.vector import TampingVectorEnv
if __name__ == "__main__":
    env = ShardedVectorEnv(TampingVectorEnv, {envs}, workers={workers}); env.reset(seed=0)
    rng = np.random.default_rng(0)
    act = lambda: rng.integers(0, 2, size=(env.num_envs, env.config.n_sections))
    for _ in range(3): env.step(act())
    t = time.perf_counter()
    for _ in range({steps}): env.step(act())
    print({envs} * {steps} / (time.perf_counter() - t))
    env.close()
""",
    "env": _GYM_STEPS.replace("ENV_ID", "{env_id}").replace("WARM", "5"),
    "line": _GYM_STEPS.replace("ENV_ID", "trackenv/TampingLine-v0").replace("WARM", "3"),
    "line_vector": """
import time
from trackenv.envs.line import TampingLineVectorEnv
env = TampingLineVectorEnv({envs}, scenario="default"{kwargs}); env.reset(seed=0); env.action_space.seed(0)
for _ in range(3): env.step(env.action_space.sample())
t = time.perf_counter()
for _ in range({steps}): env.step(env.action_space.sample())
print({envs} * {steps} / (time.perf_counter() - t))
""",
    "line_rule": _RULE + """
import time, gymnasium as gym
import trackenv.envs
env = gym.make("trackenv/TampingLine-v0"{kwargs})
obs, _ = env.reset(seed=0); env.step(act(obs))
steps, episode, t = 0, 1, time.perf_counter()
while steps < {steps}:
    obs, _ = env.reset(seed=episode); episode += 1; done = False
    while not done:
        obs, _, te, tr, _ = env.step(act(obs)); steps += 1; done = te or tr
print(steps / (time.perf_counter() - t))
""",
    "line_vector_rule": _RULE + """
import time
from trackenv.envs.line import TampingLineVectorEnv
env = TampingLineVectorEnv({envs}, scenario="default"{kwargs}); obs, _ = env.reset(seed=0)
obs, *_ = env.step(act(obs))
steps, t = 0, time.perf_counter()
obs, _ = env.reset(seed=1)
while steps < {steps}:  # the lines end together (one horizon): whole episodes, each next one reset here
    obs, _, te, tr, _ = env.step(act(obs)); steps += 1
    if (te | tr).all() and steps < {steps}: obs, _ = env.reset(seed=steps)
    elif (te | tr).all(): break
print({envs} * steps / (time.perf_counter() - t))
""",
    "seed": """
import time
from trackenv.physics.dynamics import simulate_pass
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Wheelset
track, wheel = Track.seed(), Wheelset(mass=1800.0, static_load=100e3)
simulate_pass(track, wheel, 80 / 3.6, dt=1e-4)
t = time.perf_counter()
for _ in range({steps}): simulate_pass(track, wheel, 80 / 3.6, dt=1e-4)
print({steps} / (time.perf_counter() - t))
""",
}
FIGURES = tuple(_SNIPPETS)
_UNITS = {"vector": "env steps/s", "sharded": "env steps/s", "env": "env steps/s", "line": "line-steps/s",
          "line_vector": "line-steps/s", "line_rule": "line-steps/s", "line_vector_rule": "line-steps/s",
          "seed": "passes/s"}
#: the figures whose env takes keyword arguments (``--new-kwargs``)
_TAKES_KWARGS = ("env", "line", "line_vector", "line_rule", "line_vector_rule")


def rounds(variants: Sequence[str], pairs: int) -> list[str]:
    """The run order of ``variants`` over ``pairs`` rounds: every round runs each once, in order in even rounds and
    reversed in odd ones (A B B A A B … for two), so that a steady drift of the machine over the whole run favours
    none of them."""
    if pairs < 1:
        raise ValueError(f"pairs must be >= 1, got {pairs!r}")
    return [x for p in range(pairs) for x in (variants if p % 2 == 0 else variants[::-1])]


def order(pairs: int) -> list[str]:
    """The run order A B B A A B … of the base and the new version (:func:`rounds`)."""
    return rounds(("base", "new"), pairs)


def json_run(args: Sequence[str]) -> dict:
    """The JSON object a fresh process ``args`` prints on its last line (its timing of one variant)."""
    out = subprocess.run(list(args), check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def timed_runs(variants: Sequence[str], pairs: int, args_of: Callable[[str], Sequence[str]],
               show: Callable[[str, dict], str] = lambda variant, rec: json.dumps(rec)) -> dict[str, list[dict]]:
    """Each variant's records, one per round (:func:`rounds`): the JSON object the fresh process ``args_of(variant)``
    prints (:func:`json_run`), each printed as ``show(variant, record)`` as it ends (the A/B scripts' loop)."""
    runs: dict[str, list[dict]] = {v: [] for v in variants}
    for variant in rounds(variants, pairs):
        runs[variant].append(json_run(args_of(variant)))
        print(show(variant, runs[variant][-1]), flush=True)
    return runs


def load_range(runs: dict[str, list[dict]]) -> list[float]:
    """[lowest, highest] load average over every record of ``runs`` (their ``"load"``)."""
    loads = [r["load"] for records in runs.values() for r in records]
    return [min(loads), max(loads)]


def summary(base: list[float], new: list[float]) -> dict:
    """Medians of both, the per-pair ratios new / base, their median and how many pairs favour ``new`` (a higher
    figure is faster)."""
    if len(base) != len(new) or not base:
        raise ValueError(f"base and new must be equal, non-empty lists of figures, got {len(base)} and {len(new)}")
    ratios = [n / b for b, n in zip(base, new)]
    return {"base": base, "new": new, "median_base": statistics.median(base), "median_new": statistics.median(new),
            "ratios": ratios, "median_ratio": statistics.median(ratios), "new_faster": sum(r > 1.0 for r in ratios),
            "pairs": len(ratios)}


def _checkout(rev: str, where: Path) -> Path:
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "--quiet", str(where), rev], check=True)
    return where


def _kept_checkout(rev: str, where: Path) -> Path:
    """A checkout of ``rev`` at ``where`` that outlives the run (``--base-dir``): made if absent, else reused if it
    holds ``rev`` (its compiled kernel with it: the next runs compile nothing)."""
    if not where.exists():
        return _checkout(rev, where)
    def commit(*args: str) -> str:
        return subprocess.run(["git", *args], check=True, capture_output=True, text=True).stdout.strip()
    held = commit("-C", str(where), "rev-parse", "HEAD")
    wanted = commit("-C", str(ROOT), "rev-parse", f"{rev}^{{commit}}")
    if held != wanted:
        raise SystemExit(f"--base-dir {where} holds {held[:10]}, not --base {rev} ({wanted[:10]})")
    return where


def _run(tree: Path, code: str) -> float:
    """The figure printed by ``code`` run in a fresh process on the trackenv of ``tree``."""
    check = f"import trackenv, sys; assert trackenv.__file__.startswith({str(tree)!r}), trackenv.__file__\n"
    env = {**os.environ, "PYTHONPATH": str(tree)}
    # a file (spawn needs a __main__) in a folder of its own: the script's folder leads sys.path, and a stray
    # module in the shared temporary folder (a select.py, say) would shadow the standard library's
    with tempfile.TemporaryDirectory(prefix="ab_speed_run_") as folder:
        script = Path(folder) / "figure.py"
        script.write_text(check + code)
        out = subprocess.run([sys.executable, str(script)], cwd=tree, env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"the figure failed in {tree}:\n{out.stderr[-2000:]}")
    return float(out.stdout.strip().splitlines()[-1])


def _keyword_arguments(text: str, figure: str, parser: argparse.ArgumentParser, option: str = "--new-kwargs") -> dict:
    """The value of ``option`` (``--new-kwargs`` or ``--base-kwargs``) as a dict of names to JSON values (an error
    naming the option if it is not one, or if the figure's env takes none)."""
    try:
        given = json.loads(text)
    except json.JSONDecodeError as e:
        parser.error(f"{option} must be a JSON object, got {text!r} ({e})")
    if not isinstance(given, dict) or not all(isinstance(k, str) and k.isidentifier() for k in given):
        parser.error(f"{option} must be a JSON object of keyword names, got {text!r}")
    if given and figure not in _TAKES_KWARGS:
        parser.error(f"{option} applies to the figures {list(_TAKES_KWARGS)}, not {figure!r}")
    return given


def figure_codes(figure: str, env_ids: dict[str, str], kwargs: dict[str, dict], *, steps: int, envs: int,
                 workers: int) -> dict[str, str]:
    """Each version's code for ``figure`` ("base", "new"): the figure's snippet with that version's env id and env
    keyword arguments (``env_ids``, ``kwargs``: by version)."""
    return {side: _SNIPPETS[figure].format(envs=envs, steps=steps, workers=workers, env_id=env_ids[side],
                                           kwargs="".join(f", {k}={v!r}" for k, v in kwargs[side].items()))
            for side in ("base", "new")}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="git revision of the base version")
    parser.add_argument("--new", default=None, help="git revision of the new version (default: the working tree)")
    parser.add_argument("--figure", choices=FIGURES, default="vector", help="what to time (default: vector)")
    parser.add_argument("--pairs", type=int, default=8, help="pairs of runs (default 8)")
    parser.add_argument("--steps", type=int, default=None,
                        help="steps (passes for seed) per run (default: vector/sharded 40, env 300, line 60, "
                             "line_rule 80, line_vector_rule 40, seed 20)")
    parser.add_argument("--envs", type=int, default=32, help="envs of the vector figures (default 32)")
    parser.add_argument("--workers", type=int, default=2, help="processes of the sharded figure (default 2)")
    parser.add_argument("--env-id", default="trackenv/Tamping-v1", help="the env figure's id (default Tamping-v1)")
    parser.add_argument("--base-env-id", default=None, help="the env figure's id on the base (default --env-id)")
    parser.add_argument("--new-kwargs", default="{}",
                        help="JSON object of keyword arguments for the new version's env (figures env, line, "
                             "line_vector), e.g. '{\"engine\": \"fast\"}'")
    parser.add_argument("--base-kwargs", default="{}",
                        help="JSON object of keyword arguments for the base version's env (as --new-kwargs)")
    parser.add_argument("--base-dir", default=None,
                        help="check the base out here and keep it, with its compiled kernel, for later runs (a "
                             "checkout of --base already there is reused)")
    parser.add_argument("--out", default="", help="write the JSON report here")
    args = parser.parse_args(argv)
    if args.pairs < 1 or args.envs < 1 or args.workers < 1 or (args.steps is not None and args.steps < 1):
        parser.error("pairs, steps, envs and workers must be >= 1")
    new_kwargs = _keyword_arguments(args.new_kwargs, args.figure, parser)
    base_kwargs = _keyword_arguments(args.base_kwargs, args.figure, parser, "--base-kwargs")
    steps = args.steps or {"vector": 40, "sharded": 40, "env": 300, "line": 60, "line_vector": 10,
                           "line_rule": 80, "line_vector_rule": 40, "seed": 20}[args.figure]
    env_ids = {"base": args.base_env_id or args.env_id, "new": args.env_id}
    codes = figure_codes(args.figure, env_ids, {"base": base_kwargs, "new": new_kwargs}, steps=steps, envs=args.envs,
                         workers=args.workers)
    runs = order(args.pairs)
    with tempfile.TemporaryDirectory(prefix="ab_speed_") as tmp:
        trees = {"base": _kept_checkout(args.base, Path(args.base_dir)) if args.base_dir
                 else _checkout(args.base, Path(tmp) / "base")}
        trees["new"] = ROOT if args.new is None else _checkout(args.new, Path(tmp) / "new")
        try:
            for name, tree in trees.items():  # compile (or load) each version's kernel, untimed
                print(f"warming {name} ({tree}) ...", file=sys.stderr, flush=True)
                _run(tree, codes[name])
            figures: dict[str, list[float]] = {"base": [], "new": []}
            for i, name in enumerate(runs):
                figures[name].append(_run(trees[name], codes[name]))
                print(f"run {i + 1}/{len(runs)} {name}: {figures[name][-1]:.2f}", file=sys.stderr, flush=True)
        finally:
            for name, tree in trees.items():
                if tree != ROOT and not (name == "base" and args.base_dir):
                    subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False)
    from trackenv_studies.bench import cpu_model  # the machine's processor, named with the figures

    report = {"figure": args.figure, "unit": _UNITS[args.figure], "base_rev": args.base,
              "new_rev": args.new or "working tree", "base_kwargs": base_kwargs, "new_kwargs": new_kwargs,
              **({"env_ids": env_ids} if args.figure == "env" else {}),
              "steps": steps, "envs": args.envs, "order": runs, "processor": cpu_model(),
              "load_average_1min": os.getloadavg()[0],
              **summary(figures["base"], figures["new"])}
    print(f"{args.figure} ({report['unit']}), {report['pairs']} pairs: base {report['median_base']:.2f}, new "
          f"{report['median_new']:.2f}, median ratio {report['median_ratio']:.3f} "
          f"({report['new_faster']}/{report['pairs']} pairs favour new), load {report['load_average_1min']:.2f}, "
          f"{report['processor']}")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(report, indent=2))
    return report


if __name__ == "__main__":
    main()
