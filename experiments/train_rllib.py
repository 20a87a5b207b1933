"""Train PPO with RLlib (Ray 2.60, new API stack) on a trackenv env, registered with ``register_env``.

The env is ``--env-id`` (default ``trackenv/Tamping-v1``; any id with MultiBinary section actions and a Dict
observation with ``section_sd`` works, e.g. the line env's, and the ids with the choices) seen through
:mod:`trackenv.envs.wrappers`: ranked actions (``Discrete(n_sections + 1)``; with the choices one count per
choice, ``MultiDiscrete``) and the section-level observation flattened to one ``Box``, which
RLlib's default encoders take (a Dict observation or MultiBinary actions they do not). With ``--num-envs`` > 1
each env runner steps the native vector env (batched physics, NEXT_STEP autoreset, RLlib's convention).

With ``--multi-agent`` the env is a line id posed as one agent per section
(:func:`trackenv.envs.line_parallel_env`, through RLlib's ``ParallelPettingZooEnv``), every agent mapped to one
shared policy (parameter sharing) and each agent's dict observation (its features and its action mask) flattened
to one vector by RLlib's ``FlattenObservations`` connector.

Examples::

    python experiments/train_rllib.py --iterations 20 --out results/rllib
    python experiments/train_rllib.py --env-id trackenv/Tamping-v1 --env-config '{"horizon_years": 5}' \\
        --num-env-runners 2 --num-envs 8
    python experiments/train_rllib.py --address auto ...     # on a Ray cluster (ray start --head first)
    python experiments/train_rllib.py --multi-agent --env-id trackenv/TampingLineSmall-v0

Writes ``<out>/rllib_summary.json`` (per-iteration mean return, episode length, time) and a checkpoint.

**Reproducible.** The same command on the same machine trains the same policy: ``--seed`` seeds RLlib (its
module, its sampling, the envs' first reset), and the script runs with ``PYTHONHASHSEED`` fixed (it starts
itself again with ``PYTHONHASHSEED=0`` where the variable is unset, and passes it to Ray's workers): RLlib's
multi-agent episodes iterate sets of agent ids, whose order follows Python's per-process string hashing, so
without it two runs of ``--multi-agent`` sample in different orders from the first iteration on.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

ENV_NAME = "trackenv-rllib"
HASH_SEED = "0"  # PYTHONHASHSEED the script runs with where none is set (see the module's docstring)


def run_with_fixed_hash_seed() -> None:
    """Start this script again with ``PYTHONHASHSEED`` fixed where it is unset (it must be set before the
    interpreter starts); a value the caller set is kept."""
    if os.environ.get("PYTHONHASHSEED") is None:
        os.environ["PYTHONHASHSEED"] = HASH_SEED
        os.execv(sys.executable, [sys.executable, *sys.argv])


def make_env(env_config: dict[str, Any]):
    """RLlib's env creator: ``env_id`` (default ``trackenv/Tamping-v1``) in ranked actions with a flat
    section-level observation; with ``num_envs`` (RLlib's ``vector_entry_point`` mode) the native vector env;
    with ``multi_agent`` (a line id) one agent per section, as RLlib's ``ParallelPettingZooEnv``."""
    import trackenv.envs  # noqa: F401  (registers the ids in this worker)
    from trackenv.envs.wrappers import make_ranked, make_ranked_vector

    kwargs = dict(env_config)
    env_id = kwargs.pop("env_id", "trackenv/Tamping-v1")
    num_envs = kwargs.pop("num_envs", None)
    if kwargs.pop("multi_agent", False):
        from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

        return ParallelPettingZooEnv(trackenv.envs.line_parallel_env(env_id, **kwargs))
    if num_envs is not None:
        return make_ranked_vector(int(num_envs), env_id=env_id, flat=True, **kwargs)
    return make_ranked(env_id, flat=True, **kwargs)


def build_config(env_config: dict[str, Any] | None = None, *, num_env_runners: int = 0, num_envs: int = 1,
                 train_batch: int = 512, minibatch: int = 128, epochs: int = 5, lr: float = 3e-4,
                 gamma: float = 0.995, hidden: tuple[int, ...] = (64, 64), seed: int = 20_000,
                 native_vector: bool = True):
    """A PPOConfig for :func:`make_env` (registered as ``trackenv-rllib``); the CI test uses a tiny one. With
    ``multi_agent`` in ``env_config``: one policy (``"shared"``) for every section's agent, fed the flattened
    dict observation; one env per runner (``num_envs`` 1)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.tune.registry import register_env

    register_env(ENV_NAME, make_env)
    env_config = dict(env_config or {})
    multi_agent = bool(env_config.get("multi_agent", False))
    if multi_agent and num_envs != 1:
        raise ValueError(f"num_envs must be 1 with multi_agent (one line env per runner), got {num_envs}")
    config = (
        PPOConfig()
        .environment(ENV_NAME, env_config=env_config)
        .env_runners(num_env_runners=num_env_runners, num_envs_per_env_runner=num_envs,
                     gym_env_vectorize_mode="vector_entry_point" if native_vector and num_envs > 1 else "sync",
                     rollout_fragment_length="auto")
        .learners(num_learners=0)
        .training(train_batch_size_per_learner=train_batch, minibatch_size=minibatch, num_epochs=epochs, lr=lr,
                  gamma=gamma)
        .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=list(hidden)))
        .debugging(seed=seed)
    )
    if multi_agent:
        from ray.rllib.connectors.env_to_module import FlattenObservations

        config = (config
                  .env_runners(env_to_module_connector=lambda env, spaces, device: FlattenObservations(
                      multi_agent=True))
                  .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, episode, **kw: "shared"))
    return config


def iteration_record(i: int, result: dict, seconds: float) -> dict[str, Any]:
    runners = result.get("env_runners", {})
    return {"iteration": i, "env_steps": int(runners.get("num_env_steps_sampled_lifetime", 0)),
            "episode_return_mean": runners.get("episode_return_mean"),
            "episode_len_mean": runners.get("episode_len_mean"), "seconds": seconds}


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--env-id", default=None,
                   help="default trackenv/Tamping-v1; with --multi-agent trackenv/TampingLine-v0")
    p.add_argument("--env-config", default="{}", help="JSON of env keyword arguments (LineConfig fields)")
    p.add_argument("--iterations", type=int, default=10)
    p.add_argument("--num-env-runners", type=int, default=0, help="remote env runners (0: sample in the driver)")
    p.add_argument("--num-envs", type=int, default=None,
                   help="envs per runner (native vector env if > 1; default 8, with --multi-agent 1)")
    p.add_argument("--sync", action="store_true", help="Gymnasium's SyncVectorEnv instead of the native one")
    p.add_argument("--multi-agent", action="store_true",
                   help="one agent per section of a line id, one shared policy")
    p.add_argument("--train-batch", type=int, default=512)
    p.add_argument("--minibatch", type=int, default=128)
    p.add_argument("--epochs", type=int, default=5)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--gamma", type=float, default=0.995)
    p.add_argument("--seed", type=int, default=20_000)
    p.add_argument("--num-cpus", type=int, default=None, help="CPUs of the local Ray (default: all)")
    p.add_argument("--address", default=None, help="join a Ray cluster ('auto' or ray://HEAD:10001)")
    p.add_argument("--out", default="results/rllib")
    a = p.parse_args(argv)
    import ray

    hash_seed = os.environ.get("PYTHONHASHSEED")
    ray.init(address=a.address, num_cpus=None if a.address else a.num_cpus, include_dashboard=False,
             runtime_env={"env_vars": {"PYTHONHASHSEED": hash_seed}} if hash_seed is not None else None)
    env_id = a.env_id or ("trackenv/TampingLine-v0" if a.multi_agent else "trackenv/Tamping-v1")
    env_config = {"env_id": env_id, **json.loads(a.env_config), **({"multi_agent": True} if a.multi_agent else {})}
    num_envs = a.num_envs if a.num_envs is not None else (1 if a.multi_agent else 8)
    algo = build_config(env_config, num_env_runners=a.num_env_runners, num_envs=num_envs,
                        train_batch=a.train_batch, minibatch=a.minibatch, epochs=a.epochs, lr=a.lr, gamma=a.gamma,
                        seed=a.seed, native_vector=not a.sync).build_algo()
    history = []
    try:
        for i in range(a.iterations):
            t0 = time.perf_counter()
            rec = iteration_record(i, algo.train(), time.perf_counter() - t0)
            history.append(rec)
            print(json.dumps(rec), flush=True)
        out = Path(a.out).resolve()
        out.mkdir(parents=True, exist_ok=True)
        checkpoint = algo.save(str(out / "checkpoint"))
        summary = {"env_config": env_config, "seed": a.seed, "pythonhashseed": hash_seed, "history": history,
                   "checkpoint": str(getattr(checkpoint, "checkpoint", checkpoint))}
        (out / "rllib_summary.json").write_text(json.dumps(summary, indent=1, default=str))
    finally:
        algo.stop()
        ray.shutdown()
    return summary


if __name__ == "__main__":
    run_with_fixed_hash_seed()
    main()
