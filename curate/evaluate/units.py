"""The evaluation's trainings: the same radiance field trained on each subset, scored on held-out views.

Each *unit* trains the same field (same :class:`curate.field.config.FieldConfig`, same iterations, same
scene box, same training seed) on one subset of the registered photos and renders the held-out views of its
fold (:mod:`curate.evaluate.folds` says which units a fold has; :mod:`curate.evaluate.schedule` runs them).

Training length is a number of iterations, not seconds, so results do not depend on
how loaded the machine is (``EvalConfig.time_budget_s`` adds an optional cap).

Each unit is a stage of its own, ``RUN/evaluate/<key>/``:

* ``stage.json``: the stage record (written last: a unit killed half-way is redone);
* ``metrics.json``: ``{"method", "seed", "subset": [camera indices], "n_train", "psnr",
  "ssim", "per_view": [{"name", "psnr", "ssim"}], "train_seconds", "iters", "cpu_seconds"}`` (``cpu_seconds``:
  the worker's CPU time over loading, training and scoring: what the training costs whatever else runs);
* ``renders/<stem>.png``: the rendered held-out views (``stem`` of the camera name);
* ``field.pt``: the trained field.

``RUN/evaluate/gt/<stem>.png`` holds the held-out ground truth at evaluation size.
Units run in a process pool (one single-threaded training per CPU core on a CPU
machine, one at a time on CUDA). The pool's workers die with the process that started
them, and a training writes its results only while that process still holds the run's
lock (:func:`curate.core.runfolder.check_holder`): a stale worker never writes a unit.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from curate.core.graph import BY_NAME, UNIT_OWNS
from curate.core.paths import RunPaths
from curate.core.cameras import Cameras
from curate.core.executors import available_memory, cpu_count
from curate.evaluate.config import EvalConfig  # noqa: F401  (re-exported: research imports it from here)

log = logging.getLogger(__name__)


@dataclass
class Unit:
    """One training: a subset of the registered cameras, scored on the held-out ones."""

    key: str
    """Its folder under RUN/evaluate: ``f<offset>_<method>`` for a fold's units (``f03_selection``,
    ``f03_random_s0``; :mod:`curate.evaluate.folds`), any name for research's."""
    method: str
    """'selection', 'random', 'fvs', 'stride', 'all' or 'check' (the budget check's other budgets)."""
    seed: int | None
    """The random draw's seed (random subsets only)."""
    subset: list[int]
    """Indices into the registered cameras."""
    fold: int = 0
    """The hold-out fold's offset."""


def resolved(cfg: EvalConfig) -> EvalConfig:
    """``cfg`` as its trainings run it, the device chosen once (here, not in each worker): the field on CUDA when
    torch sees a GPU, else the CPU (``FieldConfig.device`` 'auto'); ``--trainer gsplat`` checked (ValueError, one
    line, where it cannot run). The units' keys do not change with it (:meth:`EvalConfig.training`)."""
    from dataclasses import replace
    if cfg.trainer == "gsplat":
        from curate.field.splat import unavailable
        why = unavailable()
        if why:
            raise ValueError(why)
        return cfg
    return replace(cfg, field=replace(cfg.field, device=str(cfg.field.resolve_device())))


def eval_cameras(cams: Cameras, max_side: int) -> Cameras:
    """The cameras at evaluation size (longer side <= ``max_side``; never upscaled)."""
    return cams.at_most(max_side)


def _stem(name: str) -> str:
    return Path(name).stem


def auto_workers(cfg: EvalConfig, n_units: int, pixels: int) -> int:
    """Parallel trainings: one per core on CPU (each single-threaded), limited by memory
    (about 40 bytes of cached rays per training pixel) and by the number of units."""
    if cfg.workers > 0:
        return min(cfg.workers, max(n_units, 1))
    if cfg.trainer == "gsplat" or cfg.field.resolve_device().type == "cuda":
        return 1
    per = 40 * pixels + (1 << 30)
    return int(max(1, min(cpu_count(), n_units, available_memory() // per)))


def train_unit(run_dir: str, unit: Unit, cfg: EvalConfig, cams: Cameras, paths: Sequence[str],
               holdout: Sequence[int], box: tuple, key: str, field_path: str | None = None,
               lock_token: str | None = None) -> dict:
    """Train (or load ``field_path``) on ``unit.subset``, render and score ``holdout``; write the unit's folder.

    ``cams`` are the registered cameras at evaluation size, ``paths`` their image files.
    Returns the metrics dict (also written as ``metrics.json``). ``lock_token``: the run
    lock's token of the process that started this training (see
    :func:`curate.core.runfolder.held_token`): the unit is written only while that process
    still holds the run folder (else :class:`curate.core.runfolder.StaleWorker`).
    """
    from curate.core.runfolder import check_holder
    import torch
    from curate.field.metrics import psnr, render_image, save_png, ssim
    from curate.core.stage import begin_stage, finish_stage, write_json_atomic, write_text_atomic
    from curate.field.train import TrainStats, load_image, train_field

    d = RunPaths(run_dir).evaluate / unit.key
    check_holder(run_dir, lock_token)
    if begin_stage(d, key, owns=UNIT_OWNS):
        return json.loads((d / "metrics.json").read_text())
    t0, c0 = time.perf_counter(), time.process_time()
    if cfg.field.threads > 0:
        torch.set_num_threads(cfg.field.threads)
    sub = list(unit.subset)
    if field_path is not None:
        from curate.field.model import RadianceField
        fld = RadianceField.load(field_path, device=cfg.field.resolve_device())
        meta = json.loads((Path(field_path).parent / "train.json").read_text())
        st = TrainStats(iters=meta["iters"], train_seconds=meta["train_seconds"],
                        stop_reason=meta.get("stop_reason", ""))
        import shutil
        shutil.copy2(field_path, d / "field.pt")
    elif cfg.trainer == "gsplat":
        from curate.field.splat import render_view, train_splats
        from curate.sfm.io import load_points_rgb

        def step(it: int) -> None:
            if it % PROGRESS_EVERY == 0:
                write_text_atomic(d / PROGRESS_FILE, str(it))
        pts_file = RunPaths(run_dir).sfm / "points.npy"
        pts = np.load(pts_file) if pts_file.is_file() else None
        fld, st = train_splats(cfg.splat, cams[sub], [paths[i] for i in sub], pts, load_points_rgb(run_dir), box,
                               seed=cfg.train_seed, callback=step)
        write_text_atomic(d / PROGRESS_FILE, str(cfg.train_steps()))
    else:
        def report(it: int, _secs: float, _fld) -> None:   # the parent's bar reads it (run_units)
            if it % PROGRESS_EVERY == 0:
                write_text_atomic(d / PROGRESS_FILE, str(it))
        fld, st = train_field(cfg.field, cams[sub], [paths[i] for i in sub], d, time_budget_s=cfg.time_budget_s,
                              iters=cfg.iters, seed=cfg.train_seed, box=box, callback=report)
        write_text_atomic(d / PROGRESS_FILE, str(cfg.iters))   # trained: the bar stays full while it renders
    check_holder(run_dir, lock_token)  # after the long training: do not render into a folder taken since
    per = []
    test = cams[list(holdout)]
    with torch.no_grad():
        for k, i in enumerate(holdout):
            gt = load_image(paths[i], int(test.width[k]), int(test.height[k]))
            pred = render_view(fld, test, k) if cfg.trainer == "gsplat" else render_image(fld, test, k)
            save_png(pred, d / "renders" / f"{_stem(cams.names[i])}.png")
            per.append({"name": cams.names[i], "psnr": psnr(pred, gt), "ssim": ssim(pred, gt)})
    m = {"method": unit.method, "seed": unit.seed, "subset": sub, "n_train": len(sub),
         "psnr": float(np.mean([r["psnr"] for r in per])), "ssim": float(np.mean([r["ssim"] for r in per])),
         "per_view": per, "train_seconds": round(st.train_seconds, 2), "iters": st.iters,
         "cpu_seconds": round(time.process_time() - c0, 2)}
    check_holder(run_dir, lock_token)  # a worker whose run lost the folder writes nothing
    write_json_atomic(d / "metrics.json", m)
    (d / PROGRESS_FILE).unlink(missing_ok=True)
    finish_stage(d, key, cfg, t0, outputs={"metrics": "metrics.json", "renders": "renders/"}, seed=cfg.train_seed,
                 owns=UNIT_OWNS, method=unit.method, psnr=m["psnr"])
    log.info("evaluate %s: %d images, PSNR %.2f, SSIM %.3f (%.0fs)", unit.key, len(sub), m["psnr"], m["ssim"],
             time.perf_counter() - t0)
    return m


def read_metrics(unit_dir: Path) -> dict:
    """A finished unit's ``metrics.json``."""
    return json.loads((Path(unit_dir) / "metrics.json").read_text())


PROGRESS_FILE = ".progress"
"""``RUN/evaluate/<unit>/.progress``: the iterations a training has done (removed when it finishes)."""
PROGRESS_EVERY = 10


def _unit_progress(ev_dir: Path, units: list, iters: int, done: set) -> int:
    """Iterations done over ``units``: ``iters`` for each finished one (``done``), else what its
    progress file says."""
    n = 0
    for u in units:
        if u.key in done:
            n += iters
            continue
        try:
            n += min(int((ev_dir / u.key / PROGRESS_FILE).read_text()), iters)
        except (OSError, ValueError):
            pass
    return n


def worker_start(parent_pid: int) -> None:
    """A training worker's start: it dies with the process that started it
    (:func:`curate.core.runfolder.die_with_parent`), and its progress bars take a thread lock instead of
    tqdm's default multiprocessing one, so that a worker killed by Ctrl-C or SIGTERM leaves no semaphore
    behind (the "leaked semaphore" warning at exit)."""
    import threading
    from curate.core.runfolder import die_with_parent
    from tqdm import tqdm
    die_with_parent(parent_pid)
    tqdm.set_lock(threading.RLock())


def _unit_entry(args: tuple) -> dict:
    """Process-pool entry point (spawned workers re-import curate); ``args``: :func:`train_unit`'s, then the log
    level."""
    logging.basicConfig(level=args[-1], format="%(levelname)s %(name)s: %(message)s")
    return train_unit(*args[:-1])


def save_ground_truth(run_dir: str | Path, cams: Cameras, paths: Sequence[str], holdout: Sequence[int]) -> None:
    """``RUN/evaluate/gt/<stem>.png``: the held-out images at evaluation size."""
    from curate.field.metrics import save_png
    from curate.field.train import load_image
    evaluation_folder(run_dir)
    d = RunPaths(run_dir).gt
    for i in holdout:
        p = d / f"{_stem(cams.names[i])}.png"
        if not p.is_file():
            save_png(load_image(paths[i], int(cams.width[i]), int(cams.height[i])), p)


def run_units(run_dir: str | Path, units: list[Unit], keys: dict[str, str], cfg: EvalConfig, cams: Cameras,
              paths: Sequence[str], holdout: Sequence[int], box: tuple,
              field_paths: dict[str, str] | None = None, progress: bool = True,
              executor=None) -> dict[str, dict]:
    """Run every unit (finished ones are skipped); {unit key: metrics}.

    ``keys[unit.key]`` is the unit's stage key; ``field_paths`` maps a unit key to an
    already trained field (the occupancy stage's pool field serves 'all').
    ``executor``: any ``concurrent.futures.Executor`` (e.g. a Ray-backed one for a
    cluster) to submit the trainings to; None: a local process pool (see
    :func:`auto_workers`), or this process for one worker.
    """
    from curate.core.stage import is_fresh
    from tqdm import tqdm
    field_paths = field_paths or {}
    save_ground_truth(run_dir, cams, paths, holdout)
    todo = [u for u in units if not is_fresh(RunPaths(run_dir).evaluate / u.key, keys[u.key])]
    fresh = [u for u in units if u not in todo]
    # units with equal keys (e.g. method "auto" chose exactly the FVS subset) train once; the others copy it
    first: dict[str, Unit] = {keys[u.key]: u for u in reversed(fresh)}
    dups = []
    for u in todo:
        src = first.setdefault(keys[u.key], u) if u.key not in field_paths else u
        if src is not u:
            dups.append((u, src))
    todo = [u for u in todo if all(u is not d for d, _ in dups)]
    results: dict[str, dict] = {}
    for u in fresh:
        results[u.key] = json.loads((RunPaths(run_dir).evaluate / u.key / "metrics.json").read_text())
    pix = int(np.max([np.sum(cams.width[u.subset] * cams.height[u.subset]) for u in todo])) if todo else 0
    n_train = [u for u in todo if u.key not in field_paths]
    workers = auto_workers(cfg, len(n_train), pix)
    level = logging.getLogger("curate").getEffectiveLevel()
    from curate.core.runfolder import held_token
    token = held_token(run_dir)
    args = [(str(run_dir), u, cfg, cams, list(paths), list(holdout), box, keys[u.key], field_paths.get(u.key), token,
             level) for u in todo]
    # progress in training iterations over every unit (each training reports through its progress file)
    ev_dir = RunPaths(run_dir).evaluate
    trained = [u for u in todo if u.key not in field_paths]
    bar = tqdm(total=len(trained) * cfg.train_steps(), desc=f"evaluate: {len(trained)} trainings", unit="it",
               disable=not progress or not trained, smoothing=0.05)
    done: set = set()

    keys_trained = {u.key for u in trained}

    def show() -> None:
        bar.n = _unit_progress(ev_dir, trained, cfg.train_steps(), done)
        bar.set_postfix_str(f"{len(done & keys_trained)} of {len(trained)} done", refresh=False)
        bar.refresh()

    def collect(futs: dict) -> None:
        from concurrent.futures import FIRST_COMPLETED, wait
        pending = set(futs)
        while pending:
            finished, pending = wait(pending, timeout=1.0, return_when=FIRST_COMPLETED)
            for f in finished:
                results[futs[f]] = f.result()
                done.add(futs[f])
            show()

    if executor is not None and todo:
        collect({executor.submit(_unit_entry, a): a[1].key for a in args})
    elif workers <= 1 or len(todo) <= 1:
        import threading
        stop = threading.Event()       # one at a time, here; a thread only moves the bar

        def poll() -> None:
            while not stop.wait(1.0):
                show()
        t = threading.Thread(target=poll, daemon=True)
        t.start()
        try:
            for a in args:
                results[a[1].key] = _unit_entry(a)
                done.add(a[1].key)
        finally:
            stop.set()
            t.join()
        show()
    else:
        import os
        from curate.core.pools import end_pool, local_pool
        ex = local_pool(workers, worker_start, (os.getpid(),))
        try:
            collect({ex.submit(_unit_entry, a): a[1].key for a in args})
        except BaseException:
            end_pool(ex, kill=True)      # no training outlives the command
            raise
        end_pool(ex)
    for u, src in dups:
        results[u.key] = _copy_unit(RunPaths(run_dir).evaluate, src.key, u, results[src.key])
    bar.close()
    return {u.key: results[u.key] for u in units}


def _copy_unit(ev_dir: Path, src_key: str, unit: Unit, metrics: dict) -> dict:
    """Copy the finished unit ``src_key`` as ``unit`` (same key: same subset and settings);
    its record last, so a crash leaves no stale record."""
    import shutil
    from curate.core.runfolder import clear_tree, manifest, write_stage_marker
    from curate.core.stage import STAGE_FILE, write_json_atomic
    src, dst = ev_dir / src_key, ev_dir / unit.key
    clear_tree(dst, UNIT_OWNS)
    dst.mkdir(parents=True, exist_ok=True)
    write_stage_marker(dst, UNIT_OWNS)
    for rel in manifest(src, UNIT_OWNS):       # what the source unit wrote, not what the user left there
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src / rel, dst / rel)
    m = {**metrics, "method": unit.method, "seed": unit.seed, "copied_from": src_key}
    write_json_atomic(dst / "metrics.json", m)
    rec = json.loads((src / STAGE_FILE).read_text())
    write_json_atomic(dst / STAGE_FILE, {**rec, "files": manifest(dst, UNIT_OWNS), "copied_from": src_key})
    return m


EVAL_OWN = BY_NAME["evaluate"].owns
"""Files of ``RUN/evaluate``: the summary, the ground truth and, in each unit's folder, what a training writes."""


def evaluation_folder(run_dir: str | Path) -> Path:
    """``RUN/evaluate``, created with its stage marker (:func:`curate.core.runfolder.write_stage_marker`) when it
    has none: the evaluation and the budget stage write their trainings there, each a stage of its own."""
    from curate.core.runfolder import STAGE_MARKER, write_stage_marker
    d = RunPaths(run_dir).evaluate
    d.mkdir(parents=True, exist_ok=True)
    if not (d / STAGE_MARKER).is_file():
        write_stage_marker(d, EVAL_OWN)
    return d


def clear_evaluation(run_dir: str | Path) -> list[Path]:
    """Remove ``RUN/evaluate`` (``--force``): the units' recorded files, the summary and the ground
    truth; the user's own files stay (returned). Nothing at all when a file curate wrote was changed since
    (:class:`curate.core.runfolder.RunFolderError`)."""
    from curate.core.runfolder import clear_tree
    if RunPaths(run_dir).evaluate.is_dir():
        evaluation_folder(run_dir)      # an evaluation folder of curate 0.2 had no marker
    return clear_tree(RunPaths(run_dir).evaluate, own=EVAL_OWN)


LEGACY_KEYS = {"energy": "selection", "energy-random": "selection-random", "energy-fvs": "selection-fvs",
               "energy_minus_random": "selection_minus_random"}
"""Keys curate 0.1 wrote for the selection (called 'energy' whatever its method) and their names now."""


def legacy_keys(d: dict) -> dict:
    """``d`` (a report's ``methods`` or ``paired``, a batch row) with curate 0.1's 'energy' keys renamed."""
    return {LEGACY_KEYS.get(k, k) if k not in ("psnr", "ssim") else k: v for k, v in d.items()}
