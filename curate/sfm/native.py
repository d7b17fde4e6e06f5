"""pycolmap, imported with curate's own signal handlers kept; COLMAP's log sent to a file.

pycolmap installs glog's failure signal handler when it is imported: on SIGTERM it prints a native stack dump
(and during mapping it deadlocked, holding the run folder's lock). :func:`load` imports pycolmap and installs
curate's handlers again (:mod:`curate.core.signals`), where curate had installed them.
"""

from __future__ import annotations

import contextlib
from pathlib import Path


def load():
    """The pycolmap module, with curate's signal handlers (re)installed after its import."""
    import pycolmap
    from curate.core import signals
    if signals.installed():
        signals.install()
    return pycolmap


@contextlib.contextmanager
def colmap_log(path: Path):
    """Send COLMAP's (glog) messages to ``path`` instead of the terminal while inside.

    glog appends a timestamp and pid to the destination name, so it writes to
    ``path.part.*`` files that are appended to ``path`` on exit. Errors still reach stderr.
    """
    pycolmap = load()
    L = pycolmap.logging
    saved = (L.logtostderr, L.alsologtostderr, L.stderrthreshold)
    prefix = str(path) + ".part."
    # COLMAP's errors go to the log too: the global mapper logs "Global mapping failed" for parts of
    # runs that succeed; a real failure reaches the user as curate's own error
    L.logtostderr, L.alsologtostderr, L.stderrthreshold = False, False, 3
    for lvl in (L.WARNING, L.ERROR, L.FATAL):
        L.set_log_destination(lvl, "")
    L.set_log_destination(L.INFO, prefix)
    try:
        yield
    finally:
        L.set_log_destination(L.INFO, "")  # closes (and flushes) the file
        L.logtostderr, L.alsologtostderr, L.stderrthreshold = saved
        with open(path, "ab") as dst:
            for part in sorted(path.parent.glob(path.name + ".part.*")):
                dst.write(part.read_bytes())
                part.unlink()


@contextlib.contextmanager
def stdout_to(path: Path):
    """Redirect the process's stdout file descriptor (C/C++ printf included) to ``path``, appending."""
    import os
    import sys
    sys.stdout.flush()
    saved = os.dup(1)
    with open(path, "ab") as f:
        os.dup2(f.fileno(), 1)
        try:
            yield
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)
