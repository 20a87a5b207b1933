"""The benchmark harness's stage profile: shares that add up, stages that are really timed, nothing left wrapped."""

import time

import gymnasium
import numpy as np

import trackenv.degradation
import trackenv.envs  # noqa: F401  (registers the environments)
import trackenv.envs.line_episode
import trackenv.physics._kernel
from trackenv_studies.bench import PROFILE_LABELS, _StageTimer, cpu_model, format_profile


def test_stage_timer_profiles_env_steps_and_restores_the_functions():
    def wrapped():
        episode = trackenv.envs.line_episode
        return (trackenv.physics._kernel.run, trackenv.degradation.implicit_settlement_step,
                episode.simulate_pass_batches, episode.implicit_settlement_step, episode.d1_filter)

    before = wrapped()
    env = gymnasium.make("trackenv/Tamping-v1")
    env.reset(seed=0)
    env.action_space.seed(0)
    with _StageTimer() as timer:
        t0 = time.perf_counter()
        for _ in range(2):
            env.step(env.action_space.sample())
        wall = time.perf_counter() - t0
    assert wrapped() == before  # unwrapped on exit
    for stage in ("kernel", "passes", "settlement", "quality"):
        assert timer.seconds.get(stage, 0.0) > 0.0, stage
    assert timer.seconds["passes"] >= timer.seconds["kernel"]  # the kernel runs inside the passes
    shares = timer.profile(wall)
    assert set(shares) == {key for key, _ in PROFILE_LABELS}
    assert all(v >= 0.0 for v in shares.values())
    assert np.isclose(sum(shares.values()), 1.0)  # the stages are disjoint and "other" is the rest


def test_a_stage_running_in_two_threads_at_once_counts_its_wall_time_once():
    """Kernels side by side (two threads) count the wall time during which either runs, not the sum of both."""
    import threading

    timer, barrier, spans = _StageTimer(), threading.Barrier(2, timeout=30), []

    def kernel():
        t0 = time.perf_counter()
        barrier.wait()  # both calls run at once
        time.sleep(0.05)
        spans.append((t0, time.perf_counter()))

    timed = timer._timed("kernel", kernel)
    threads = [threading.Thread(target=timed) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    union = max(end for _, end in spans) - min(start for start, _ in spans)
    assert max(end - start for start, end in spans) <= timer.seconds["kernel"] <= union + 0.01
    assert timer.seconds["kernel"] < sum(end - start for start, end in spans)


def test_format_profile_is_a_markdown_table_of_every_env_benchmark():
    share = {"kernel": 0.5, "pass_setup": 0.1, "settlement": 0.2, "quality": 0.05, "other": 0.15}
    ok = {"status": "ok", "profile": share}
    d = {"env": ok, "vector_env": {"8": ok, "32": {"status": "unavailable", "reason": "x"}}, "line_env": ok,
         "line_vector_env": {}}
    table = format_profile(d).splitlines()
    assert table[0] == "| share of the step | Tamping-v1, 1 env | Tamping-v1, 8 envs | TampingLine-v0, 1 line |"
    assert table[2] == "| kernel | 50 % | 50 % | 50 % |"
    assert len(table) == 2 + len(PROFILE_LABELS)


def test_batch_gains_compare_the_largest_batch_with_single_passes():
    """``batch_gain`` divides the largest batch's passes/s on the default threads by the single pass's,
    ``lockstep_gain`` the same on one thread; both from the timings the benchmark reports."""
    from trackenv_studies.bench import _bench_batches

    out = _bench_batches(1, sizes=(1, 2))
    one, two = out["rows"]["1"], out["rows"]["2"]
    assert out["batch_gain"] == two["all_threads"]["passes_per_s"] / one["all_threads"]["passes_per_s"]
    assert out["lockstep_gain"] == two["one_thread"]["passes_per_s"] / one["one_thread"]["passes_per_s"]
    assert out["batch_gain"] > 0.0 and out["lockstep_gain"] > 0.0


def test_state_benchmark_times_both_problems_snapshots():
    from trackenv_studies.bench import STAGES, _bench_state

    out = _bench_state(1)
    assert set(out) == {"line", "tamping"} and STAGES[-1] == "state"
    for figures in out.values():
        assert figures["get_state"]["median_s"] > 0 and figures["set_state"]["median_s"] > 0
        assert figures["pickled_bytes"] > 10_000  # the arrays of an episode, not an empty shell


def test_the_fast_line_figure_runs_the_line_with_the_fast_options():
    """``line_env_fast`` makes the line with :data:`FAST_LINE` (the fast engine and pass reuse), which the config
    accepts as given, and reports them with its figure."""
    from trackenv_studies.bench import FAST_LINE, STAGES, _bench_env

    out = _bench_env(1, 30.0, env_id="trackenv/TampingLine-v0", **FAST_LINE)
    assert out["status"] == "ok", out.get("reason")
    assert out["make_kwargs"] == FAST_LINE and out["steps"] == 1
    cfg = gymnasium.make("trackenv/TampingLine-v0", **FAST_LINE).unwrapped.config
    assert (cfg.engine, cfg.pass_reuse_tolerance_m) == (FAST_LINE["engine"], FAST_LINE["pass_reuse_tolerance_m"])
    assert STAGES.index("line_env_fast") == STAGES.index("line_env") + 1


def test_the_line_rule_figures_step_the_policy_given():
    """``line_env_rule`` steps the line with the policy's actions: every step asks it, from the observation the
    previous step returned, and the figure names it."""
    from trackenv_studies.bench import STAGES, _bench_env

    class Waits:
        def __init__(self) -> None:
            self.seen: list[float] = []

        def predict(self, obs):
            self.seen.append(float(obs["time"][0]))
            return np.zeros(obs["section_sd"].shape, dtype=np.int8), None

        def __repr__(self) -> str:
            return "Waits()"

    policy = Waits()
    out = _bench_env(2, 30.0, env_id="trackenv/TampingLine-v0", policy=policy)
    assert out["status"] == "ok", out.get("reason")
    assert out["actions"] == out["policy"] == "Waits()" and out["steps"] == 2
    assert len(policy.seen) == 3 and policy.seen == sorted(policy.seen) and policy.seen[0] < policy.seen[-1]
    assert STAGES.index("line_env_rule") == STAGES.index("line_env_fast") + 1
    assert STAGES.index("line_env_fast_rule") == STAGES.index("line_env_rule") + 1


def test_the_machine_is_named_by_its_processor_model(tmp_path):
    """The figures carry the processor's model name (the first "model name" of /proc/cpuinfo), not just the
    architecture; without one, what the platform module knows."""
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: GenuineIntel\nmodel name\t: Intel(R) Xeon(R)  Processor @ 2.80GHz\n"
                    "\nprocessor\t: 1\nmodel name\t: Intel(R) Xeon(R) Processor @ 2.80GHz\n")
    assert cpu_model(str(info)) == "Intel(R) Xeon(R) Processor @ 2.80GHz"
    info.write_text("processor\t: 0\nBogoMIPS\t: 50.00\n")  # e.g. an ARM machine's: no model name
    assert cpu_model(str(info)) and cpu_model(str(info)) != "Intel(R) Xeon(R) Processor @ 2.80GHz"
    assert cpu_model(str(tmp_path / "missing")) == cpu_model(str(info))
