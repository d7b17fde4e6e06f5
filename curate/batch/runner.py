"""``curate batch``: ``curate run`` on many photo folders (or videos), locally or on a Ray cluster.

One run folder per input folder, ``RUNS/<name>/`` (the same contents as ``curate run``
plus ``run.log``, the folder's stage lines and log, and ``batch.json``, its summary row
and resume key), and for the whole batch ``RUNS/summary.json``, ``RUNS/summary.html`` and
``RUNS/batch.log`` (summary rows and page: :mod:`curate.batch.summary`; the per-folder
log: :mod:`curate.batch.log`).

Poses of a folder: its ``transforms.json`` if it has one (image paths relative to it), else
a COLMAP model in ``sparse/0`` (photos in ``images/`` if that exists, else the folder),
else SfM on the folder's photos. A video file given instead of a folder is one capture, as
``curate run walk.mp4`` takes it (SfM on its candidate frames; run folder named by its stem).

Executors:

* ``local``: one spawned process per folder, ``jobs`` at a time (default: one per core,
  capped by the folders and by memory, ~3 GB a folder). Each folder's trainings run in
  that folder's process with ``max(1, cores // jobs)`` single-threaded training workers
  (unless ``--workers`` says otherwise), so folders x trainings never exceed the cores.
  A folder's process dying (killed for memory, a crash) fails that folder only.
* ``ray``: per folder, a ``prep`` task (1 CPU, and 1 GPU when the cluster has one) runs
  SfM / occupancy / selection; then a ``finish`` task (0 CPU: it only waits) runs the
  rest of the pipeline with :class:`curate.core.executors.RayExecutor`, so each evaluation
  training (selection, every random seed, FVS) is a Ray task of its own (1 CPU, 1 GPU
  when the cluster has GPUs) and a cluster trains them in parallel. ``jobs`` folders are
  in flight at once (default: the cluster's CPUs). The run folders and photos must be
  on a file system every node sees, and curate installed on every node.

Failure isolation: any exception in a folder (no usable photos, SfM failure, out of
memory, ...) marks that folder ``failed`` with its reason and the first stage without a
finished record; the others go on. Resume: a folder whose last batch row is ``ok`` with
the same key (options, poses source and the folder's file listing: names, sizes, mtimes)
and whose report is there is skipped; anything else re-runs ``pipeline.run``, which skips
its finished stages and trainings by their keys. ``force`` redoes everything.

Run-folder safety (:mod:`curate.core.runfolder`): the batch folder is claimed and locked
for the whole batch (no input folder inside it), every run folder is claimed before any
folder starts and locked by the process working in it; a folder's process and its
training workers die with the batch process, whatever kills it (``local``); with ``ray``,
Ray kills the tasks of a dead driver, and a training still running would not write its
unit (its run's lock is gone).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import threading
import time
import traceback
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Iterable

from curate.core.paths import RunPaths
from curate.batch.log import folder_log
from curate.batch.summary import make_row, write_summary_html
from curate.html.parts import fmt_num

log = logging.getLogger(__name__)



@dataclass
class Folder:
    """One input folder of a batch and where its run goes."""

    folder: str
    """The input folder (absolute)."""
    name: str
    """Its run folder's name under RUNS (unique in the batch)."""
    photos: str
    """The photo folder given to the pipeline."""
    poses: str | None
    """transforms.json or COLMAP model imported as poses; None: SfM."""
    source: str
    """'transforms.json', 'colmap' or 'sfm'."""
    run_dir: str
    """RUNS/<name> (absolute)."""


# ------------------------------------------------------------------ planning
def read_list(path: str | Path) -> list[str]:
    """Folders listed in a text file, one a line ('#' comments and blank lines skipped);
    relative paths are relative to the list file's folder."""
    path = Path(path)
    out = []
    for line in path.read_text().splitlines():
        line = line.split("#", 1)[0].strip() if not line.lstrip().startswith("#") else ""
        if line:
            p = Path(line).expanduser()
            out.append(str(p if p.is_absolute() else path.parent / p))
    return out


def find_poses(folder: Path) -> tuple[str, str | None, str]:
    """(photos, poses, source) of a folder: its pose source (:func:`curate.sfm.poses.find_pose_source`:
    its transforms.json, else its COLMAP model), else SfM on its photos."""
    from curate.sfm.poses import find_pose_source
    src = find_pose_source(folder)
    if src is None:
        return str(folder), None, "sfm"
    if src.name == "transforms.json":
        return str(folder), str(src), "transforms.json"
    if src.is_dir():
        photos = folder / "images" if (folder / "images").is_dir() else folder
        model = src / "sparse" / "0" if (src / "sparse" / "0").is_dir() else src
        return str(photos), str(model), "colmap"
    return str(folder), None, "sfm"   # a cameras.json alone names no photos: SfM


def _safe_name(s: str) -> str:
    s = re.sub(r"[^A-Za-z0-9._-]+", "_", s).strip("._")
    return s or "folder"


GENERIC_NAMES = {"images", "image", "imgs", "img", "photos", "pictures", "frames", "input", "rgb", "color", "dcim",
                 "100apple", "100media", "raw", "jpg", "jpeg"}
"""Folder names that say nothing of the capture: a batch names such a folder by its parent (``scene1/images`` is
``scene1``)."""


def _display_base(p: Path) -> str:
    """The name a person recognises a capture by: a video's stem; a folder's name, or its parent's when the folder's
    name is generic (:data:`GENERIC_NAMES`)."""
    if _is_video(p):
        return _safe_name(p.stem)
    if p.name.lower() in GENERIC_NAMES and p.parent.name:
        return _safe_name(p.parent.name)
    return _safe_name(p.name)


def _is_video(p: Path) -> bool:
    from curate.sfm.config import VIDEO_EXTS
    return p.is_file() and p.suffix.lower() in VIDEO_EXTS


def plan(folders: Iterable[str | Path], out: str | Path) -> list[Folder]:
    """One :class:`Folder` per distinct input folder (or video file: one capture, as ``curate run
    walk.mp4`` takes it), in order; names are what a person recognises (:func:`_display_base`: a video's stem, a
    folder's name or, for ``images``-like names, its parent's), then parent-name where two clash, then a short
    hash of the full path."""
    out = Path(out).resolve()
    seen, paths = set(), []
    for f in folders:
        p = Path(f).expanduser().resolve()
        if p not in seen:
            seen.add(p)
            paths.append(p)
    base = [_display_base(p) for p in paths]
    longer = [_safe_name(f"{p.parent.name}-{p.stem if _is_video(p) else p.name}") for p in paths]
    items = []
    for p, b, lb in zip(paths, base, longer):
        reserved = ("summary.json", "summary.html", "batch.log")
        if base.count(b) == 1 and b not in reserved:
            name = b
        elif longer.count(lb) == 1 and lb not in reserved:       # scene1-images, scene2-images
            name = lb
        else:
            name = f"{b}-{hashlib.sha1(str(p).encode()).hexdigest()[:6]}"
        photos, poses, source = (str(p), None, "sfm") if _is_video(p) else find_poses(p)
        items.append(Folder(str(p), name, photos, poses, source, str(out / name)))
    return items


def folder_key(item: Folder, cfg) -> str:
    """Resume key of a folder: options (less the worker count), poses source, file listing."""
    from curate.core.stage import stage_key
    h = hashlib.sha256()
    root = Path(item.folder)
    if _is_video(root):
        st = root.stat()
        h.update(f"{root.name}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    elif root.is_dir():
        for p in sorted(root.rglob("*")):
            try:
                st = p.stat()
            except OSError:
                continue
            if p.is_file():
                h.update(f"{p.relative_to(root)}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    cfg = replace(cfg, evaluate=replace(cfg.evaluate, workers=0))
    return stage_key({"cfg": cfg, "photos": item.photos, "poses": item.poses}, [h.hexdigest()])


def default_jobs(n_folders: int) -> int:
    """Folders at once on this machine: one per core, capped by the folders and by memory (~3 GB each)."""
    from curate.core.executors import available_memory, cpu_count
    return int(max(1, min(n_folders, cpu_count(), available_memory() // (3 << 30))))


# ------------------------------------------------------------------ one folder
def _reason(e: BaseException) -> str:
    text = str(e).strip().splitlines()[0] if str(e).strip() else ""
    if isinstance(e, MemoryError):
        text = text or "out of memory"
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def _prep(cfg, item: Folder, run_dir: Path, force: bool) -> None:
    """SfM (or pose import), occupancy and selection: the part of ``pipeline.run`` before the evaluation."""
    from curate.evaluate.units import clear_evaluation
    from curate.pipeline import run
    run(cfg, item.photos, run_dir, poses=item.poses, force=force, until="select")  # claims and locks the folder
    if force:
        clear_evaluation(run_dir)


def run_folder(item: Folder, cfg, force: bool = False, executor=None, phase: str = "all",
               fd_level: bool = False, key: str | None = None) -> dict:
    """Run one folder, never raising; returns its summary row (also ``RUN/batch.json`` unless
    ``phase`` is 'prep' and it went well).

    ``phase``: 'all' (``pipeline.run``), 'prep' (up to the selection) or 'finish' (the
    whole pipeline again: the prepared stages are skipped by their keys).
    """
    from curate.pipeline import run
    from curate.core.stage import write_json_atomic
    run_dir = Path(item.run_dir)
    t0 = time.perf_counter()
    status, reason = "ok", ""
    with folder_log(run_dir, fd_level) as f:
        print(f"folder {item.folder} ({item.source}) -> {run_dir} [{phase}]", flush=True)
        try:
            if not (Path(item.folder).is_dir() or _is_video(Path(item.folder))):
                raise FileNotFoundError(f"no such folder: {item.folder}" if not Path(item.folder).exists() else
                                        f"{item.folder} is neither a folder nor a video")
            if run_dir.resolve().is_relative_to(Path(item.photos).resolve()):
                raise ValueError(f"the run folder {run_dir} is inside the photo folder {item.photos}")
            if phase == "prep":
                _prep(cfg, item, run_dir, force)
            else:
                run(cfg, item.photos, run_dir, poses=item.poses, force=force, executor=executor)
        except Exception as e:  # noqa: BLE001 - any failure fails this folder only
            status, reason = "failed", _reason(e)
            f.write(traceback.format_exc())
        print(f"{'folder':10s} {status}{': ' + reason if reason else ''}  [{time.perf_counter() - t0:.1f}s]",
              flush=True)
    row = make_row(item, status, reason, time.perf_counter() - t0, cfg)
    if phase != "prep" or status != "ok":
        write_json_atomic(run_dir / "batch.json", {**row, "key": key})
    return row


def _local_child(item: Folder, cfg, force: bool, key: str, parent: int | None = None) -> None:
    """Entry point of a folder's own process (``local`` executor); it dies with the batch process ``parent``."""
    from curate.core.runfolder import die_with_parent
    die_with_parent(parent)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    run_folder(item, cfg, force, fd_level=True, key=key)


def _ray_task(item: Folder, cfg, force: bool, phase: str, gpus: float, key: str) -> dict:
    """A folder's Ray task: 'prep' (SfM, occupancy, select) or 'finish' (trainings as Ray tasks, export, report)."""
    from curate.core.executors import RayExecutor
    ex = RayExecutor(num_cpus=1, num_gpus=gpus) if phase == "finish" else None
    return run_folder(item, cfg, force, executor=ex, phase=phase, key=key)


def stage_in_progress(run_dir: str | Path, cfg) -> str:
    """The stage a folder's run (with options ``cfg``) is at: 'starting' before its run folder holds its options,
    then the first stage without a finished record (:func:`curate.core.graph.first_unfinished`, which a failed
    folder's row names)."""
    from curate.core.graph import first_unfinished
    d = Path(run_dir)
    return first_unfinished(cfg, d) if RunPaths(d).run_json.is_file() else "starting"


# ------------------------------------------------------------------ executors
def _run_local(items: list[Folder], cfg, force: bool, jobs: int, keys: dict, event: Callable) -> None:
    import multiprocessing as mp
    from multiprocessing.connection import wait
    ctx = mp.get_context("spawn")
    pending = list(items)
    running: dict = {}
    try:
        while pending or running:
            while pending and len(running) < jobs:
                it = pending.pop(0)
                (Path(it.run_dir) / "batch.json").unlink(missing_ok=True)
                p = ctx.Process(target=_local_child, args=(it, cfg, force, keys[it.name], os.getpid()),
                                name=f"curate-{it.name}")
                p.start()
                running[p.sentinel] = (it, p, time.perf_counter())
                event("start", it, None)
            ready = wait(list(running), timeout=5.0)
            if not ready:
                event("tick", None, None)      # the folders' stages, for the progress line
            for s in ready:
                it, p, t0 = running.pop(s)
                p.join()
                row = _read_row(it)
                if row is None:  # the process died without writing its row
                    code = p.exitcode
                    why = (f"killed by signal {-code}" + (" (out of memory?)" if code == -9 else "")
                           if code is not None and code < 0 else f"exit status {code}")
                    row = make_row(it, "failed", f"the folder's process died: {why}", time.perf_counter() - t0, cfg)
                    _write_row(it, row, keys[it.name])
                event("done", it, row)
    finally:
        for it, p, _ in running.values():
            p.terminate()
            p.join()


@contextmanager
def ticking(event: Callable, period: float = 5.0):
    """``event("tick", None, None)`` every ``period`` seconds from a thread of its own while the block runs
    (the progress line's stages, while the folders' Ray tasks block their threads); none after it."""
    stop = threading.Event()

    def tick() -> None:
        while not stop.wait(period):
            event("tick", None, None)
    t = threading.Thread(target=tick, name="curate-batch-tick", daemon=True)
    t.start()
    try:
        yield
    finally:
        stop.set()
        t.join()


def _run_ray(items: list[Folder], cfg, force: bool, jobs: int, keys: dict, event: Callable,
             address: str | None, num_cpus: int | None) -> None:
    from concurrent.futures import ThreadPoolExecutor
    from curate.core.executors import cluster_gpus, ray_init
    ray = ray_init(address, num_cpus, env={"OMP_NUM_THREADS": "1"})
    try:
        gpus = 1.0 if cluster_gpus() >= 1 else 0.0
        prep = ray.remote(_ray_task).options(num_cpus=1, num_gpus=gpus, max_retries=0)
        finish = ray.remote(_ray_task).options(num_cpus=0, num_gpus=0, max_retries=0)
        if jobs <= 0:
            jobs = max(1, int(ray.cluster_resources().get("CPU", 1)))

        def one(it: Folder) -> None:
            event("start", it, None)
            t0 = time.perf_counter()
            (Path(it.run_dir) / "batch.json").unlink(missing_ok=True)
            try:
                row = ray.get(prep.remote(it, cfg, force, "prep", gpus, keys[it.name]))
                if row["status"] == "ok":
                    w = row["wall_seconds"] or 0.0
                    row = ray.get(finish.remote(it, cfg, False, "finish", gpus, keys[it.name]))
                    row["wall_seconds"] = round((row["wall_seconds"] or 0.0) + w, 2)
                    _write_row(it, row, keys[it.name])
            except Exception as e:  # noqa: BLE001 - a worker died (memory), the cluster lost a node, ...
                row = make_row(it, "failed", f"Ray task failed: {_reason(e)}", time.perf_counter() - t0, cfg)
                _write_row(it, row, keys[it.name])
            event("done", it, row)

        with ticking(event), ThreadPoolExecutor(min(jobs, len(items)) or 1) as ex:
            list(ex.map(one, items))
    finally:
        ray.shutdown()


def _read_row(it: Folder) -> dict | None:
    p = Path(it.run_dir) / "batch.json"
    try:
        return json.loads(p.read_text()) if p.is_file() else None
    except ValueError:
        return None


def _write_row(it: Folder, row: dict, key: str) -> None:
    from curate.core.stage import write_json_atomic
    Path(it.run_dir).mkdir(parents=True, exist_ok=True)
    write_json_atomic(Path(it.run_dir) / "batch.json", {**row, "key": key})


# ------------------------------------------------------------------ the batch
def run_batch(folders: Iterable[str | Path], out: str | Path, cfg, executor: str = "local", jobs: int = 0,
              ray_address: str | None = None, ray_cpus: int | None = None, force: bool = False,
              progress: bool = True, adopt: bool = False) -> dict:
    """Curate every folder into ``out/<name>``; write and return ``out/summary.json``'s content.

    ``cfg``: the :class:`curate.pipeline.RunConfig` of every folder. ``executor``: 'local'
    or 'ray'. ``jobs``: folders at once (0: see :func:`default_jobs`, or the Ray cluster's
    CPUs). ``ray_address``: 'auto' or 'HOST:PORT' of a running cluster (None: a local
    instance with ``ray_cpus`` CPUs, default this machine's cores). ``adopt``: accept a
    non-empty batch folder (and run folders) curate did not create; their files are never touched.
    """
    from curate.core.runfolder import claimed
    folders = list(folders)
    with claimed(out, folders, adopt=adopt, writes=("summary.json", "summary.html", "batch.log")):
        return _run_batch(folders, out, cfg, executor, jobs, ray_address, ray_cpus, force, progress, adopt)


def _run_batch(folders: list, out, cfg, executor: str, jobs: int, ray_address, ray_cpus, force: bool,
               progress: bool, adopt: bool) -> dict:
    from tqdm import tqdm
    from curate.core.executors import cpu_count, require_ray
    if executor not in ("local", "ray"):
        raise ValueError(f"unknown executor {executor!r} (local or ray)")
    if executor == "ray":
        require_ray()  # a clear error before anything runs
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    items = plan(folders, out)
    if not items:
        raise ValueError("no folders given")
    from curate.core.runfolder import claim
    for it in items:  # every run folder is claimed before any folder starts
        claim(it.run_dir, [it.photos, it.poses, it.folder], adopt=adopt)
    t_start = time.perf_counter()
    keys = {it.name: folder_key(it, cfg) for it in items}
    rows: dict[str, dict] = {it.name: make_row(it, "pending") for it in items}
    todo = []
    for it in items:
        prev = _read_row(it)
        if (not force and prev and prev.get("status") == "ok" and prev.get("key") == keys[it.name]
                and RunPaths(it.run_dir).report_json.is_file()):
            prev.pop("key", None)
            rows[it.name] = {**prev, "resumed": True}
        else:
            todo.append(it)
    if executor == "local" and jobs <= 0:
        jobs = default_jobs(len(todo))
    run_cfg = cfg
    if executor == "local" and cfg.evaluate.workers <= 0:
        run_cfg = replace(cfg, evaluate=replace(cfg.evaluate, workers=max(1, cpu_count() // max(jobs, 1))))
    lock = threading.Lock()
    blog = open(out / "batch.log", "a", buffering=1, encoding="utf-8")
    blog.write(f"==== curate batch {time.strftime('%Y-%m-%d %H:%M:%S')}: {len(items)} folders, {len(todo)} to run, "
               f"executor {executor}, jobs {jobs or 'auto'} ====\n")
    for it in items:
        if rows[it.name]["resumed"]:
            blog.write(f"{time.strftime('%H:%M:%S')} {it.name}: finished before, skipped\n")
    counts = {"ok": sum(r["resumed"] and r["status"] == "ok" for r in rows.values()), "failed": 0, "running": 0}
    bar = tqdm(total=len(items), initial=counts["ok"], desc="folders", unit="folder", disable=not progress,
               dynamic_ncols=True)

    def postfix():
        now = [f"{it.name}: {stage_in_progress(it.run_dir, run_cfg)}" for it in items
               if rows[it.name].get("status") == "running"]
        bar.set_postfix_str(f"ok {counts['ok']}, failed {counts['failed']}"
                            + (f"; {', '.join(now)}" if now else f", running {counts['running']}"))

    def write_summary():
        summ = {"out": str(out), "executor": executor, "jobs": jobs, "n_folders": len(items),
                "n_ok": sum(r["status"] == "ok" for r in rows.values()),
                "n_failed": sum(r["status"] == "failed" for r in rows.values()),
                "wall_seconds": round(time.perf_counter() - t_start, 2), "config": _config(cfg),
                "rows": [rows[it.name] for it in items]}
        from curate.core.stage import write_json_atomic
        write_json_atomic(out / "summary.json", summ)
        write_summary_html(out, summ)
        return summ

    def event(kind: str, it: Folder | None, row: dict | None) -> None:
        with lock:
            stamp = time.strftime("%H:%M:%S")
            if kind == "tick":
                postfix()
                return
            if kind == "start":
                counts["running"] += 1
                rows[it.name] = {**rows[it.name], "status": "running"}
                blog.write(f"{stamp} {it.name}: start ({it.source}; log {it.run_dir}/run.log)\n")
            else:
                counts["running"] -= 1
                counts[row["status"] if row["status"] in ("ok", "failed") else "failed"] += 1
                row = {k: v for k, v in row.items() if k != "key"}
                rows[it.name] = row
                if row["status"] == "ok":
                    p = row["psnr"]
                    said = (f"PSNR selection {fmt_num(p['selection'])} / random {fmt_num(p['random'])} / fvs "
                            f"{fmt_num(p['fvs'])} / all {fmt_num(p['all'])}"
                            if any(v is not None for v in p.values()) else "not evaluated")
                    msg = (f"{it.name}: ok, {row['chosen']} of {row['registered']} chosen, "
                           f"{said} ({row['wall_seconds']:.0f}s)")
                else:
                    msg = f"{it.name}: FAILED in {row.get('failed_stage')}: {row['reason']}"
                blog.write(f"{stamp} {msg}\n")
                bar.write(msg) if progress else None
                bar.update(1)
                write_summary()
            postfix()

    postfix()
    write_summary()
    try:
        if todo:
            if executor == "local":
                _run_local(todo, run_cfg, force, jobs, keys, event)
            else:
                _run_ray(todo, run_cfg, force, jobs, keys, event, ray_address, ray_cpus)
    finally:
        bar.close()
        summ = write_summary()
        blog.write(f"==== done: {summ['n_ok']} ok, {summ['n_failed']} failed, {summ['wall_seconds']:.0f}s ====\n")
        blog.close()
    return summ


def _config(cfg) -> dict:
    from curate.core.stage import config_dict
    return config_dict(cfg)
