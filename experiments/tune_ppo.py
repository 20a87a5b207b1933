"""Ray Tune over PPO's hyper-parameters (stable-baselines3 through ``trackenv_agents.learning.tamping``), with ASHA.

Each trial trains from the hyper-parameters of ``agents/learning/hyperparams/ppo.yml`` with four of them drawn from a
small space (learning rate, clip range, rollout length, entropy bonus); the held-out evaluation of the training
run (deterministic return on evaluation seeds 10000-, never the test seeds) is reported to Tune after every
``--eval-freq`` env steps, and ASHA stops the trials that trail the others at each rung. One CPU per trial
(the compiled kernel then runs one thread), so a local Ray runs as many trials at once as it has CPUs; on a
cluster (``--address auto``) trials spread over the machines.

Examples::

    python experiments/tune_ppo.py --quick                       # 2 tiny trials on a 30 m track, ~1 min
    python experiments/tune_ppo.py --num-samples 16 --timesteps 40960 --eval-freq 4096 --out results/tune_ppo
    python experiments/tune_ppo.py --address auto --num-samples 64 ...   # on a Ray cluster

Writes ``<out>/tune_ppo.json``: every trial's parameters and last/best evaluation return, best first.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

# --quick: the 60 m track (the trainer's preset, "track60") cut to 30 m in 3 sections over 1 year (4 steps)
QUICK_OVERRIDES = {"n_sections": 3, "segment_length_m": 30.0, "sections_per_segment": 3, "capacity": 3,
                   "horizon_years": 1.0}


def search_space() -> dict[str, Any]:
    """The hyper-parameters searched (the rest come from agents/learning/hyperparams/ppo.yml)."""
    from ray import tune

    return {
        "learning_rate": tune.loguniform(1e-5, 3e-4),
        "clip_range": tune.choice([0.1, 0.2]),
        "n_steps": tune.choice([64, 128]),
        "ent_coef": tune.choice([0.0, 0.01]),
    }


def trainable(params: dict[str, Any], *, config: dict | None, timesteps: int, eval_freq: int,
              eval_seeds: list[int], extra: dict[str, Any]) -> None:
    """One Tune trial: train() with ``params`` over the shipped hyper-parameters, reporting every evaluation."""
    from ray import tune

    from trackenv_agents.learning.tamping import train

    def report(rec: dict) -> None:
        tune.report({"eval_return": rec["mean_return"], "timesteps": rec["timesteps"]})

    with tempfile.TemporaryDirectory() as out:
        train(config=config, total_timesteps=timesteps, n_envs=extra.get("n_envs"), out_dir=out,
              hyperparams={**extra, **params}, progress=False, eval_seeds=eval_seeds, eval_freq=eval_freq,
              checkpoint_every_s=0, verbose=0, on_evaluation=report)


def run(num_samples: int, timesteps: int, eval_freq: int, eval_seeds: list[int], config: dict | None = None,
        extra: dict[str, Any] | None = None, address: str | None = None, num_cpus: int | None = None,
        seed: int = 0) -> list[dict[str, Any]]:
    """Run the search; the trials sorted by their best evaluation return (best first)."""
    import ray
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler

    ray.init(address=address, num_cpus=None if address else num_cpus, include_dashboard=False,
             runtime_env={"env_vars": {"NUMBA_NUM_THREADS": "1"}})
    try:
        fn = tune.with_parameters(trainable, config=config, timesteps=timesteps, eval_freq=eval_freq,
                                  eval_seeds=eval_seeds, extra=dict(extra or {}))
        space = search_space()
        tuner = tune.Tuner(
            tune.with_resources(fn, {"cpu": 1}),
            param_space=space,
            tune_config=tune.TuneConfig(
                metric="eval_return", mode="max", num_samples=num_samples,
                scheduler=ASHAScheduler(time_attr="timesteps", max_t=timesteps, grace_period=eval_freq,
                                        reduction_factor=2),
                search_alg=tune.search.BasicVariantGenerator(random_state=seed),
            ),
            run_config=tune.RunConfig(storage_path=str(Path(tempfile.gettempdir()) / "trackenv_tune"),
                                      verbose=0),
        )
        results = tuner.fit()
        rows = []
        for r in results:
            hist = r.metrics_dataframe
            rows.append({"params": {k: r.config[k] for k in space},
                         "best_eval_return": float(hist["eval_return"].max()) if hist is not None else None,
                         "last_eval_return": r.metrics.get("eval_return"),
                         "timesteps": r.metrics.get("timesteps"), "error": str(r.error) if r.error else None})
    finally:
        ray.shutdown()
    return sorted(rows, key=lambda row: -(row["best_eval_return"] if row["best_eval_return"] is not None
                                          else float("-inf")))


def main(argv=None) -> list[dict[str, Any]]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--num-samples", type=int, default=8)
    p.add_argument("--timesteps", type=int, default=16384, help="env steps per trial at most")
    p.add_argument("--eval-freq", type=int, default=2048, help="env steps between reports (an ASHA rung)")
    p.add_argument("--n-eval", type=int, default=16, help="evaluation seeds (10000, 10001, ...)")
    p.add_argument("--no-warm-start", action="store_true", help="train from scratch (no behaviour cloning)")
    p.add_argument("--quick", action="store_true", help="2 trials of 256 steps on a 30 m track, one env (a smoke run)")
    p.add_argument("--num-cpus", type=int, default=None, help="CPUs of the local Ray (default: all)")
    p.add_argument("--address", default=None, help="join a Ray cluster ('auto' or ray://HEAD:10001)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random search")
    p.add_argument("--out", default="results/tune_ppo")
    a = p.parse_args(argv)
    config, extra = None, {}
    if a.no_warm_start or a.quick:
        extra["warm_start_rule"] = None
    if a.quick:
        from trackenv.envs.line_config import scenario

        config = scenario("track60", **QUICK_OVERRIDES).to_dict()
        a.num_samples, a.timesteps, a.eval_freq, a.n_eval = 2, 256, 128, 1
        extra.update(n_envs=1, batch_size=64)  # one env: batches of one, the kernel entry compiled first
    rows = run(a.num_samples, a.timesteps, a.eval_freq, list(range(10_000, 10_000 + a.n_eval)), config, extra,
               a.address, a.num_cpus, a.seed)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "tune_ppo.json").write_text(json.dumps(rows, indent=1))
    for row in rows:
        print(json.dumps(row))
    return rows


if __name__ == "__main__":
    main()
