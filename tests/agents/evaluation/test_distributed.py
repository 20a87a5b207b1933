"""Ray tasks for the evaluation harness: the same results as the single-process path (a local Ray, 2 CPUs), for
the 60 m track and for the comparison of a preset (what `trackenv evaluate --env ... --ray` runs)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ray")

# one local Ray at a time: with `make test`'s workers (pytest-xdist, --dist loadgroup) every test that starts
# one runs in the same worker
pytestmark = pytest.mark.xdist_group("ray")

from trackenv.envs.line_config import scenario  # noqa: E402
from trackenv_agents.evaluation.distributed import RayExecutor  # noqa: E402
from trackenv_agents.evaluation.harness import evaluate_many  # noqa: E402
from trackenv_agents.evaluation.line_compare import line_comparison  # noqa: E402
from trackenv_agents.evaluation.tuning import tune  # noqa: E402
from trackenv_agents.rules.line import LineNoMaintenance, SectionThreshold, UniformPeriodic  # noqa: E402

# the 60 m track cut to 30 m in 3 sections over 1 year: 4 steps
CFG = scenario("track60", n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3,
               horizon_years=1.0)
SEEDS = [0, 1, 2, 3, 4]
# one episode per batch: the kernel entry that tests/conftest.py compiles, also in the one-thread Ray workers
# (a wider batch there needs an entry of its own, minutes to compile on a fresh machine)
BATCH = 1


@pytest.fixture(scope="module")
def executor():
    with RayExecutor(num_cpus=2) as ex:
        yield ex


@pytest.mark.slow
def test_ray_tasks_give_the_single_process_results(executor) -> None:
    policies = [LineNoMaintenance(), SectionThreshold(threshold_mm=0.8)]
    here = evaluate_many(policies, CFG, SEEDS, batch_size=BATCH)
    there = evaluate_many(policies, CFG, SEEDS, batch_size=BATCH, executor=executor)
    for a, b in zip(here, there, strict=True):
        np.testing.assert_array_equal(a.seeds, b.seeds)
        np.testing.assert_array_equal(a.cost, b.cost)
        np.testing.assert_array_equal(a.section_tampings, b.section_tampings)
        np.testing.assert_array_equal(a.final_mean_sd_mm, b.final_mean_sd_mm)
        assert a.summary() == b.summary()


@pytest.mark.slow
def test_tuning_over_ray_picks_the_same_parameters(executor) -> None:
    grid = [{"interval_years": 0.5}, {"interval_years": 0.75}]
    here = tune(UniformPeriodic, CFG, [10, 11], grid=grid, batch_size=BATCH)
    there = tune(UniformPeriodic, CFG, [10, 11], grid=grid, batch_size=BATCH, executor=executor)
    assert here == there


@pytest.mark.slow
def test_line_comparison_over_ray_gives_the_single_process_table(executor, tmp_path) -> None:
    """The line's comparison (`trackenv evaluate --env trackenv/TampingLineSmall-v0 --ray`) on a short horizon and
    two seeds: every policy's costs, CIs and paired differences as in one process. Batches of two episodes, so
    the six policies' twelve episodes make six Ray tasks."""
    kw = {"seeds": [0, 1], "batch_size": 2, "progress": False, "horizon_years": 1.0}
    here = line_comparison("trackenv/TampingLineSmall-v0", out_dir=str(tmp_path / "here"), **kw)
    there = line_comparison("trackenv/TampingLineSmall-v0", out_dir=str(tmp_path / "there"), executor=executor,
                            **kw)
    assert [r["policy"] for r in here["results"]] == [r["policy"] for r in there["results"]]
    assert len(here["results"]) == 6 and here["results"][-1]["mean_cost"] > 0
    assert here["results"] == there["results"]


def test_executor_checks_its_arguments() -> None:
    with pytest.raises(ValueError, match="cpus_per_task"):
        RayExecutor(cpus_per_task=0)
