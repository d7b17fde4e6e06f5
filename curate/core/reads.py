"""Files of a run folder read once per process, and read again only once they changed.

One ``curate run`` reads the same small files many times: every stage's key reads the records of the stages it
depends on, the SfM result is read by each stage after it, the report reads what the stages wrote. :func:`kept`
parses a file once and keeps the result, keyed by its path and its identity on disk (device, inode, size,
modification and change times, to the nanosecond): a file rewritten since, by a later stage, by another process
or by the user (curate's writes replace a file by a rename, a new inode), is read again. A kept result lives as
long as the process, :data:`MAX_KEPT` files at most.

Light: no curate import, so that every module of the core may read through it (:mod:`curate.core.stage`'s
``read_stage``, the run folder's manifests); the typed readers of a run's results are :mod:`curate.core.run`.
"""

from __future__ import annotations

import json
import os
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable, TypeVar

T = TypeVar("T")

MAX_KEPT = 512
"""Files kept at most (the least recently read are let go first): a batch of many run folders stays bounded."""

_kept: "OrderedDict[tuple[str, str], tuple[tuple[int, ...], Any]]" = OrderedDict()
_lock = threading.Lock()


def identity(path: str | Path) -> tuple[int, ...]:
    """What tells one version of the file ``path`` from another: (device, inode, size, mtime_ns, ctime_ns).
    ``OSError`` (``FileNotFoundError``, ...) as ``open`` would raise it."""
    st = os.stat(path)
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns


def kept(path: str | Path, kind: str, parse: Callable[[Path], T]) -> T:
    """``parse(path)``, parsed once while the file stays the same (:func:`identity`); ``kind`` names the parse (one
    file may be kept as text and as an object). What ``parse`` raises is raised, and nothing is kept. The result is
    shared by every caller: ``parse`` must return something no caller changes (text, a tuple, read-only arrays)."""
    p = Path(path)
    key = (os.path.abspath(p), kind)
    now = identity(p)
    with _lock:
        hit = _kept.get(key)
        if hit is not None and hit[0] == now:
            _kept.move_to_end(key)
            return hit[1]
    value = parse(p)
    with _lock:
        _kept[key] = (now, value)
        _kept.move_to_end(key)
        while len(_kept) > MAX_KEPT:
            _kept.popitem(last=False)
    return value


def read_text(path: str | Path) -> str:
    """``Path(path).read_text()``, read once while the file stays the same."""
    return kept(path, "text", lambda p: p.read_text())


def read_json(path: str | Path) -> Any:
    """``json.loads(Path(path).read_text())``: the text read once while the file stays the same, parsed on each
    call (the caller may change what it gets). ``OSError`` or ``ValueError`` as those would raise them."""
    return json.loads(read_text(path))
