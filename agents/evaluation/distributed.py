"""Ray for the work that outgrows one process: episode batches of the evaluation harness as Ray tasks.

:class:`RayExecutor` has the one method the harness asks of an executor, ``map(fn, items)`` (results in the
order of ``items``), and runs each call as a Ray task: ``evaluate_many(..., executor=RayExecutor())`` sends
every batch of episodes (:func:`trackenv_agents.evaluation.harness.run_episodes`, one native vector env each) to a
worker, on this machine (a local Ray started with ``num_cpus``) or on a cluster (``address="ray://head:10001"``
or ``"auto"`` on a cluster node). Each episode is fixed by its seed and the batches are the ones the
single-process path runs, so the results are the same; only the wall time changes.

Each task reserves ``cpus_per_task`` CPUs and runs the compiled kernel on that many threads
(``NUMBA_NUM_THREADS`` in the workers' environment), so tasks do not fight over cores: on one machine, one task
per core is the fastest split (the kernel's own threads gain less than separate batches).

Ray is an optional extra (``pip install trackenv[ray]``); nothing else in trackenv imports this module.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

__all__ = ["RayExecutor"]


def _call(fn: Callable, item: Any) -> Any:
    return fn(item)


class RayExecutor:
    """``map(fn, items)`` over Ray tasks. Connects to (or starts) Ray on first use; :meth:`close` (or ``with``)
    shuts down a Ray it started.

    ``address``: None starts a local Ray (``num_cpus`` CPUs, default all); ``"auto"`` or ``"ray://host:10001"``
    joins a running cluster (``num_cpus`` is then ignored). ``cpus_per_task``: CPUs (and kernel threads) per
    batch of episodes."""

    def __init__(self, address: str | None = None, num_cpus: int | None = None, cpus_per_task: int = 1) -> None:
        if cpus_per_task < 1:
            raise ValueError(f"cpus_per_task must be >= 1, got {cpus_per_task!r}")
        self.address = address
        self.num_cpus = num_cpus
        self.cpus_per_task = int(cpus_per_task)
        self._started = False
        self._task: Any = None  # the Ray remote function, made on first use

    def _ray(self):
        try:
            import ray
        except ImportError as exc:  # pragma: no cover - depends on the installation
            raise ImportError("Ray is not installed: pip install 'trackenv[ray]'") from exc
        if not ray.is_initialized():
            env = {"env_vars": {"NUMBA_NUM_THREADS": str(self.cpus_per_task)}}
            if self.address is None:
                ray.init(num_cpus=self.num_cpus, include_dashboard=False, runtime_env=env,
                         log_to_driver=False)
            else:
                ray.init(address=self.address, runtime_env=env, log_to_driver=False)
            self._started = True
        if self._task is None:
            self._task = ray.remote(num_cpus=self.cpus_per_task)(_call)
        return ray

    def map(self, fn: Callable, items: Iterable[Any]) -> Iterator[Any]:
        """``fn(item)`` for each item as Ray tasks (``fn`` is shipped once); yields the results in order."""
        ray = self._ray()
        fn_ref = ray.put(fn)
        refs = [self._task.remote(fn_ref, item) for item in items]
        for ref in refs:
            yield ray.get(ref)

    def close(self) -> None:
        """Shut down the Ray this executor started (a Ray started elsewhere is left running)."""
        if self._started:
            import ray

            ray.shutdown()
            self._started = False
            self._task = None

    def __enter__(self) -> RayExecutor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
