"""Executors for ``curate batch``: a ``concurrent.futures.Executor`` over Ray, and Ray start-up.

Ray is an optional dependency (``pip install 'curate[ray]'``) imported only here and only
when asked for; :func:`require_ray` turns its absence into a clear error.

:class:`RayExecutor` is the adapter :func:`curate.pipeline.run` takes as ``executor=``:
each ``submit(fn, *args)`` becomes one Ray task (``ray.remote(fn).options(num_cpus=...,
num_gpus=...)``) and returns that task's ``ObjectRef.future()``, so the evaluation's
``as_completed`` loop works unchanged while a cluster trains the subsets in parallel.

A task waiting on such futures does not give its CPU back to Ray (only a blocking
``ray.get`` on the task's main thread does; measured: two 1-CPU tasks waiting on
1-CPU sub-tasks through ``future()`` deadlock a 2-CPU instance). So the code that
submits trainings must hold no CPU: ``curate batch`` runs it in a ``num_cpus=0`` task
(see :mod:`curate.batch.runner`).
"""

from __future__ import annotations

import os
from concurrent.futures import Executor, Future
from typing import Any, Callable


class RayMissing(RuntimeError):
    """``--executor ray`` without the ray package."""


def require_ray():
    """The ``ray`` module, or :class:`RayMissing` with how to install it."""
    try:
        import ray  # noqa: PLC0415 - optional, heavy
    except ImportError as e:
        raise RayMissing("--executor ray needs the ray package: pip install 'ray>=2.9' "
                         f"(or pip install -e '.[ray]') ({type(e).__name__}: {e})") from None
    return ray


def cpu_count() -> int:
    """CPU cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def available_memory() -> int:
    """Bytes of physical memory free now (8 GiB where the system does not say)."""
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # pragma: no cover
        return 8 << 30


def ray_init(address: str | None = None, num_cpus: int | None = None, env: dict | None = None):
    """Connect to a Ray cluster (``address``: 'auto' or 'HOST:PORT') or start a local instance.

    A local instance gets ``num_cpus`` (default: this machine's cores) and no dashboard.
    ``env``: environment variables for every worker (e.g. ``TQDM_DISABLE``). Returns ``ray``.
    """
    ray = require_ray()
    if ray.is_initialized():
        return ray
    kw: dict[str, Any] = {"log_to_driver": False, "runtime_env": {"env_vars": dict(env or {})}}
    if address:
        ray.init(address=address, **kw)
    else:
        ray.init(num_cpus=num_cpus or cpu_count(), include_dashboard=False, **kw)
    return ray


def cluster_gpus() -> float:
    """GPUs the Ray cluster advertises (0 without GPUs or without Ray)."""
    ray = require_ray()
    return float(ray.cluster_resources().get("GPU", 0.0))


class RayExecutor(Executor):
    """``concurrent.futures.Executor`` that runs each submitted call as one Ray task.

    ``num_cpus`` / ``num_gpus``: the resources each task asks for (a training is
    single-threaded on CPU: 1 CPU; one GPU per training when the cluster has GPUs).
    ``max_retries``: Ray's retries of a task whose worker died (0: a training killed
    for memory fails at once instead of being retried three times).
    The Ray connection must already be up (:func:`ray_init`, or inside a Ray task).
    """

    def __init__(self, num_cpus: float = 1, num_gpus: float = 0, max_retries: int = 0):
        self._ray = require_ray()
        self._opts = {"num_cpus": num_cpus, "num_gpus": num_gpus, "max_retries": max_retries}
        self._remote: dict[Callable, Any] = {}
        self._refs: list = []
        self._shutdown = False

    def submit(self, fn: Callable, /, *args, **kwargs) -> Future:
        if self._shutdown:
            raise RuntimeError("cannot submit after shutdown")
        rf = self._remote.get(fn)
        if rf is None:
            rf = self._remote[fn] = self._ray.remote(fn).options(**self._opts)
        ref = rf.remote(*args, **kwargs)
        self._refs.append(ref)
        return ref.future()

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._shutdown = True
        if cancel_futures:
            for ref in self._refs:
                try:
                    self._ray.cancel(ref)
                except Exception:  # noqa: BLE001 - already finished
                    pass
        if wait:
            for ref in self._refs:
                try:
                    self._ray.wait([ref])
                except Exception:  # noqa: BLE001
                    pass
        self._refs.clear()
