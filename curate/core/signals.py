"""The signals a scheduler sends stop curate as Ctrl-C does.

``timeout``, ``docker stop``, systemd, Slurm and Kubernetes send SIGTERM (a closed terminal SIGHUP). curate
handles them as Ctrl-C: the main thread raises :class:`Terminated` (a ``KeyboardInterrupt``), the run folder's
lock is released as the ``with`` blocks unwind, the training workers are killed, one line is printed and the
exit status is 143 (130 for Ctrl-C); a re-run resumes from the stages and trainings that finished.

Python runs a signal handler only between bytecodes of the main thread, and COLMAP's extraction, matching and
mapping are native calls that run for minutes (they release the GIL, but do not return). So every such signal
also wakes a watcher thread (``signal.set_wakeup_fd``): when the main thread has not finished unwinding
within :data:`GRACE_S`, the watcher ends the process itself, with the same line (said once, by whichever of the
two gets there first): the training workers killed and reaped (:func:`curate.core.pools.end_all`), the locks
released (:func:`curate.core.runfolder.release_all`), then ``os._exit``.

pycolmap installs glog's failure handler for SIGTERM when it is imported (it prints a native stack dump, and
during mapping it deadlocked holding the lock): :func:`install` is called again after that import
(:func:`curate.sfm.native.load`).
"""

from __future__ import annotations

import os
import signal
import sys
import threading

GRACE_S = 3.0
"""Seconds the main thread has to unwind after a signal before the watcher ends the process."""

_HUP = getattr(signal, "SIGHUP", None)     # not on Windows

EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143, **({_HUP: 129} if _HUP is not None else {})}
"""Exit status by signal (128 + its number, as a shell reports a process it killed)."""

WORD = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated",
        **({_HUP: "terminated (hang-up)"} if _HUP is not None else {})}
"""What the last line says, by signal."""


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP: stop as Ctrl-C does. ``signum``: the signal."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_state: dict = {"command": "curate", "pipe": None, "done": threading.Event(), "said": threading.Lock(),
                "installed": False, "ignored": None}
"""``said``: taken by whichever says the last line, the main thread (:func:`unwound`) or the watcher (``_force``),
so that it is said once."""


def _raise(signum, frame) -> None:
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


def install(command: str | None = None) -> None:
    """Handle SIGINT, SIGTERM and SIGHUP as described above (the main thread only; elsewhere nothing).
    ``command``: what the last line names ("curate run"). Calling it again re-installs the handlers (after an
    import that replaced them) and keeps the watcher. A signal ignored when curate started stays ignored
    (``nohup curate run ...``: closing the terminal does not stop the run; SIGINT of a background job)."""
    if threading.current_thread() is not threading.main_thread():
        return
    if command:
        _state["command"] = command
    if _state["ignored"] is None:
        _state["ignored"] = {s for s in EXIT if signal.getsignal(s) is signal.SIG_IGN}
    for s in EXIT:
        signal.signal(s, signal.SIG_IGN if s in _state["ignored"] else _raise)
    if _state["pipe"] is None:
        r, w = os.pipe()
        os.set_blocking(w, False)
        _state["pipe"] = (r, w)
        threading.Thread(target=_watch, args=(r,), name="curate-signals", daemon=True).start()
    signal.set_wakeup_fd(_state["pipe"][1], warn_on_full_buffer=False)
    _state["installed"] = True


def _after_fork_in_child() -> None:
    """A forked child (a multiprocessing worker) must not write its signals into the parent's pipe: the
    parent's watcher would take a worker's SIGTERM for its own and end the parent. The child starts without
    curate's watcher; :func:`install` there makes its own."""
    pipe = _state["pipe"]
    if pipe is None:
        return
    try:
        signal.set_wakeup_fd(-1)
    except (ValueError, OSError):
        pass
    for fd in pipe:
        try:
            os.close(fd)
        except OSError:
            pass
    _state.update(pipe=None, done=threading.Event(), said=threading.Lock(), installed=False)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


def installed() -> bool:
    return _state["installed"]


def said(exc: BaseException) -> tuple[str, int]:
    """(the word for the last line, the exit status) of a ``KeyboardInterrupt`` or :class:`Terminated`."""
    s = getattr(exc, "signum", signal.SIGINT)
    return WORD.get(s, "interrupted"), EXIT.get(s, 130)


def unwound() -> bool:
    """The main thread has handled the signal: the watcher leaves the exit to it. True: the main thread says the
    last line; False: the watcher, whose grace ran out just before, is ending the process and says it (the line
    once, not twice)."""
    _state["done"].set()
    return _state["said"].acquire(blocking=False)


def _watch(r: int) -> None:
    while True:
        try:
            data = os.read(r, 64)
        except OSError:
            return
        sigs = [s for s in data if s in EXIT]
        if not sigs:
            continue
        if _state["done"].wait(GRACE_S) or not _state["said"].acquire(blocking=False):
            return               # the main thread unwound in time, or just now: it says the line
        _force(sigs[-1])


def _force(signum: int) -> None:
    """End the process now: the main thread is inside native work and cannot unwind."""
    from curate.core import pools, runfolder
    try:
        pools.end_all()          # the training workers killed and reaped: none outlives the command
        runfolder.release_all()
    finally:
        word = WORD.get(signum, "terminated")
        try:
            sys.stderr.write(f"{_state['command']}: {word}\n")
            sys.stderr.flush()
        finally:
            os._exit(EXIT.get(signum, 143))

