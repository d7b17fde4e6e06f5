"""A run folder is curate's own: claim it, lock it, and clear only what curate wrote there.

Three guarantees, for every command that writes a run folder (``run``, ``sfm``, ``select``,
the stage commands, ``batch``):

* **Claim** (:func:`claim`), before any work: ``RUN/.curate-run.json`` (tool version,
  created time) marks a folder curate created. Refused, with one line naming both paths:
  a non-empty folder without the marker (unless ``adopt``: the marker is written and the
  top-level entries already there are recorded as the user's, ``adopted``: curate never
  writes, clears or deletes them); any input (photo folder, poses file or model) inside the
  run folder, anywhere; the run folder inside an input folder; a run folder that cannot be
  written (read-only). Symbolic links are resolved first.
* **Lock** (:class:`RunLock`): one process per run folder at a time. ``RUN/.curate-lock``
  is held with ``fcntl.flock`` (released by the kernel when its process dies, whatever
  kills it) and holds the holder's PID, its start time (``/proc/PID/stat``: a reused PID
  is not mistaken for the holder), host, command, wall-clock start and a random token. A
  second process is refused (:class:`RunFolderBusy`: "RUN is in use by curate run, PID
  1234, started 13:02:11"); a lock whose holder is gone is taken over with a log line.
  The lock file is never deleted (deleting it would let two processes lock two inodes);
  on release it is emptied. Re-entrant within a process.
* **Never delete what curate did not write** (:func:`clear_tree`): a stage folder is
  cleared only inside a claimed run folder, and only when every file in it is curate's:
  listed in the stage's manifest (``files`` of ``stage.json``, written by
  :func:`curate.core.stage.finish_stage`), curate's bookkeeping (``stage.json``,
  ``.curate-stage``, ``*.tmp<pid>``), a file pattern the caller names as the stage's own, or
  anything in a folder that carries the ``.curate-stage`` marker but no record yet (a stage
  curate created empty and that was killed half-way: its contents are curate's scratch).
  Otherwise nothing at all is removed and :class:`RunFolderError` names the first foreign
  file.

* **A failed command leaves nothing behind** (:func:`claimed`): when the command fails and
  the run folder holds nothing but curate's bookkeeping (marker, lock, ``run.json``, empty
  stage folders), what the claim made goes: a folder it created (and the parents it
  created), or the marker and lock it wrote into a folder that was there (empty, or adopted),
  which is left as it was. A folder holding anything else (a finished stage, a record the
  error names) is kept as it is. A stage command never marks a folder: one without the
  marker is refused.

Stale workers: :func:`check_holder` (called by an evaluation training before it writes its
results) raises :class:`StaleWorker` unless the run's lock is still held, by the process
that started the worker (same token, holder alive). Workers also die with their parent:
:func:`die_with_parent` (``prctl(PR_SET_PDEATHSIG, SIGKILL)`` on Linux, plus a thread that
exits the process when ``os.getppid()`` changes) is the initializer of every process pool
curate starts. Ray: a task whose owner (driver or parent task) dies is killed by Ray's
fate sharing, and a training that still ran would fail :func:`check_holder`.
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import logging
import os
import socket
import stat
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Iterable, Iterator, NamedTuple

from curate.core.paths import RunPaths
from curate.core.reads import read_json

log = logging.getLogger(__name__)

MARKER = ".curate-run.json"
"""Written in every run folder curate creates (or adopts)."""
LOCK = ".curate-lock"
"""The run's lock file (flock'ed by the process working there)."""
STAGE_MARKER = ".curate-stage"
"""Written by :func:`curate.core.stage.begin_stage` in every stage folder it creates."""
BOOKKEEPING = (MARKER, LOCK, STAGE_MARKER, "stage.json")

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows: the PID / start time check alone
    fcntl = None  # type: ignore[assignment]


class RunFolderError(ValueError):
    """A run folder curate must not or cannot use: a one-line message naming the paths."""


class RunFolderBusy(RunFolderError):
    """Another process holds the run folder's lock."""


class StaleWorker(RuntimeError):
    """A worker whose run lost its lock (its parent died, another run took the folder)."""


# ------------------------------------------------------------------ claim
def _resolve(p: str | Path) -> Path:
    return Path(os.path.abspath(Path(p).expanduser())).resolve()


def is_claimed(path: str | Path) -> bool:
    """True when ``path`` carries curate's run-folder marker."""
    return (Path(path) / MARKER).is_file()


def run_root(path: str | Path) -> Path | None:
    """The nearest claimed run folder holding ``path`` (``path`` itself included), or None."""
    p = _resolve(path)
    for d in (p, *p.parents):
        if (d / MARKER).is_file():
            return d
    return None


def read_marker(path: str | Path) -> dict:
    try:
        return json.loads((Path(path) / MARKER).read_text())
    except (OSError, ValueError):
        return {}


def _write_marker(out: Path, adopted: list[str] | None) -> None:
    from curate import __version__
    rec = {"tool": "curate", "version": __version__, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    if adopted is not None:
        rec["adopted"] = adopted
    tmp = out / f"{MARKER}.tmp{os.getpid()}"
    try:
        tmp.write_text(json.dumps(rec, indent=1))
    except OSError:
        tmp.unlink(missing_ok=True)   # a full disk leaves no half-written marker that would block the next claim
        raise
    os.replace(tmp, out / MARKER)


def _why(e: OSError) -> str:
    import errno
    if e.errno == errno.ENOSPC:
        return "the disk is full (no space left on device); free some space, then run again"
    return str(e.strerror or e)


def claim(out: str | Path, inputs: Iterable[str | Path | None] = (), adopt: bool = False,
          writes: Iterable[str] = (), must_exist: bool = False) -> Path:
    """See :func:`_claim` (the folder only)."""
    return _claim(out, inputs, adopt, writes, must_exist)[0]


class _Made(NamedTuple):
    """What one :func:`_claim` call made: the topmost folder it created (None: it created none) and
    whether it wrote the marker into a folder that was there before (empty, or adopted)."""

    created: Path | None
    marked: bool


def _claim(out: str | Path, inputs: Iterable[str | Path | None] = (), adopt: bool = False,
           writes: Iterable[str] = (), must_exist: bool = False) -> tuple[Path, _Made]:
    """Make sure ``out`` is a run folder curate may write; create and mark it if new. Returns it resolved.

    ``inputs``: the photo folder, poses file or model... (None entries are ignored): none
    may lie inside ``out``, and ``out`` may not lie inside any of them (a folder; a run folder
    beside a transforms.json is accepted: nothing there is cleared but curate's own). ``adopt``: accept a
    non-empty folder without the marker (its present top-level entries stay the user's).
    ``writes``: top-level names the command writes (``report.html``, ``export``...): refused
    when they are the user's (present when the folder was adopted). ``must_exist``: a stage
    command on an existing run folder (never created here). Raises :class:`RunFolderError`.
    """
    raw = Path(out)
    o = _resolve(out)
    for inp in inputs:
        if inp is None or str(inp) == "":
            continue
        i = _resolve(inp)
        if i == o or o in i.parents:
            raise RunFolderError(f"the input {inp} is inside the run folder {raw}: curate writes and clears "
                                 "stage folders there; choose another --out")
        if i.is_dir() and i in o.parents:
            what = "poses folder" if any((i / f).is_file() for f in ("cameras.bin", "cameras.txt")) else "photo folder"
            raise RunFolderError(f"the run folder {raw} is inside the {what} {inp}: curate never writes there")
    if o.exists() and not o.is_dir():
        raise RunFolderError(f"the run folder {raw} is a file, not a folder")
    if must_exist and not o.is_dir():
        raise RunFolderError(f"{raw}: no such run folder")
    created, marked = None, False
    if o.is_dir() and not (o / MARKER).is_file():
        entries = sorted(e.name for e in o.iterdir())
        if RunPaths(o).run_json.is_file() and RunPaths(o).record("sfm").is_file():
            raise RunFolderError(f"{raw} is a run folder of curate 0.1 (no {MARKER}): this version cannot prove which "
                                 "of its files are curate's, so it does not write there; run again into a new folder")
        if must_exist:  # a stage command needs a run folder; it never makes one of the user's folder
            raise RunFolderError(f"{raw} is not a run folder (no run.json): `curate run PHOTOS --out RUN` makes one"
                                 if not RunPaths(o).run_json.is_file() else
                                 f"{raw} is not a run folder curate created (no {MARKER})")
        if entries and not adopt:
            raise RunFolderError(f"{raw} is a non-empty folder curate did not create (no {MARKER}; it holds "
                                 f"{entries[0]!r}{' and more' if len(entries) > 1 else ''}): give an empty or new "
                                 "folder, or --adopt to use it (curate never deletes its files)")
        try:
            _write_marker(o, entries if entries else None)
        except OSError as e:
            raise RunFolderError(f"cannot write the run folder {raw}: {_why(e)}") from None
        marked = True
        if entries:
            log.warning("%s: adopted (%d entries of yours kept, never written)", raw, len(entries))
    elif not o.exists():
        created = o
        while not created.parent.exists():
            created = created.parent
        try:
            o.mkdir(parents=True, exist_ok=True)
            _write_marker(o, None)
        except OSError as e:
            d = o                        # what this call created goes again (empty folders only)
            while d.is_dir() and not any(d.iterdir()):
                d.rmdir()
                if d == created:
                    break
                d = d.parent
            raise RunFolderError(f"cannot create the run folder {raw}: {_why(e)}") from None
    made = _Made(created, marked)
    if not os.access(o, os.W_OK | os.X_OK):
        raise RunFolderError(f"cannot write the run folder {raw}: read-only")
    theirs = set(read_marker(o).get("adopted") or ())
    clash = [w for w in writes if w in theirs]
    if clash:
        _undo_claim(o, made)  # adopted just now: the folder goes back to how it was
        raise RunFolderError(f"{raw}/{clash[0]} was there when {raw} was adopted: curate never writes over it; "
                             "move it, or choose another --out")
    return o, made


def _only_bookkeeping(o: Path) -> bool:
    """True when every file under the run folder ``o`` that is not the user's (adopted) is curate's
    bookkeeping: the marker, the lock, ``run.json`` of a run folder, a stage folder's marker,
    a temporary file. Nested run folders (``curate batch``) count alike."""
    theirs = set(read_marker(o).get("adopted") or ())
    for e in os.scandir(o):
        if e.name in theirs:
            continue
        for p in ([Path(e.path)] if not e.is_dir(follow_symlinks=False) else _walk(Path(e.path))):
            ok = (p.name in (MARKER, LOCK, STAGE_MARKER) or _is_tmp(p.name)
                  or p.name == "run.json" and (p.parent / MARKER).is_file())
            if not ok or p.is_symlink():
                return False
    return True


def _undo_claim(o: Path, made: _Made) -> None:
    """After a failed command: remove what :func:`_claim` made, when the run folder holds nothing but
    curate's bookkeeping (else leave it all: a record the user is told to read, resumable work).
    A folder this call created goes (with the empty parents it created); a folder that was there
    keeps its own entries and loses only the marker, the lock and the rest of curate's bookkeeping.
    Called with the lock held: the marker goes before the lock, so a second process sees a
    folder it may not use rather than one it may."""
    if made.created is None and not made.marked:
        return
    try:
        if not o.is_dir() or not _only_bookkeeping(o):
            return
        theirs = set(read_marker(o).get("adopted") or ())
        mine = [Path(e.path) for e in os.scandir(o) if e.name not in theirs]
        for p in mine:
            if p.is_dir() and not p.is_symlink():
                for f in sorted(_walk(p), key=lambda q: len(q.parts), reverse=True):
                    f.unlink()
                for sub, _, _ in sorted(os.walk(p), key=lambda t: len(Path(t[0]).parts), reverse=True):
                    os.rmdir(sub)
            elif p.name not in (MARKER, LOCK):
                p.unlink()
        (o / MARKER).unlink(missing_ok=True)
        (o / LOCK).unlink(missing_ok=True)
        if made.created is not None:
            d = o
            while True:
                d.rmdir()  # only empty folders: OSError (left as they are) when anything else is there
                if d == made.created:
                    break
                d = d.parent
    except OSError as e:  # a concurrent process, a permission: leave the rest, say so
        log.warning("%s: could not remove what this failed command created: %s", o, e)


def check_writable(path: str | Path) -> None:
    """Raise :class:`RunFolderError` when ``path``'s top-level entry in its run folder is the user's (adopted)."""
    p = _resolve(path)
    root = run_root(p.parent)
    if root is None or p == root:
        return
    top = p.relative_to(root).parts[0]
    if top in set(read_marker(root).get("adopted") or ()):
        raise RunFolderError(f"{root / top} was there when {root} was adopted: curate never writes over it")


# ------------------------------------------------------------------ processes
def proc_start_time(pid: int) -> int | None:
    """Start time of process ``pid`` (clock ticks since boot, /proc/PID/stat field 22), None when unknown or gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            stat = f.read().decode(errors="replace")
        return int(stat[stat.rindex(")") + 2:].split()[19])
    except (OSError, ValueError, IndexError):
        pass
    try:
        import psutil  # noqa: PLC0415 - optional
        return int(psutil.Process(pid).create_time() * 100)
    except Exception:  # noqa: BLE001 - no psutil, no such process
        return None


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    return True


def holder_alive(info: dict) -> bool:
    """True when the process a lock record names still runs (same host, PID alive with the same start time)."""
    pid = info.get("pid")
    if not isinstance(pid, int):
        return False
    if info.get("host") not in (None, socket.gethostname()):
        return True  # another machine: cannot tell; the flock (shared file system) decides
    if not pid_alive(pid):
        return False
    st = info.get("start_time")
    return st is None or proc_start_time(pid) in (None, st)


def _command() -> str:
    argv = sys.argv
    if argv and Path(argv[0]).name in ("curate", "__main__.py"):
        sub = next((a for a in argv[1:] if not a.startswith("-")), "")
        return f"curate {sub}".strip()
    return Path(argv[0]).name if argv and argv[0] else "python"


def die_with_parent(parent_pid: int | None = None) -> None:
    """Make this (worker) process die when its parent dies, SIGKILL included.

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (the kernel kills us when the thread that
    started us ends: start pools from a long-lived thread, e.g. the main one). Everywhere:
    a daemon thread that exits the process when ``os.getppid()`` changes (polls every 0.5 s).
    ``parent_pid``: the parent's PID when the worker was started (default: the current one);
    a parent already gone exits at once.
    """
    parent = parent_pid if parent_pid is not None else os.getppid()
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):  # pragma: no cover
            pass
    if os.getppid() != parent:
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="curate-die-with-parent", daemon=True).start()


# ------------------------------------------------------------------ lock
_held: dict[Path, list] = {}  # resolved run folder -> [fd, token, depth]
_held_mutex = threading.Lock()


def read_lock(path: str | Path) -> dict:
    """The record of ``RUN/.curate-lock`` ({} when empty or unreadable)."""
    try:
        text = (Path(path) / LOCK).read_text()
        return json.loads(text) if text.strip() else {}
    except (OSError, ValueError):
        return {}


def _describe(run: Path, info: dict) -> str:
    when = info.get("started", "?")
    when = when[11:19] if len(when) >= 19 else when
    host = f" on {info['host']}" if info.get("host") not in (None, socket.gethostname()) else ""
    return f"{run} is in use by {info.get('command', 'curate')}, PID {info.get('pid', '?')}{host}, started {when}"


def held_token(run_dir: str | Path) -> str | None:
    """The lock token when this process holds ``run_dir``'s lock, else None."""
    rec = _held.get(_resolve(run_dir))
    return rec[1] if rec else None


class RunLock:
    """``with RunLock(run_dir):`` one process works in ``run_dir`` at a time (see the module docstring).

    Raises :class:`RunFolderBusy` naming the holder; takes over a lock whose holder is gone.
    """

    def __init__(self, run_dir: str | Path, command: str | None = None):
        self.run_dir = _resolve(run_dir)
        self.command = command or _command()
        self.token: str | None = None

    def __enter__(self) -> "RunLock":
        with _held_mutex:
            rec = _held.get(self.run_dir)
            if rec is not None:
                rec[2] += 1
                self.token = rec[1]
                return self
            path = self.run_dir / LOCK
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as e:
                raise RunFolderError(f"cannot write the run folder {self.run_dir}: {e.strerror or e}") from None
            prev = read_lock(self.run_dir)
            if fcntl is not None:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except OSError:
                    os.close(fd)
                    raise RunFolderBusy(_describe(self.run_dir, read_lock(self.run_dir) or prev)) from None
                prev = read_lock(self.run_dir)
            elif prev and holder_alive(prev) and prev.get("pid") != os.getpid():  # pragma: no cover
                os.close(fd)
                raise RunFolderBusy(_describe(self.run_dir, prev))
            if prev.get("pid") is not None:
                why = "no longer running" if not holder_alive(prev) else "its lock was released"
                log.warning("%s: taking over the lock of %s, PID %s (%s)", self.run_dir, prev.get("command", "?"),
                            prev.get("pid"), why)
            self.token = uuid.uuid4().hex
            info = {"pid": os.getpid(), "start_time": proc_start_time(os.getpid()), "host": socket.gethostname(),
                    "command": self.command, "started": time.strftime("%Y-%m-%dT%H:%M:%S"), "token": self.token}
            data = json.dumps(info).encode()
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, data, 0)
                os.fsync(fd)
            except OSError as e:      # a full disk: the lock named, released
                if fcntl is not None:
                    fcntl.flock(fd, fcntl.LOCK_UN)
                os.close(fd)
                raise OSError(e.errno, e.strerror, str(path)) from None
            _held[self.run_dir] = [fd, self.token, 1]
            return self

    def __exit__(self, *exc) -> None:
        with _held_mutex:
            rec = _held.get(self.run_dir)
            if rec is None:
                return
            rec[2] -= 1
            if rec[2] > 0:
                return
            fd = rec[0]
            del _held[self.run_dir]
            try:
                os.ftruncate(fd, 0)
                if fcntl is not None:
                    fcntl.flock(fd, fcntl.LOCK_UN)
            finally:
                os.close(fd)


def release_all() -> None:
    """Release every run folder lock this process holds (the process is about to end without unwinding: a
    signal during native work, :mod:`curate.core.signals`)."""
    with _held_mutex:
        for run_dir, rec in list(_held.items()):
            del _held[run_dir]
            try:
                os.ftruncate(rec[0], 0)
                if fcntl is not None:
                    fcntl.flock(rec[0], fcntl.LOCK_UN)
                os.close(rec[0])
            except OSError:
                pass


@contextlib.contextmanager
def claimed(out: str | Path, inputs: Iterable[str | Path | None] = (), adopt: bool = False,
            writes: Iterable[str] = (), must_exist: bool = False, command: str | None = None) -> Iterator[Path]:
    """:func:`claim` then hold the :class:`RunLock` for the ``with`` block; yields the resolved folder.

    When the block fails and the folder holds nothing but curate's bookkeeping, what the claim
    made is removed (:func:`_undo_claim`): a command refused for a bad input leaves no run folder
    behind, and a folder that was there before is left as it was."""
    o, made = _claim(out, inputs, adopt=adopt, writes=writes, must_exist=must_exist)
    with RunLock(o, command):
        try:
            yield o
        except BaseException:
            _undo_claim(o, made)
            raise


def check_holder(run_dir: str | Path, token: str | None) -> None:
    """Raise :class:`StaleWorker` unless the run's lock still holds ``token`` and its holder is alive.

    ``token``: :func:`held_token` of the process that started the worker (None: no check,
    the caller works without a lock)."""
    if token is None:
        return
    info = read_lock(_resolve(run_dir))
    if info.get("token") != token or not holder_alive(info):
        raise StaleWorker(f"{run_dir}: the run that started this worker no longer holds the folder "
                          f"({'taken by PID ' + str(info.get('pid')) if info.get('token') else 'released'}): "
                          "results not written")


# ------------------------------------------------------------------ clearing
def _walk(d: Path) -> Iterator[Path]:
    """Every non-directory entry under ``d`` (links are entries: never followed). A folder curate cannot read
    is a :class:`RunFolderError` naming it."""
    try:
        entries = list(os.scandir(d))
    except PermissionError as e:
        raise RunFolderError(f"{d}: cannot read this folder ({e.strerror}): curate needs to see what it wrote "
                             "there; give it back read permission (chmod u+rwx), then run again") from None
    for e in entries:
        p = Path(e.path)
        if e.is_dir(follow_symlinks=False):
            yield from _walk(p)
        else:
            yield p


def _is_tmp(name: str) -> bool:
    base, _, tail = name.rpartition(".tmp")
    return bool(base) and tail.isdigit()


def sha256_file(p: str | Path) -> str:
    """SHA-256 of the bytes of the file ``p``."""
    import hashlib
    h = hashlib.sha256()
    with open(p, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def file_state(p: str | Path, known: dict | None = None) -> dict:
    """What a stage record keeps of one file it wrote: a symbolic link's target (``link``), else its ``size``,
    modification time (``mtime_ns``), ``inode`` and ``sha256``. ``known``: the same file's earlier state; its
    checksum is reused when size and time are unchanged (a finished unit's files are not read again)."""
    p = Path(p)
    st = os.lstat(p)
    if stat.S_ISLNK(st.st_mode):
        return {"link": os.readlink(p)}
    if (known and known.get("size") == st.st_size and known.get("mtime_ns") == st.st_mtime_ns
            and known.get("sha256")):
        digest = known["sha256"]
    else:
        digest = sha256_file(p)
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns, "inode": [st.st_dev, st.st_ino], "sha256": digest}


def is_changed(p: str | Path, was: dict | str) -> bool:
    """True when the file ``p`` (present) is no longer what curate wrote (``was``: :func:`file_state`, or a
    bare SHA-256 as an export of curate 0.3 recorded it): a link that leads elsewhere or became a file, a file
    that became a link, or other bytes. Same size and time: unchanged. The same file (inode) with more than one
    name: a hard link curate made to an original, unchanged (the original is the user's to edit). A file that
    cannot be read is taken as changed: curate cannot prove it is its own."""
    p = Path(p)
    if isinstance(was, str):
        was = {"sha256": was}
    try:
        st = os.lstat(p)
    except OSError:
        return False
    if "link" in was:
        try:
            return not stat.S_ISLNK(st.st_mode) or os.readlink(p) != was["link"]
        except OSError:
            return True
    if not stat.S_ISREG(st.st_mode):
        return True
    if "size" in was and st.st_size == was["size"] and st.st_mtime_ns == was.get("mtime_ns"):
        return False
    if was.get("inode") == [st.st_dev, st.st_ino] and st.st_nlink > 1:
        return False
    if "size" in was and st.st_size != was["size"]:
        return True
    try:
        return sha256_file(p) != was.get("sha256")
    except OSError:
        return True


class Outputs(NamedTuple):
    """How the files a stage record lists (``files``) stand now (:func:`check_outputs`)."""

    missing: list[str]
    """Listed files that are gone (relative paths)."""
    changed: list[str]
    """Listed files that are there but are no longer what curate wrote (the user's edits)."""


def check_outputs(d: str | Path, files, spare: Iterable[str] = ()) -> Outputs:
    """:class:`Outputs` of the stage folder ``d`` against its record's ``files`` (a dict of :func:`file_state`;
    a list, from an earlier curate: presence only). ``spare``: patterns of files whose absence does not count
    (a log, COLMAP's database: nothing reads them again)."""
    d = Path(d)
    missing, changed = [], []
    items = files.items() if isinstance(files, dict) else ((f, None) for f in (files or ()))
    for rel, was in items:
        p = d / rel
        if not os.path.lexists(p):
            if not any(fnmatch.fnmatch(rel, g) for g in spare):
                missing.append(rel)
        elif was is not None and is_changed(p, was):
            changed.append(rel)
    return Outputs(missing, changed)


def _read_record(d: Path) -> dict | None:
    try:
        rec = read_json(d / "stage.json")
    except (OSError, ValueError):
        return None
    return rec if isinstance(rec, dict) else None


class Sorted(NamedTuple):
    """The files under a stage folder, by whose they are (:func:`sort_files`)."""

    curates: list[Path]
    """Curate's: listed in the record and unchanged, its bookkeeping, or (no record yet) its names."""
    kept: list[Path]
    """The user's: neither listed nor among the names the stage writes. Never removed."""
    blocking: list[tuple[Path, str]]
    """(file, why) that forbid clearing: a file curate wrote and the user changed, or a file of the user's
    where the stage writes (it would be written over)."""


def sort_files(d: str | Path, owns: Iterable[str] | None = None) -> Sorted:
    """Sort every file under the stage folder ``d``.

    ``owns``: glob patterns (relative to ``d``) of the files the stage writes (None: every file of a folder
    curate created and left without a record is its scratch, as before curate 0.3). A file listed in the
    record (``files`` of ``stage.json``) is curate's unless it was changed since; in a folder that carries the
    ``.curate-stage`` marker but no record (a stage killed half-way) the files matching ``owns`` are curate's
    scratch; a nested stage folder (``evaluate/<unit>``) follows its own record. Anything else is the
    user's: kept, unless it matches ``owns`` (the stage would write over it: blocking). A folder curate did
    not create (no marker, no record) is all the user's and blocks."""
    d = Path(d)
    rec = _read_record(d)
    scratch = rec is None and (d / STAGE_MARKER).is_file()
    if owns is None:   # the names the stage said it writes, in its record or (killed half-way) its marker
        owns = (rec if rec is not None else read_stage_marker(d) if scratch else {}).get("owns")
    owns = None if owns is None else tuple(owns)
    files = (rec or {}).get("files")
    listed = set(files) if isinstance(files, (dict, list)) else set()
    ours = rec is not None or scratch
    out = Sorted([], [], [])
    nested: dict[Path, Sorted] = {}

    def matches(rel: str) -> bool:
        return owns is None or any(fnmatch.fnmatch(rel, g) for g in owns)
    for p in _walk(d):
        rel = p.relative_to(d).as_posix()
        if p.name in BOOKKEEPING and p.parent == d or _is_tmp(p.name):
            out.curates.append(p)
            continue
        sub = next((q for q in p.relative_to(d).parents if q != Path(".") and (d / q / STAGE_MARKER).is_file()), None)
        if sub is not None and rel not in listed:
            if sub not in nested:
                inner = sort_files(d / sub)
                nested[sub] = inner
                out.curates.extend(inner.curates)
                out.kept.extend(inner.kept)
                out.blocking.extend(inner.blocking)
            continue
        if rel in listed:
            was = files.get(rel) if isinstance(files, dict) else None
            if was is not None and is_changed(p, was):
                out.blocking.append((p, "changed"))
            else:
                out.curates.append(p)
        elif ours and _idle_sqlite_sidecar(p, rel, files):
            out.curates.append(p)
        elif not ours:
            out.blocking.append((p, "foreign"))
        elif scratch and matches(rel):
            out.curates.append(p)
        elif owns is not None and not matches(rel):
            out.kept.append(p)
        else:
            out.blocking.append((p, "foreign"))
    return out


def _idle_sqlite_sidecar(p: Path, rel: str, files) -> bool:
    """True for the write-ahead log (``-wal``, empty) or its index (``-shm``) of a database the stage record lists
    and that is unchanged: SQLite leaves them for whoever reads a database in WAL mode (``sqlite3 -readonly``, a
    read-only connection) and they hold nothing of the reader's. A log that holds writes is the user's change."""
    base, _, kind = rel.rpartition("-")
    if kind not in ("wal", "shm") or not isinstance(files, dict) or not isinstance(files.get(base), dict):
        return False
    db = p.with_name(p.name[:-len(kind) - 1])
    if not db.is_file() or is_changed(db, files[base]):
        return False
    log = p.with_name(db.name + "-wal")
    try:
        return not log.exists() or log.stat().st_size == 0
    except OSError:
        return False


def read_stage_marker(d: str | Path) -> dict:
    """The ``.curate-stage`` marker of the stage folder ``d``: when the stage began and ``owns``, the names it
    writes ({} for a marker of curate 0.2, which held only the time)."""
    try:
        rec = json.loads((Path(d) / STAGE_MARKER).read_text())
    except (OSError, ValueError):
        return {}
    return rec if isinstance(rec, dict) else {}


def write_stage_marker(d: str | Path, owns: Iterable[str] | None) -> None:
    """Mark ``d`` as a stage folder curate created, with the names the stage writes (:func:`sort_files`)."""
    rec = {"begun": time.strftime("%Y-%m-%dT%H:%M:%S"), "owns": None if owns is None else list(owns)}
    (Path(d) / STAGE_MARKER).write_text(json.dumps(rec) + "\n")


def changed_said(p: Path, d: Path, verb: str = "wrote") -> str:
    """The line that refuses to clear a stage folder over the user's edit of ``p``."""
    return (f"{p} was changed since curate {verb} it: curate does not remove or write over it; move it out of {d} "
            "(or keep the result as it is), then run again")


def clear_tree(d: str | Path, own: Iterable[str] | None = None) -> list[Path]:
    """Remove what curate wrote under the folder ``d`` of a claimed run folder (:func:`sort_files`); keep the
    user's files and return them (the caller says so). Nothing at all is removed, and :class:`RunFolderError`
    names the file, when ``d`` is not inside a claimed run folder, when a file curate wrote was changed since
    (the user's edit), or when a file curate did not write lies where the stage writes.
    Links are removed, never followed. Folders left empty go; ``d`` itself stays when it keeps a file."""
    d = Path(d)
    if not d.exists() and not d.is_symlink():
        return []
    root = run_root(d.parent)
    if root is None:
        raise RunFolderError(f"refusing to clear {d}: not inside a run folder curate created (no {MARKER})")
    check_writable(d)
    if d.is_symlink() or not d.is_dir():
        raise RunFolderError(f"refusing to clear {d}: not a folder curate created")
    got = sort_files(d, own)
    changed = [p for p, why in got.blocking if why == "changed"]
    if changed:
        raise RunFolderError(changed_said(changed[0], d))
    if got.blocking:
        bad = [p for p, _ in got.blocking]
        raise RunFolderError(f"refusing to clear {d}: it holds {len(bad)} file(s) curate did not write, e.g. "
                             f"{bad[0]}; move them out or choose another run folder")
    (d / "stage.json").unlink(missing_ok=True)  # the record first: a crash never leaves a stale one
    for p in sorted(got.curates, key=lambda q: len(q.parts), reverse=True):
        p.unlink(missing_ok=True)
    for sub, _, _ in sorted(os.walk(d), key=lambda t: len(Path(t[0]).parts), reverse=True):
        if Path(sub) != d or not got.kept:
            try:
                os.rmdir(sub)
            except OSError:       # a folder holding the user's files stays
                pass
    return sorted(got.kept)


def foreign_files(d: str | Path, own: Iterable[str] | None = None) -> list[Path]:
    """The files under ``d`` a re-run would not remove: the user's, and curate's that the user changed."""
    got = sort_files(d, own)
    return sorted(got.kept + [p for p, _ in got.blocking])


def manifest(d: str | Path, owns: Iterable[str] | None = None) -> dict[str, dict]:
    """{relative path (POSIX): :func:`file_state`} of every file under the stage folder ``d`` that the stage
    wrote (matching ``owns``; None: every file), for its ``stage.json``. Nested stage folders (the evaluation's
    units) are left to their own records; the previous record's checksums are reused for unchanged files."""
    d = Path(d)
    if not d.is_dir():
        return {}
    owns = None if owns is None else tuple(owns)
    prev = ((_read_record(d) or {}).get("files"))
    prev = prev if isinstance(prev, dict) else {}
    out = {}
    for p in _walk(d):
        rel = p.relative_to(d).as_posix()
        if p.name in BOOKKEEPING and p.parent == d or _is_tmp(p.name):
            continue
        if any((d / q / STAGE_MARKER).is_file() for q in p.relative_to(d).parents if q != Path(".")):
            continue
        if owns is not None and not any(fnmatch.fnmatch(rel, g) for g in owns):
            continue
        out[rel] = file_state(p, prev.get(rel))
    return dict(sorted(out.items()))
