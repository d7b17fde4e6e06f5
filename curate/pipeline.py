"""``curate run``: photos -> SfM -> occupancy -> selection -> evaluation -> export -> report.

This module only sequences the stages of :data:`curate.core.graph.STAGES` (the graph, declared once). Each stage
is a plain function ``run(ctx: RunContext) -> StageResult`` in its own package that writes its own folder of
the run with a ``stage.json`` record last, and says whether it ran or was skipped. A stage's key hashes its
resolved config with the keys of the stages it reads, so a re-run skips a stage whose inputs and options did
not change and redoes everything downstream of a change. The run-folder contract is in ``docs/architecture.md``.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

from curate.core.paths import RunPaths
from curate.config import RunConfig
from curate.core.graph import BY_NAME, RUN_WRITES, STAGES, RunContext, redone_after
from curate.core.runner import run_stage
from curate.core.stage import StageResult

log = logging.getLogger(__name__)

__all__ = ["RunConfig", "run", "save_run_config", "saved_config"]


def save_run_config(cfg: RunConfig, run_dir: Path, photos=None, poses=None) -> None:
    """``RUN/run.json``: the resolved options (the base of every stage re-run), the inputs and the versions."""
    from curate.core.stage import config_dict, versions, write_json_atomic
    def absolute(p):   # as given, made absolute: a stage re-run from another directory finds the same files
        return str(Path(p).absolute()) if p else None
    write_json_atomic(RunPaths(run_dir).run_json, {"config": config_dict(cfg), "photos": absolute(photos),
                                                   "poses": absolute(poses), "versions": versions()})


def saved_config(run_dir: Path) -> tuple[RunConfig, dict]:
    """(the RunConfig saved in ``RUN/run.json`` by :func:`save_run_config`, the whole record): the base of every
    stage command. ``FileNotFoundError`` when the folder has none, ``ValueError`` when it is not one of this curate."""
    from curate.config import upgrade_config
    from curate.core.stage import config_from_dict
    p = RunPaths(run_dir).run_json
    if not p.is_file():
        raise FileNotFoundError(f"{run_dir}: not a run folder of `curate run` (run.json missing)")
    try:
        rec = json.loads(p.read_text())
        return config_from_dict(RunConfig, upgrade_config(rec["config"],
                                                          (rec.get("versions") or {}).get("curate"))), rec
    except (ValueError, KeyError, TypeError) as e:
        raise ValueError(f"{p}: not a run record of this curate version ({e})") from None


def _start(name: str) -> None:
    """On a terminal, a line saying which stage runs now (the stage's own line replaces it)."""
    import sys
    if sys.stdout.isatty():
        print(f"{name:10s} {BY_NAME[name].start} ...", flush=True)


def _done(res: StageResult, results: list[StageResult]) -> StageResult:
    results.append(res)
    print(res.line(), flush=True)
    return res


def check_same_capture(run_dir: Path, photos, poses) -> None:
    """ValueError when ``run_dir`` holds a run of another capture (its ``run.json`` names other photos or
    poses): a typo in ``--out`` must not replace that run without a word; ``--force`` does, on purpose. The
    same photos moved to another folder (the same file names), or the same pose file's content elsewhere, are
    the same capture: not refused (the stages that read the moved files are redone). ``run.json`` records the
    inputs as absolute paths (:func:`save_run_config`), so a run resumed from another directory is the same."""
    run_dir = Path(run_dir)
    try:
        rec = json.loads(RunPaths(run_dir).run_json.read_text())
    except (OSError, ValueError):
        return

    def same_path(a, b) -> bool:
        return (a is None) == (b is None) and (a is None or Path(a).resolve() == Path(b).resolve())

    def moved_photos(a, b) -> bool:        # the run's photos, by their names, in another folder
        try:
            had = {Path(r["original"]).name for r in json.loads(RunPaths(run_dir).images_json.read_text())["photos"]
                   if r.get("original") and Path(r["original"]).parent == Path(a).resolve()}
            from curate.sfm.ingest import find_images
            imgs, other = find_images(b)
            return bool(had) and had == {p.name for p in imgs + other}
        except (OSError, ValueError, KeyError, TypeError):
            return False

    def same_poses(a, b) -> bool:
        try:
            return Path(a).is_file() and Path(b).is_file() and Path(a).read_bytes() == Path(b).read_bytes()
        except OSError:
            return False
    ok_photos = same_path(rec.get("photos"), photos) or (photos and rec.get("photos") and
                                                         moved_photos(rec["photos"], photos))
    ok_poses = same_path(rec.get("poses"), poses) or (poses and rec.get("poses") and same_poses(rec["poses"], poses))
    # the same poses with the photos named once and found beside the poses the other time: the same capture
    ok_photos = ok_photos or bool(ok_poses and poses and (photos is None or rec.get("photos") is None))
    if not (ok_photos and ok_poses):
        held = " and ".join(f"{k} {rec[k]}" for k in ("photos", "poses") if rec.get(k)) or "another capture"
        raise ValueError(f"{run_dir} holds a run of another capture ({held}): give another --out, or --force to "
                         "replace that run")


def split_parts(run_dir: Path) -> list[dict]:
    """The models of a capture that split (``RUN/sfm`` stats ``parts``: the largest first, then
    ``sparse/1``, ...) with at least :data:`MIN_PART` photos; [] when it did not split."""
    from curate.core.stage import read_stage
    from curate.sfm.config import MIN_PART
    parts = ((read_stage(RunPaths(run_dir).sfm) or {}).get("stats") or {}).get("parts") or []
    parts = [p for p in parts if p["n_registered"] >= MIN_PART]
    return parts if len(parts) > 1 else []


def part_budget(budget: str, n_part: int, n_all: int) -> str:
    """A part's share of ``budget``: a percentage or 'auto' stays (it is of each part's pool); a
    count is shared in proportion to the parts' sizes (``n_part`` of ``n_all``), at least 2."""
    from curate.core.budget import parse_budget
    b = parse_budget(budget)
    return budget if isinstance(b, (float, str)) else str(max(2, int(round(b * n_part / max(n_all, 1)))))


def _run_parts(cfg: RunConfig, run_dir: Path, parts: list[dict], force: bool, executor) -> None:
    """Curate every part but the largest in ``RUN/parts/<k>`` (poses: ``RUN/sfm/sparse/<k>``, photos:
    the working copies ``RUN/sfm/images``, at SfM's working size), each a run folder of its own."""
    from dataclasses import replace
    n_all = sum(p["n_registered"] for p in parts)
    for p in parts[1:]:
        k = Path(p["model"]).name
        sub = RunPaths(run_dir).parts / k
        pcfg = replace(cfg, budget=part_budget(cfg.budget, p["n_registered"], n_all),
                       sfm=replace(cfg.sfm, on_split="largest"))
        print(f"part {k}: {p['n_registered']} photos, budget {pcfg.budget} -> {sub}", flush=True)
        # photos: SfM's working copies, found beside the model (RUN/sfm/images; the other parts' are not listed)
        run(pcfg, None, sub, poses=RunPaths(run_dir).sfm / p["model"], force=force, executor=executor)


def check_needs(command: str, run_dir: Path, rec: dict) -> None:
    """Before the stage command ``command`` (``curate select RUN``, ...): ``FileNotFoundError`` naming the curate
    command to run when a stage it reads has not finished, or when a file that stage wrote is missing (up to date
    means the files are there: :func:`curate.core.stage.up_to_date`). ``rec``: the run's ``run.json`` (its
    inputs, for the command that finishes the run)."""
    import shlex
    from curate.core.graph import BY_NAME
    from curate.core.runfolder import check_outputs
    from curate.core.stage import finished_record, read_stage
    missing = [s for s in BY_NAME[command].needs if finished_record(run_dir, s) is None]
    gone = {s: check_outputs(run_dir / s, (read_stage(run_dir / s) or {}).get("files"), BY_NAME[s].spare).missing
            for s in BY_NAME[command].needs if s not in missing}
    gone = {s: m for s, m in gone.items() if m}
    if not missing and not gone:
        return
    q = shlex.quote
    inputs = "".join(f" {q(v)}" if k == "photos" else f" --poses {q(v)}"
                     for k in ("photos", "poses") if (v := rec.get(k)))
    whole = f"curate run{inputs or ' PHOTOS'} --out {q(str(run_dir))}"
    first = next(s for s in BY_NAME[command].needs if s in missing or s in gone)
    cmd = (f"curate sfm{inputs or ' PHOTOS'} --out {q(str(run_dir))}" if first == "sfm"
           else f"curate {first} {q(str(run_dir))}")
    what = {"sfm": "SfM", "occupancy": "the occupancy stage", "select": "the selection"}[first]
    if first in gone:
        raise FileNotFoundError(f"{run_dir / first / gone[first][0]} is missing (a file {what} wrote"
                                f"{f', with {len(gone[first]) - 1} more' if len(gone[first]) > 1 else ''}); run "
                                f"`{cmd}` to write it again first (or `{whole}`)")
    raise FileNotFoundError(f"{run_dir}: {what} has not finished there; run `{cmd}` first "
                            f"(or `{whole}` to finish the whole run)")


def refresh_after(ctx: RunContext, stage: str) -> list[StageResult]:
    """After ``stage`` ran on its own (``curate select RUN``, ...): redo the cheap stages computed from it
    (:func:`curate.core.graph.redone_after`) and the report, printing a line for each, and a line naming the
    evaluation when it is now out of date (with the command that refreshes it). Returns the stages' results."""
    from curate.core.stage import refresh_command, stale_stages
    results = [_done(run_stage(BY_NAME[s], ctx), []) for s in redone_after(stage) if s != "report"]
    stale = stale_stages(ctx.run_dir)
    if "evaluate" in stale:
        print(f"{'evaluate':10s} out of date ({stale['evaluate']}): "
              f"`{refresh_command(ctx.run_dir, stale, 'evaluate')}` estimates the current selection", flush=True)
    out = run_stage(BY_NAME["report"], ctx)
    print(out.line(), flush=True)
    return results + [out]


def run(cfg: RunConfig, photos: str | Path | None, run_dir: str | Path, poses: str | Path | None = None,
        force: bool = False, executor=None, until: str | None = None, adopt: bool = False) -> Path:
    """:func:`_run` inside the claimed and locked run folder (:mod:`curate.core.runfolder`: refused
    before any work when it is not curate's, holds an input, lies inside one, or another run holds
    it; ``adopt``: accept a non-empty folder curate did not create, whose files are never touched)."""
    from curate.core import runfolder
    with runfolder.claimed(run_dir, inputs=[photos, poses], adopt=adopt, writes=RUN_WRITES):
        return _run(cfg, photos, run_dir, poses, force, executor, until)


def _run(cfg: RunConfig, photos: str | Path | None, run_dir: str | Path, poses: str | Path | None = None,
         force: bool = False, executor=None, until: str | None = None) -> Path:
    """The whole pipeline into ``run_dir``; returns the path of ``report.json`` (or, with
    ``until``, the folder of that stage, the last one run).

    ``photos``: the photo folder (SfM), or with ``poses`` (a COLMAP model or a
    transforms.json) the folder the poses' image paths are relative to. ``executor``:
    a ``concurrent.futures.Executor`` for the evaluation's trainings (None: local processes).
    """
    t_start = time.perf_counter()
    run_dir = Path(run_dir)      # claimed by run(): not inside the photos or the poses, none of them inside it
    run_dir.mkdir(parents=True, exist_ok=True)
    if not force:
        check_same_capture(run_dir, photos, poses)
    save_run_config(cfg, run_dir, photos, poses)
    ctx = RunContext(cfg, run_dir, force, photos, poses, executor)
    results: list[StageResult] = []
    sfm, *rest, report = STAGES
    _start(sfm.name)
    last = _done(run_stage(sfm, ctx), results)
    parts = split_parts(run_dir) if cfg.sfm.on_split == "each" and until is None else []
    if parts:  # the largest part takes its share of a count budget; the others follow the export
        from dataclasses import replace
        ctx.cfg = replace(cfg, budget=part_budget(cfg.budget, parts[0]["n_registered"],
                                                  sum(p["n_registered"] for p in parts)))
        print(f"part 0 (the largest): {parts[0]['n_registered']} photos, budget {ctx.cfg.budget} -> {run_dir}",
              flush=True)
    from curate.core.plan import plan_of_run
    plan_of_run(ctx.cfg, run_dir)   # the plan, once: a budget that does not fit stops here, before any training
    for stage in rest:
        if until is not None and last.name == until:
            return last.path
        if not stage.applies(ctx.cfg, run_dir):
            continue
        _start(stage.name)
        last = _done(run_stage(stage, ctx), results)
    if until is not None and last.name == until:
        return last.path
    if parts:
        _run_parts(cfg, run_dir, parts, force, executor)
    ctx.timings, ctx.seconds = [r.timing() for r in results], time.perf_counter() - t_start
    out = run_stage(report, ctx)
    print(out.line(), flush=True)
    for r in results:
        if r.warning:
            print(f"WARNING ({r.name}): {r.warning}", flush=True)
    return out.path
