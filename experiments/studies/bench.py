"""How fast the physics runs: one pass, batched passes on all cores and on one, a car, the paper loop and
the env.

:func:`run_benchmarks` returns a JSON-ready dict; :func:`format_benchmarks` renders it as a table. Every
timing is the median wall time over repeats after a warm-up run (which also triggers numba's compilation, or
loads it from numba's cache), measured with :func:`time.perf_counter`.

* ``seed_pass``: one pass of ``Wheelset(mass=1800, static_load=100e3)`` over ``Track.seed()`` at 80 km/h,
  dt = 1e-4 s (the paper's setting); ``seed_pass_auto``: the same at ``dt="auto"``. The passes repeat over one
  track object, so they use what a pass keeps per track (stiffness factor, window factors and bay columns), as
  an episode's passes do: a pass over a new track object took ~0.3 ms more (2.9 against 2.6 ms at the auto step,
  8.9 against 8.5 ms at 1e-4; 2026-12-03);
* ``batch``: throughput of :func:`simulate_passes` with 1, 16 and 64 rows, a different random irregularity in
  every row, once with numba's default thread count (chunks of rows in parallel) and once with one thread;
  ``batch_gain``: passes/s of a batch of 64 on numba's default threads over those of 64 single passes (a single
  pass is one chunk: it runs on one thread whatever the setting), what batching buys on the machine;
  ``lockstep_gain``: the same with the batch on one thread too, what the rows in lockstep (SIMD) buy alone;
* ``car``: the 10-DOF ``Car.manchester_coach()`` over ``Track.realistic(120.0)`` at 80 km/h;
* ``paper_b``: the paper's scenario B, 6 iterations of 50 000 cycles (:class:`TrackDegradation`, dt = 1e-4 s as
  the paper's reproduction runs it);
* ``env``: environment steps per second of ``trackenv/Tamping-v1`` (the 60 m track) with random actions, or
  "unavailable" and the reason when the environment cannot be made; ``vector_env``: env steps per second (steps
  × envs) of the native :class:`~trackenv.envs.vector.TampingVectorEnv` with 8 and 32 envs; ``vector_env_sharded``: the
  32 envs split over 2 processes (:class:`~trackenv.envs.sharded.ShardedVectorEnv`; machines with >= 2 cores);
* ``line_env`` / ``line_vector_env``: the same for ``trackenv/TampingLine-v0`` (12 sections of 200 m, each a
  30 m physics segment) and its native :class:`~trackenv.envs.line.TampingLineVectorEnv` with 8 lines, with
  ``pass_share``: the share of the step's wall time spent in the batched passes (the physics);
  ``line_env_fast``: ``TampingLine-v0`` with the faster opt-in options (:data:`FAST_LINE`: the fast engine and
  pass reuse at 1 mm), random actions as the others (which tamp about half the line every step: under a tuned
  rule reuse skips more, see the performance page of the documentation);
* ``line_env_rule`` / ``line_env_fast_rule``: the default line, plain and with :data:`FAST_LINE`, over whole
  episodes under a policy given to :func:`run_benchmarks` (``trackenv bench``: the tuned grouped threshold),
  the line's realistic load: under the tuned rule a campaign about once a year, so most steps tamp nothing;
* every env figure carries ``profile``: the shares of its wall time spent in the compiled kernel, the pass set-up
  around it (irregularity, matrices, static start), the settlement step, the D1/quality computation and the rest
  (:data:`PROFILE_STAGES`; :func:`format_profile` renders them as the documentation's performance table).

Every figure carries ``load_average_1min``, the machine's load when it was taken: other work on the machine
slows every figure, so compare figures taken at a similar load.
"""

from __future__ import annotations

import functools
import os
import platform
import statistics
import sys
import threading
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from trackenv.degradation import TrackDegradation
from trackenv.physics.dynamics import simulate_pass, simulate_passes
from trackenv.physics.kernels import usable_cores
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Car, Wheelset

__all__ = ["run_benchmarks", "format_benchmarks", "format_profile"]

SPEED = 80 / 3.6
DT = 1e-4
BATCH_SIZES = (1, 16, 64)
#: the line's faster opt-in options (:class:`~trackenv.envs.line_config.LineConfig`): the fast engine, and pass
#: reuse at the tolerance the performance page of the documentation measured
FAST_LINE: dict[str, Any] = {"engine": "fast", "pass_reuse_tolerance_m": 1e-3}
VECTOR_ENVS = (8, 32)
# vector steps per native (and sharded) vector-env figure: 60 steps of 32 envs take ~3-4 s here; at 20 (~1 s) a
# figure followed the machine's minute-to-minute drift (+-10 %) more than the code
VECTOR_STEPS = 60
SHARDED_ENVS, SHARDED_WORKERS = 32, 2  # the vector env split over processes (on machines with >= 2 cores)
LINE_VECTOR_ENVS = (8,)
LINE_EPISODE_STEPS = 80  # two 10-year episodes of 40 quarterly steps: the realistic figures step whole episodes


def _loaded_wheelset() -> Wheelset:
    return Wheelset(mass=1800.0, static_load=100e3)


def _time(fn: Callable[[], object], repeats: int, warmup: int = 1) -> dict:
    """Median, min and max wall time [s] of ``fn()`` over ``repeats`` calls after ``warmup`` calls."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return {"median_s": statistics.median(times), "min_s": min(times), "max_s": max(times),
            "repeats": repeats}


def _machine() -> dict:
    import numba

    try:
        affinity = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover (not on Linux)
        affinity = None
    return {"platform": platform.platform(), "processor": cpu_model(),
            "python": sys.version.split()[0], "numpy": np.__version__, "numba": numba.__version__,
            "cpu_count": os.cpu_count(), "cpus_usable": affinity, "numba_threads": numba.get_num_threads(),
            "numba_threading_layer": _threading_layer(), "load_average_1min": _load_average()}


def cpu_model(cpuinfo: str = "/proc/cpuinfo") -> str:
    """The processor's model name (Linux: the first "model name" of ``cpuinfo``; elsewhere what ``platform``
    knows): figures differ by up to 2x between machines of one kind, so each carries the model it ran on."""
    try:
        with open(cpuinfo, encoding="utf-8", errors="replace") as f:
            for line in f:
                key, sep, value = line.partition(":")
                if sep and key.strip() == "model name" and value.strip():
                    return " ".join(value.split())
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _load_average() -> float | None:
    """The 1-minute load average when the benchmark starts: other work on the machine slows every figure."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):  # pragma: no cover (not on Unix)
        return None


def _threading_layer() -> str:
    import numba

    try:
        return str(numba.threading_layer())
    except ValueError:  # no parallel function has run yet
        return "not initialised"


def _irregularities(rows: int, x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Different smooth random rail levels per row [m] at the sleeper positions ``x`` [m]: a few sines of
    2-20 m wavelength, ~0.5 mm RMS."""
    n_sleepers = x.size
    out = np.zeros((rows, n_sleepers))
    for _ in range(4):
        lam = rng.uniform(2.0, 20.0, size=(rows, 1))
        amp = rng.uniform(0.1e-3, 0.5e-3, size=(rows, 1))
        phase = rng.uniform(0.0, 2 * np.pi, size=(rows, 1))
        out += amp * np.sin(2 * np.pi * x / lam + phase)
    return out


def _bench_seed_pass(repeats: int, dt: float | str = DT) -> dict:
    track, wheel = Track.seed(), _loaded_wheelset()
    res = simulate_pass(track, wheel, SPEED, dt=dt)
    t = _time(lambda: simulate_pass(track, wheel, SPEED, dt=dt), repeats)
    steps = res.time.size - 1
    t.update({"dt_s": res.dt, "time_steps": steps, "simulated_s": float(res.time[-1]),
              "steps_per_s": steps / t["median_s"], "real_time_factor": float(res.time[-1]) / t["median_s"],
              "load_average_1min": _load_average()})
    return t


def _bench_batches(repeats: int, sizes=BATCH_SIZES) -> dict:
    import numba

    track, wheel = Track.seed(), _loaded_wheelset()
    rng = np.random.default_rng(12345)
    default_threads = numba.get_num_threads()
    out: dict = {"default_threads": default_threads, "rows": {}}
    for label, threads in (("all_threads", default_threads), ("one_thread", 1)):
        numba.set_num_threads(threads)
        try:
            for b in sizes:
                irr = _irregularities(b, track.sleeper_positions, rng)
                t = _time(partial(simulate_passes, track, wheel, SPEED, irr, dt=DT), repeats)
                out["rows"].setdefault(str(b), {})[label] = {**t, "passes_per_s": b / t["median_s"],
                                                             "load_average_1min": _load_average()}
        finally:
            numba.set_num_threads(default_threads)
    for row in out["rows"].values():
        row["parallel_speedup"] = row["all_threads"]["passes_per_s"] / row["one_thread"]["passes_per_s"]
    if "1" in out["rows"] and str(max(sizes)) in out["rows"]:
        one, big = out["rows"]["1"], out["rows"][str(max(sizes))]
        out["batch_gain"] = big["all_threads"]["passes_per_s"] / one["all_threads"]["passes_per_s"]
        out["lockstep_gain"] = big["one_thread"]["passes_per_s"] / one["one_thread"]["passes_per_s"]
    return out


def _bench_car(repeats: int) -> dict:
    track, car = Track.realistic(120.0), Car.manchester_coach()
    res = simulate_pass(track, car, SPEED, dt=DT)
    t = _time(lambda: simulate_pass(track, car, SPEED, dt=DT), repeats)
    steps = res.time.size - 1
    t.update({"track": "Track.realistic(120.0)", "vehicle": "Car.manchester_coach() (10 DOF, 4 axles)",
              "time_steps": steps, "simulated_s": float(res.time[-1]), "steps_per_s": steps / t["median_s"],
              "real_time_factor": float(res.time[-1]) / t["median_s"]})
    return t


def _bench_paper_b(repeats: int, iterations: int = 6) -> dict:
    track = Track.seed().scaled(ballast_stiffness=1.10, from_sleeper=40)

    def run() -> None:
        TrackDegradation(track, _loaded_wheelset(), cycles_per_iteration=50_000, speed=SPEED, dt=DT).run(iterations)

    t = _time(run, repeats)
    t.update({"iterations": iterations, "cycles_per_iteration": 50_000,
              "per_iteration_s": t["median_s"] / iterations})
    return t


# Where an env step's wall time goes: each stage is a function the env reaches through a module attribute, wrapped
# for the length of a benchmark. "passes" contains "kernel"; the profile reports the set-up (passes − kernel).
PROFILE_STAGES = (
    ("kernel", "trackenv.physics._kernel", "run"),
    ("passes", "trackenv.degradation", "simulate_passes"),
    ("passes", "trackenv.envs.line_episode", "simulate_pass_batches"),
    ("settlement", "trackenv.degradation", "implicit_settlement_step"),
    ("settlement", "trackenv.envs.line_episode", "implicit_settlement_step"),
    ("quality", "trackenv.envs.line_episode", "d1_filter"),
)


class _StageTimer:
    """Wall time spent in the stages of :data:`PROFILE_STAGES` while in a ``with`` block (the functions are
    wrapped on entry and restored on exit). A stage's time is the wall time during which at least one call of it
    runs: kernels that run side by side in two threads (:func:`~trackenv.physics.dynamics.simulate_pass_batches`)
    count once, as does a call inside another of its stage."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._saved: list[tuple[Any, str, Any]] = []
        self._running: dict[str, tuple[int, float]] = {}  # stage -> (calls running, since when)
        self._lock = threading.Lock()

    def __enter__(self) -> _StageTimer:
        import importlib

        for stage, module, name in PROFILE_STAGES:
            owner = importlib.import_module(module)
            inner = getattr(owner, name)
            self._saved.append((owner, name, inner))
            setattr(owner, name, self._timed(stage, inner))
        return self

    def _timed(self, stage: str, inner: Callable) -> Callable:
        def timed(*args: Any, **kwargs: Any) -> Any:
            with self._lock:
                running, since = self._running.get(stage, (0, time.perf_counter()))
                self._running[stage] = (running + 1, since)
            try:
                return inner(*args, **kwargs)
            finally:
                with self._lock:
                    running, since = self._running.pop(stage)
                    if running > 1:
                        self._running[stage] = (running - 1, since)
                    else:
                        self.seconds[stage] = self.seconds.get(stage, 0.0) + time.perf_counter() - since

        return timed

    def __exit__(self, *exc: object) -> None:
        for owner, name, inner in reversed(self._saved):
            setattr(owner, name, inner)
        self._saved.clear()

    def profile(self, wall_s: float) -> dict[str, float]:
        """Shares of ``wall_s``: the kernel, the pass set-up around it, the settlement step, the D1/quality
        computation and the rest (env bookkeeping, tamping, costs, observation)."""
        t = self.seconds
        kernel, passes = t.get("kernel", 0.0), t.get("passes", 0.0)
        parts = {"kernel": kernel, "pass_setup": max(passes - kernel, 0.0), "settlement": t.get("settlement", 0.0),
                 "quality": t.get("quality", 0.0)}
        parts["other"] = max(wall_s - sum(parts.values()), 0.0)
        return {k: v / wall_s for k, v in parts.items()}


def _bench_env(steps: int, time_budget_s: float, env_id: str = "trackenv/Tamping-v1", policy: Any = None,
               **make_kwargs: Any) -> dict:
    """Steps per second of the env ``env_id`` (made with ``make_kwargs``), or why it is unavailable (line envs:
    with the share of the time spent in the passes). Random actions, or ``policy``'s (an object whose
    ``predict(obs)`` returns ``(action, state)``, as the rules and stable-baselines3 models do)."""
    actions = "random actions" if policy is None else getattr(policy, "name", None) or repr(policy)
    try:
        import gymnasium

        import trackenv.envs  # noqa: F401  (registers the environment)

        env = gymnasium.make(env_id, **make_kwargs)
    except Exception as exc:  # the environment is optional here: report, do not fail
        return {"status": "unavailable", "reason": f"{type(exc).__name__}: {exc}"}
    def act(obs: Any) -> Any:
        return env.action_space.sample() if policy is None else policy.predict(obs)[0]

    try:
        env.action_space.seed(0)
        t0 = time.perf_counter()
        obs, _ = env.reset(seed=0)
        reset_s = time.perf_counter() - t0
        obs = env.step(act(obs))[0]  # warm-up
        done_steps, resets = 0, 0
        with _StageTimer() as timer:
            t0 = time.perf_counter()
            while done_steps < steps and time.perf_counter() - t0 < time_budget_s:
                obs, _, terminated, truncated, _ = env.step(act(obs))
                done_steps += 1
                if terminated or truncated:
                    obs, _ = env.reset()
                    resets += 1
            wall = time.perf_counter() - t0
        profile = timer.profile(wall)
        return {"status": "ok", "env_id": env_id, "make_kwargs": make_kwargs, "actions": actions,
                "policy": None if policy is None else repr(policy),
                "steps": done_steps, "wall_s": wall,
                "steps_per_s": done_steps / wall, "episodes_ended": resets, "first_reset_s": reset_s,
                "profile": profile, "pass_share": profile["kernel"] + profile["pass_setup"],
                "load_average_1min": _load_average()}
    except Exception as exc:
        return {"status": "unavailable", "reason": f"{type(exc).__name__}: {exc}"}
    finally:
        env.close()


def _bench_vector_env(num_envs: int, steps: int, time_budget_s: float, line: bool = False,
                      workers: int = 1) -> dict:
    """Env steps per second (vector steps × envs) of the native vector env (``line``: of TampingLine) with
    random actions; ``workers`` > 1: split over that many processes (:class:`ShardedVectorEnv`, no profile:
    the stages run in the workers)."""
    try:
        if line:
            from trackenv.envs.line import TampingLineVectorEnv as Vec
        else:
            from trackenv.envs.vector import TampingVectorEnv as Vec
        from trackenv.envs.sharded import native_or_sharded

        t0 = time.perf_counter()
        venv = native_or_sharded(Vec, num_envs, workers)
        start_s = time.perf_counter() - t0
    except Exception as exc:  # optional here: report, do not fail
        return {"status": "unavailable", "reason": f"{type(exc).__name__}: {exc}"}
    try:
        venv.action_space.seed(0)
        t0 = time.perf_counter()
        venv.reset(seed=0)
        reset_s = time.perf_counter() - t0
        venv.step(venv.action_space.sample())  # warm-up
        done_steps = 0
        with _StageTimer() as timer:
            t0 = time.perf_counter()
            while done_steps < steps and time.perf_counter() - t0 < time_budget_s:
                venv.step(venv.action_space.sample())
                done_steps += 1
            wall = time.perf_counter() - t0
        out = {"status": "ok", "num_envs": num_envs, "workers": workers, "vector_steps": done_steps,
               "wall_s": wall, "env_steps_per_s": done_steps * num_envs / wall, "start_s": start_s,
               "first_reset_s": reset_s, "load_average_1min": _load_average()}
        if workers == 1:
            profile = timer.profile(wall)
            out.update(profile=profile, pass_share=profile["kernel"] + profile["pass_setup"])
        return out
    except Exception as exc:
        return {"status": "unavailable", "reason": f"{type(exc).__name__}: {exc}"}
    finally:
        venv.close()


def _bench_state(repeats: int) -> dict:
    """The planning state API on the default line and the 60 m track, a few steps into an episode: the median
    wall time of ``get_state`` and of ``set_state`` [s], and the size of a pickled snapshot [bytes]."""
    import pickle

    import gymnasium as gym

    out = {}
    for name, env_id in (("line", "trackenv/TampingLine-v0"), ("tamping", "trackenv/Tamping-v1")):
        env: Any = gym.make(env_id).unwrapped  # a TrackEnv: get_state / set_state
        env.reset(seed=0)
        for _ in range(3):
            env.step(np.zeros(env.action_space.shape, dtype=np.int8))
        state = env.get_state()
        restore = functools.partial(env.set_state, state)
        out[name] = {"get_state": _time(env.get_state, repeats * 20), "set_state": _time(restore, repeats * 20),
                     "pickled_bytes": len(pickle.dumps(state))}
    return out


def run_benchmarks(quick: bool = False, progress: Callable[[str], None] | None = None,
                   line_policy: Any = None) -> dict:
    """Run every benchmark and return the figures with the machine they ran on (JSON-ready).

    ``quick``: fewer repeats (3 instead of 7 for single passes; 2 instead of 5 for batches and the paper
    loop) and fewer env steps, for a smoke test; the figures are then rougher. ``progress``: called with the
    name of each benchmark as it starts (e.g. to advance a progress bar; see :data:`STAGES`). ``line_policy``:
    the policy of the line's realistic figures (``line_env_rule``, ``line_env_fast_rule``: whole episodes of the
    default line under it, plain and with :data:`FAST_LINE`; the ``trackenv bench`` command gives the tuned
    grouped threshold); without one they are reported unavailable.
    """
    rep = 3 if quick else 7
    rep_batch = 2 if quick else 5
    tell = progress or (lambda name: None)
    t0 = time.perf_counter()
    out: dict[str, Any] = {"quick": bool(quick), "machine": _machine(), "dt_s": DT, "speed_m_per_s": SPEED}
    tell("seed_pass")
    out["seed_pass"] = _bench_seed_pass(rep)
    tell("seed_pass_auto")
    out["seed_pass_auto"] = _bench_seed_pass(rep, dt="auto")
    tell("batch")
    out["batch"] = _bench_batches(rep_batch)
    tell("car")
    out["car"] = _bench_car(3 if quick else 5)
    tell("paper_b")
    out["paper_b"] = _bench_paper_b(1 if quick else 3)
    tell("env")
    out["env"] = _bench_env(20 if quick else 200, 10.0 if quick else 60.0)
    out["vector_env"] = {}
    for n in VECTOR_ENVS:
        tell(f"vector_env_{n}")
        out["vector_env"][str(n)] = _bench_vector_env(n, 3 if quick else VECTOR_STEPS, 10.0 if quick else 60.0)
    out["vector_env_sharded"] = {}
    if usable_cores() >= SHARDED_WORKERS:  # the cores this process may run on, not the machine's count
        tell(f"vector_env_{SHARDED_ENVS}_sharded")
        out["vector_env_sharded"][str(SHARDED_ENVS)] = _bench_vector_env(
            SHARDED_ENVS, 3 if quick else VECTOR_STEPS, 10.0 if quick else 60.0, workers=SHARDED_WORKERS)
    tell("line_env")
    out["line_env"] = _bench_env(3 if quick else 40, 10.0 if quick else 60.0, env_id="trackenv/TampingLine-v0")
    tell("line_env_fast")
    out["line_env_fast"] = _bench_env(3 if quick else 40, 10.0 if quick else 60.0, env_id="trackenv/TampingLine-v0",
                                      **FAST_LINE)
    for name, options in (("line_env_rule", {}), ("line_env_fast_rule", FAST_LINE)):
        tell(name)
        out[name] = (_bench_env(3 if quick else LINE_EPISODE_STEPS, 10.0 if quick else 60.0,
                                env_id="trackenv/TampingLine-v0", policy=line_policy, **options)
                     if line_policy is not None else {"status": "unavailable", "reason": "no line_policy given"})
    out["line_vector_env"] = {}
    for n in LINE_VECTOR_ENVS:
        tell(f"line_vector_env_{n}")
        out["line_vector_env"][str(n)] = _bench_vector_env(n, 2 if quick else 10, 10.0 if quick else 60.0,
                                                           line=True)
    tell("state")
    out["state"] = _bench_state(rep)
    out["machine"]["numba_threading_layer"] = _threading_layer()
    out["total_wall_s"] = time.perf_counter() - t0
    return out


STAGES = ("seed_pass", "seed_pass_auto", "batch", "car", "paper_b", "env", "vector_env_8", "vector_env_32",
          "vector_env_32_sharded", "line_env", "line_env_fast", "line_env_rule", "line_env_fast_rule",
          "line_vector_env_8", "state")
"""The benchmarks :func:`run_benchmarks` runs, in order (what ``progress`` is called with)."""


def _load(t: dict) -> str:
    load = t.get("load_average_1min")
    return "" if load is None else f" [load {load:.1f}]"


def _ms(t: dict) -> str:
    return f"{t['median_s'] * 1e3:.1f} ms (min {t['min_s'] * 1e3:.1f})"


def _in_passes(t: dict) -> str:
    share = t.get("pass_share")
    return "" if share is None else f", {100 * share:.0f} % in the passes"


PROFILE_LABELS = (("kernel", "kernel"), ("pass_setup", "pass set-up"), ("settlement", "settlement"),
                  ("quality", "quality (D1)"), ("other", "other"))


def format_profile(d: dict) -> str:
    """Where the env steps' wall time went (shares of :func:`_StageTimer.profile`), one column per env
    benchmark: the documentation's performance table, as Markdown."""
    found: list[tuple[str, Any]] = [("Tamping-v1, 1 env", d.get("env"))]
    found += [(f"Tamping-v1, {n} envs", v) for n, v in d.get("vector_env", {}).items()]
    found += [("TampingLine-v0, 1 line", d.get("line_env"))]
    found += [(f"TampingLine-v0, {n} lines", v) for n, v in d.get("line_vector_env", {}).items()]
    cols: list[tuple[str, dict]] = [(name, e) for name, e in found
                                    if e is not None and e.get("status") == "ok" and "profile" in e]
    lines = ["| share of the step | " + " | ".join(name for name, _ in cols) + " |",
             "|---|" + "---:|" * len(cols)]
    for key, label in PROFILE_LABELS:
        lines.append(f"| {label} | " + " | ".join(f"{100 * e['profile'][key]:.0f} %" for _, e in cols) + " |")
    return "\n".join(lines)


def _env_row(env_id: str, e: dict, variant: str = "") -> tuple[str, str, str]:
    """The row of an env figure; ``variant`` names the options it was made with (after the id)."""
    name = f"env {env_id}" + (f" {variant}" if variant else "")
    if e["status"] != "ok":
        return (name, "unavailable", e["reason"][:80])
    return (f"{name} ({e.get('actions', 'random actions')})", f"{e['steps_per_s']:.1f} steps/s",
            f"{e['steps']} steps, {e['episodes_ended']} episodes ended" + _in_passes(e) + _load(e))


def _vector_row(label: str, v: dict) -> tuple[str, str, str]:
    if v["status"] != "ok":
        return (label, "unavailable", v["reason"][:80])
    return (label, f"{v['env_steps_per_s']:.1f} env steps/s", f"{v['vector_steps']} vector steps" + _in_passes(v)
            + _load(v))


def format_benchmarks(d: dict) -> str:
    """The figures of :func:`run_benchmarks` as a small human-readable table (median wall times, with the
    fastest repeat, which is less sensitive to other work on the machine)."""
    m = d["machine"]
    load = m.get("load_average_1min")
    lines = [f"machine: {m['platform']}, {m['processor']}, {m['cpu_count']} CPUs "
             f"({m['cpus_usable']} usable), numba {m['numba']} with {m['numba_threads']} threads "
             f"({m['numba_threading_layer']}), Python {m['python']}, load average "
             + ("unknown" if load is None else f"{load:.2f}") + ("  [quick]" if d["quick"] else "")]
    rows = []
    sp = d["seed_pass"]
    rows.append(("seed pass (wheelset, 30 m, 80 km/h, dt 1e-4)", _ms(sp),
                 f"{sp['steps_per_s'] / 1e3:.0f} k steps/s, {sp['real_time_factor']:.0f}x real time" + _load(sp)))
    sa = d["seed_pass_auto"]
    rows.append((f"seed pass, dt auto ({sa['dt_s']:.2g} s)", _ms(sa),
                 f"{sa['steps_per_s'] / 1e3:.0f} k steps/s, {sa['real_time_factor']:.0f}x real time" + _load(sa)))
    for b, row in d["batch"]["rows"].items():
        a, o = row["all_threads"], row["one_thread"]
        rows.append((f"simulate_passes batch {b}", _ms(a),
                     f"{a['passes_per_s']:.1f} passes/s ({d['batch']['default_threads']} threads), "
                     f"{o['passes_per_s']:.1f} (1 thread), x{row['parallel_speedup']:.2f}" + _load(o)))
    if "lockstep_gain" in d["batch"]:
        rows.append((f"batch gain (batch 64 / 64 single, {d['batch']['default_threads']} threads)",
                     f"x{d['batch']['batch_gain']:.2f}", ""))
        rows.append(("lockstep gain (batch 64 / 64 single, 1 thread)", f"x{d['batch']['lockstep_gain']:.2f}", ""))
    c = d["car"]
    rows.append(("car (Manchester coach, 120 m)", _ms(c),
                 f"{c['steps_per_s'] / 1e3:.0f} k steps/s, {c['real_time_factor']:.1f}x real time"))
    p = d["paper_b"]
    rows.append((f"paper scenario B ({p['iterations']} iterations)", _ms(p),
                 f"{p['per_iteration_s'] * 1e3:.0f} ms per iteration"))
    vectors = [(f"native vector env, {n} envs", v) for n, v in d.get("vector_env", {}).items()]
    vectors += [(f"native vector env, {n} envs in {v.get('workers', SHARDED_WORKERS)} processes", v)
                for n, v in d.get("vector_env_sharded", {}).items()]
    lines_ = [(f"native line vector env, {n} lines", v) for n, v in d.get("line_vector_env", {}).items()]
    for env_id, e, vector_rows in (("trackenv/Tamping-v1", d["env"], vectors),
                                   ("trackenv/TampingLine-v0", d.get("line_env"), lines_)):
        if e is not None:
            rows.append(_env_row(env_id, e))
        if env_id == "trackenv/TampingLine-v0":
            for key, variant in (("line_env_fast", "fast + reuse"), ("line_env_rule", ""),
                                 ("line_env_fast_rule", "fast + reuse")):
                if d.get(key) is not None:
                    rows.append(_env_row(env_id, d[key], variant))
        rows += [_vector_row(label, v) for label, v in vector_rows]
    for name, s in d.get("state", {}).items():
        rows.append((f"state API, {name}: get_state", f"{s['get_state']['median_s'] * 1e3:.3f} ms",
                     f"set_state {s['set_state']['median_s'] * 1e3:.3f} ms, pickled {s['pickled_bytes'] / 1e3:.0f} kB"))
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows)
    lines += [f"{r[0]:<{w0}}  {r[1]:>{w1}}  {r[2]}" for r in rows]
    if any("profile" in (e or {}) for e in [d.get("env"), d.get("line_env")]):
        lines += ["where an env step's wall time goes:", format_profile(d)]
    lines.append(f"total benchmark wall time {d['total_wall_s']:.1f} s")
    return "\n".join(lines)
