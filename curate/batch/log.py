"""Per-folder logging of ``curate batch``: a folder's stage lines, warnings and curate's INFO
log go to ``RUN/run.log`` (:func:`folder_log`), progress-bar refreshes are dropped."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from pathlib import Path


class NoProgress:
    """A text stream that drops progress-bar refreshes (writes with a carriage return or a cursor move)."""

    def __init__(self, f):
        self._f = f

    def write(self, s: str) -> int:
        if "\r" not in s and "\x1b[" not in s and s.strip():
            self._f.write(s)
        return len(s)

    def flush(self) -> None:
        self._f.flush()

    def isatty(self) -> bool:
        return False

    def fileno(self) -> int:
        return self._f.fileno()


@contextlib.contextmanager
def folder_log(run_dir: Path, fd_level: bool):
    """Send this folder's stage lines (stdout), warnings and curate's INFO log to ``RUN/run.log``.

    ``fd_level``: also redirect file descriptors 1 and 2 (a process of its own: the
    training workers it spawns write there too).
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    f = open(run_dir / "run.log", "a", buffering=1, encoding="utf-8")
    f.write(f"==== curate batch {time.strftime('%Y-%m-%d %H:%M:%S')} (pid {os.getpid()}) ====\n")
    lg = logging.getLogger("curate")
    handler = logging.StreamHandler(f)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s", "%H:%M:%S"))
    old_level, old_prop = lg.level, lg.propagate
    lg.addHandler(handler)
    lg.setLevel(logging.INFO)
    lg.propagate = False
    saved = None
    if fd_level:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = (os.dup(1), os.dup(2))
        os.dup2(f.fileno(), 1)
        os.dup2(f.fileno(), 2)
    try:
        with contextlib.redirect_stdout(f), contextlib.redirect_stderr(NoProgress(f)):
            yield f
    finally:
        lg.removeHandler(handler)
        lg.setLevel(old_level)
        lg.propagate = old_prop
        if saved:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
        f.close()
