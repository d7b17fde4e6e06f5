"""Local process pools that never outlive the command that started them.

The evaluation trains its subsets in a ``ProcessPoolExecutor`` of spawned workers (:mod:`curate.evaluate.schedule`,
:func:`curate.evaluate.units.run_units`). Every way out of it ends them, and the command exits only once they are
gone, reaped, not left to the system to collect:

* the evaluation done, decided early, out of time (``--eval-minutes``), one fold (``--folds 1``): the pool is shut
  down, waiting for the trainings in flight (:func:`end_pool`);
* an error, Ctrl-C, SIGTERM or SIGHUP while the main thread can unwind: the workers are killed, then reaped
  (:func:`end_pool` with ``kill``);
* a signal while the main thread is inside native work (:mod:`curate.core.signals` ends the process itself):
  :func:`end_all` kills and reaps them before ``os._exit``.

Ctrl-C at a terminal sends SIGINT to the whole foreground process group, the workers included. A worker that
took it would print a ``KeyboardInterrupt`` traceback (one still starting, outside the pool's ``try``), and be
killed mid-line, so that curate's own last line was glued to a broken one. The workers therefore start with
SIGINT blocked (a blocked signal is inherited across ``fork`` and ``exec``, and Python does not unblock it):
the command that started them ends them, as above. SIGTERM and SIGHUP keep their default action, to die
silently.

A spawned pool also starts multiprocessing's *resource tracker*, a process of its own that, left alone, ends
only after curate has exited (it reads its pipe until curate's end closes it): at exit (and in :func:`end_all`)
it is stopped and reaped too (:func:`stop_tracker`).
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import gc
import logging
import os
import signal
import threading

log = logging.getLogger(__name__)

_pools: list = []
_mutex = threading.Lock()
_registered = False


@contextlib.contextmanager
def sigint_blocked():
    """SIGINT blocked in the calling thread (a process started meanwhile inherits it blocked). A SIGINT sent to
    curate meanwhile is not lost: another thread takes it, or it is delivered when the block ends."""
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - Windows has no process groups to signal
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@functools.cache
def _pool_class():
    from concurrent.futures import ProcessPoolExecutor

    class QuietPool(ProcessPoolExecutor):
        """Starts its workers (in ``submit``) with SIGINT blocked (module docstring)."""

        def submit(self, fn, /, *args, **kwargs):
            with sigint_blocked():
                return super().submit(fn, *args, **kwargs)

    return QuietPool


def local_pool(workers: int, initializer=None, initargs: tuple = ()):
    """A ``ProcessPoolExecutor`` of ``workers`` spawned processes, ended with the command, whose workers ignore
    Ctrl-C (module docstring)."""
    import multiprocessing as mp
    global _registered
    ex = _pool_class()(workers, mp_context=mp.get_context("spawn"), initializer=initializer, initargs=initargs)
    with _mutex:
        _pools.append(ex)
        if not _registered:
            atexit.register(_at_exit)
            _registered = True
    return ex


def end_pool(ex, kill: bool = False) -> None:
    """End the local pool ``ex``: with ``kill``, its running trainings are killed, not waited for; else they finish.
    Its processes are reaped before this returns."""
    procs = list((getattr(ex, "_processes", None) or {}).values())
    if kill:
        for p in procs:
            try:
                p.kill()
            except Exception:  # noqa: BLE001 - already gone
                pass
    try:
        ex.shutdown(wait=True, cancel_futures=kill)
    except Exception:  # noqa: BLE001 - a broken pool: its processes are reaped below
        pass
    for p in procs:
        try:
            p.join(10)
            if p.is_alive():    # pragma: no cover - a worker that ignores its end
                p.kill()
                p.join(5)
        except Exception:  # noqa: BLE001
            pass
    with _mutex:
        if ex in _pools:
            _pools.remove(ex)


def stop_tracker() -> None:
    """Stop multiprocessing's resource tracker of this process, if it started one, and reap it. Call once no
    pool is left (the semaphores it tracks are released when their pools are collected)."""
    try:
        from multiprocessing import resource_tracker
    except ImportError:  # pragma: no cover
        return
    rt = getattr(resource_tracker, "_resource_tracker", None)
    lock = getattr(rt, "_lock", None)
    if rt is None or lock is None:  # pragma: no cover - another Python
        return
    with lock:
        fd, pid = getattr(rt, "_fd", None), getattr(rt, "_pid", None)
        if fd is None:
            return
        try:
            os.close(fd)             # its end of the pipe: the tracker cleans up and exits
        except OSError:
            pass
        rt._fd = None
        if pid is not None:
            try:
                os.waitpid(pid, 0)
            except ChildProcessError:
                pass
            rt._pid = None


def end_all() -> None:
    """Kill and reap every local pool still running, then the resource tracker (the process ends now)."""
    with _mutex:
        pools = list(_pools)
    for ex in pools:
        end_pool(ex, kill=True)
    stop_tracker()


def _at_exit() -> None:
    with _mutex:
        left = list(_pools)
    for ex in left:
        end_pool(ex, kill=True)
    gc.collect()                 # the pools' queues release their semaphores before the tracker is told to stop
    stop_tracker()
