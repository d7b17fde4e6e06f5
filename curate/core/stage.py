"""Run-folder stages: each stage writes ``RUN/<stage>/stage.json`` when it finishes.

``stage.json`` holds the stage's *key* (a hash of its resolved config and of the
content of its inputs), the resolved config itself, versions, the seed when there is
one, the stage's outputs and its wall time. A stage whose ``stage.json`` exists with
the same key is skipped; a stage killed half-way leaves no ``stage.json`` and is
redone. Writes go to a temporary file and are renamed, so a record is whole or absent.

``stage.json`` also lists (``files``) every file the stage wrote in its folder, each with its size, time and
checksum (a link: its target). **Up to date means the files are there**: a stage is skipped only when its key is
unchanged *and* those files are there (:func:`up_to_date`); a missing one makes the stage run again, and a file
the user changed is kept and named. A re-run clears what the record lists and nothing else
(:func:`curate.core.runfolder.clear_tree`), only in a run folder curate claimed, and says which files of the
user's it kept; it refuses, naming the file, to remove or write over a file of curate's that the user changed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import logging
import os
import platform
import time
from pathlib import Path
from typing import Any, Iterable, NamedTuple

from curate.core.paths import RunPaths
from curate.core.graph import BY_NAME, NAMES, READS

STAGE_FILE = "stage.json"

log = logging.getLogger(__name__)


@dataclasses.dataclass
class StageResult:
    """What one stage call did: every stage function returns one."""

    name: str
    """The stage's name (one of :data:`STAGES`)."""
    path: Path
    """The folder (or, for ``report``, the file) the stage writes."""
    ran: bool
    """True when the stage ran now; False when it was skipped because its key was unchanged."""
    seconds: float
    """Seconds of this call (a skip takes milliseconds)."""
    summary: str = ""
    """One line for the terminal: what the stage produced."""
    warning: str | None = None
    """Something the user must know about the result (repeated at the end of ``curate run``)."""

    def line(self) -> str:
        return f"{self.name:10s} {self.summary if self.ran else 'skipped (unchanged)'}  [{self.seconds:.1f}s]"

    def timing(self) -> dict:
        return {"name": self.name, "seconds": round(self.seconds, 2), "skipped": not self.ran}


def config_dict(cfg: Any) -> dict:
    """A dataclass config (possibly nested) as a JSON-ready dict."""
    if dataclasses.is_dataclass(cfg):
        return {f.name: config_dict(getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
    if isinstance(cfg, (list, tuple)):
        return [config_dict(v) for v in cfg]  # type: ignore[return-value]
    if isinstance(cfg, Path):
        return str(cfg)  # type: ignore[return-value]
    return cfg


def _record(cfg: Any) -> Any:
    """:func:`config_dict`, also inside plain dicts (a stage's config may be ``{"select":
    SelectConfig, ...}``). Not used for keys: :func:`stage_key` keeps its hashing unchanged."""
    if isinstance(cfg, dict):
        return {k: _record(v) for k, v in cfg.items()}
    if isinstance(cfg, (list, tuple)) and not dataclasses.is_dataclass(cfg):
        return [_record(v) for v in cfg]
    return config_dict(cfg)


def hash_files(paths: Iterable[str | Path], h: "hashlib._Hash | None" = None) -> str:
    """SHA-256 over the names, sizes and content of ``paths`` (in the given order)."""
    h = h or hashlib.sha256()
    for p in paths:
        p = Path(p)
        h.update(os.fsencode(p.name))
        if p.is_file():
            h.update(str(p.stat().st_size).encode())
            with open(p, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
        else:
            h.update(b"<missing>")
    return h.hexdigest()


def stage_key(cfg: Any, input_hashes: Iterable[str] = ()) -> str:
    """Key of a stage run: its resolved config plus the hashes of its inputs."""
    h = hashlib.sha256(json.dumps(config_dict(cfg), sort_keys=True, default=str).encode())
    for x in input_hashes:
        h.update(x.encode())
    return h.hexdigest()[:16]


def versions() -> dict:
    """Versions of Python, curate and the main dependencies that are already imported or importable cheaply."""
    from curate import __version__
    out = {"python": platform.python_version(), "curate": __version__}
    from importlib import metadata
    for name in ("numpy", "torch", "pycolmap", "open3d", "rawpy", "scikit-image"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


def read_stage(stage_dir: str | Path) -> dict | None:
    p = Path(stage_dir) / STAGE_FILE
    if not p.is_file():
        return None
    try:
        rec = json.loads(p.read_text())
    except (OSError, ValueError):          # unreadable, not JSON, not UTF-8: not a finished stage
        return None
    return rec if isinstance(rec, dict) else None


class Freshness(NamedTuple):
    """Whether a finished stage can be skipped (:func:`up_to_date`)."""

    fresh: bool
    """Same key and every file of its record there: skip it."""
    missing: list[str]
    """Files its record lists that are gone (then it runs again)."""
    changed: list[str]
    """Files its record lists that the user changed (kept: never removed or written over)."""


def up_to_date(stage_dir: str | Path, key: str, spare: Iterable[str] = ()) -> Freshness:
    """Is the stage in ``stage_dir`` finished with ``key`` and are its outputs there? A record whose files are
    missing (``spare`` apart: :attr:`curate.core.graph.Stage.spare`) is not up to date: the stage runs again.
    A file the user changed does not make it out of date (their edit is kept); it is named in ``changed``."""
    from curate.core.runfolder import check_outputs
    rec = read_stage(stage_dir)
    if rec is None or rec.get("key") != key:
        return Freshness(False, [], [])
    out = check_outputs(stage_dir, rec.get("files"), spare)
    return Freshness(not out.missing, out.missing, out.changed)


def is_fresh(stage_dir: str | Path, key: str, spare: Iterable[str] = ()) -> bool:
    """True when the stage finished earlier with the same key and the files it wrote are there."""
    return up_to_date(stage_dir, key, spare).fresh


def _names(files: list[str], n: int = 3) -> str:
    return ", ".join(files[:n]) + (f" and {len(files) - n} more" if len(files) > n else "")


def begin_stage(stage_dir: str | Path, key: str, force: bool = False, owns: Iterable[str] | None = None,
                spare: Iterable[str] = ()) -> bool:
    """True when the stage finished earlier with the same ``key`` and its files are there (and ``force`` is
    off): skip it (a file the user changed since is named in a warning and kept).

    Otherwise (a file of its record missing, another key, ``force``) the stage's folder is cleared of what
    curate wrote there (its record first, so a crash in between never leaves a stale one), the user's own files
    are kept (named in a warning), the folder is (re)created with the ``.curate-stage`` marker, which records
    ``owns`` (:attr:`curate.core.graph.Stage.owns`: the names the stage writes), and False is returned: run the
    stage, then :func:`finish_stage` with the same ``owns``. Only a folder of a claimed run folder is cleared
    (:func:`curate.core.runfolder.clear_tree`); a file of curate's the user changed, or a file of the user's
    where the stage writes, is a :class:`curate.core.runfolder.RunFolderError` naming it, and nothing is removed.
    """
    from curate.core.runfolder import check_writable, clear_tree, write_stage_marker
    stage_dir = Path(stage_dir)
    if not force:
        now = up_to_date(stage_dir, key, spare)
        if now.fresh:
            if now.changed:
                log.warning("%s: %s changed since curate wrote %s: kept as you left %s (the rest is up to date)",
                            stage_dir, _names(now.changed), "them" if len(now.changed) > 1 else "it",
                            "them" if len(now.changed) > 1 else "it")
            return True
        if now.missing:
            log.warning("%s: %s missing: the stage is done again", stage_dir,
                        _names(now.missing) + (" are" if len(now.missing) > 1 else " is"))
    check_writable(stage_dir)
    kept = clear_tree(stage_dir, owns)
    if kept:
        log.warning("%s: kept %d file(s) of yours there (%s): curate removes only what it wrote", stage_dir,
                    len(kept), _names([p.relative_to(stage_dir).as_posix() for p in kept]))
    stage_dir.mkdir(parents=True, exist_ok=True)
    write_stage_marker(stage_dir, owns)
    return False


def finished_record(run_dir: str | Path, stage: str) -> dict | None:
    """``stage``'s record in ``run_dir`` (None: not finished). An evaluation made by an earlier curate recorded
    only its ``summary.json`` (with the same ``key`` and ``inputs``): that stands for its record."""
    rec = read_stage(Path(run_dir) / stage)
    if rec is None and stage == "evaluate":
        try:
            rec = json.loads(RunPaths(run_dir).summary.read_text())
        except (OSError, ValueError):
            return None
    return rec if isinstance(rec, dict) else None


def current_key(run_dir: str | Path, stage: str) -> str | None:
    """The key of ``stage``'s finished result in ``run_dir`` (None: not finished)."""
    return (finished_record(run_dir, stage) or {}).get("key")


def required_key(run_dir: str | Path, stage: str) -> str:
    """:func:`current_key` of a stage another stage is computed from: FileNotFoundError, naming the command that
    finishes the run, when it has not finished."""
    key = current_key(run_dir, stage)
    if key is None:
        raise FileNotFoundError(f"{Path(run_dir) / stage}: this stage has not finished (run `curate run ... --out "
                                "RUN` to finish the run)")
    return key


def inputs_of(run_dir: str | Path, stage: str) -> dict[str, str | None]:
    """{input stage: its current key} for ``stage`` (:data:`READS`): what a record names as its inputs."""
    return {s: current_key(run_dir, s) for s in READS.get(stage, ())}


def stale_stages(run_dir: str | Path) -> dict[str, str]:
    """{stage: why} for every finished stage of ``run_dir`` computed from inputs that have changed
    since (a stage it reads was redone, or is itself stale), in the graph's order. A record
    without ``inputs`` (an earlier curate) counts as stale: nothing says what it was computed from."""
    out: dict[str, str] = {}
    for stage in NAMES:
        if stage not in READS or (rec := finished_record(run_dir, stage)) is None:
            continue
        recorded = rec.get("inputs")
        if not isinstance(recorded, dict):
            out[stage] = "made by an earlier curate: its inputs are not recorded"
            continue
        for s in READS[stage]:
            if s in out:
                out[stage] = f"it reads {s}, which is out of date"
                break
            if recorded.get(s) != current_key(run_dir, s):
                out[stage] = f"{s} was redone since"
                break
    return out


def stale_root(stale: dict[str, str], stage: str) -> str:
    """The stage to redo first so that ``stage`` of a run folder is current again, given ``stale``
    (:func:`stale_stages`): the first out-of-date stage it reads, directly or not, else itself. A
    record made by an earlier curate makes what reads it stale; only redoing its stage mends that."""
    while (up := next((r for r in READS.get(stage, ()) if r in stale), None)) is not None:
        stage = up
    return stage


def refresh_command(run_dir: str | Path, stale: dict[str, str], stage: str) -> str:
    """The command that makes ``stage`` of ``run_dir`` current again: the stage command of
    :func:`stale_root` (a stage command redoes the cheap stages computed from it), then, for a stage that
    trains (the evaluation), which no other stage command redoes, its own command."""
    root = stale_root(stale, stage)
    return " && ".join([f"curate {root} {run_dir}"]
                       + ([f"curate {stage} {run_dir}"] if stage != root and not BY_NAME[stage].cheap else []))


@contextlib.contextmanager
def writing(path: str | Path):
    """``with writing(path):`` an ``OSError`` raised inside without a file name (numpy's, PIL's, a write through a
    file object: a full disk says only "[Errno 28] No space left on device") is raised again naming ``path``, so
    the one line the command prints says which file could not be written."""
    try:
        yield
    except OSError as e:
        if e.filename is None and e.errno is not None:
            raise OSError(e.errno, e.strerror or str(e), str(path)) from None
        raise


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file and a rename: a reader
    never sees half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    try:
        tmp.write_text(text, encoding="utf-8")
    except OSError as e:          # a full disk: the file named, the half-written temporary removed
        tmp.unlink(missing_ok=True)
        raise OSError(e.errno, e.strerror, str(path)) from None
    os.replace(tmp, path)
    return path


def write_json_atomic(path: str | Path, obj: Any) -> Path:
    return write_text_atomic(path, json.dumps(obj, indent=1, default=str))


def finish_stage(stage_dir: str | Path, key: str, cfg: Any, started: float, outputs: dict | None = None,
                 seed: int | None = None, owns: Iterable[str] | None = None, **extra: Any) -> dict:
    """Write the stage record; call last, once every output file is in place. ``owns``: the names the stage
    writes (:attr:`curate.core.graph.Stage.owns`), as given to :func:`begin_stage`: the record lists the files
    that match them (None: every file in the folder), each with its size, time and checksum."""
    stage_dir = Path(stage_dir)
    rec = {"key": key, "inputs": inputs_of(stage_dir.parent, stage_dir.name) if stage_dir.name in READS else {},
           "config": _record(cfg), "versions": versions(), "seed": seed,
           "seconds": round(time.perf_counter() - started, 3), "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S"),
           "outputs": outputs or {}, **extra}
    from curate.core.runfolder import manifest
    rec["files"] = manifest(stage_dir, owns)  # what curate wrote here: the only files a re-run may clear
    rec["owns"] = None if owns is None else list(owns)
    write_json_atomic(Path(stage_dir) / STAGE_FILE, rec)
    return rec


def config_from_dict(cls: type, d: dict) -> Any:
    """Inverse of :func:`config_dict` for a dataclass ``cls`` whose fields all have defaults.

    Nested dataclasses are rebuilt, lists become tuples where the default is a tuple,
    and unknown keys raise ``ValueError`` (a record from another version is not guessed at).
    """
    base = cls()
    kw = {}
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    for k, v in d.items():
        if k not in names:
            raise ValueError(f"{cls.__name__} has no option {k!r}")
        cur = getattr(base, k)
        if dataclasses.is_dataclass(cur) and isinstance(v, dict):
            v = config_from_dict(type(cur), v)
        elif isinstance(cur, tuple) and isinstance(v, list):
            v = tuple(v)
        kw[k] = v
    return cls(**kw)
