"""What each ``curate`` command does with its parsed arguments: a thin call into the package that does the work
(:mod:`curate.pipeline`, :mod:`curate.select.posed`, :mod:`curate.batch`, ...), its errors as one line
(:class:`CliError`). Heavy modules are imported inside each command.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from curate.cli.flags import COMMAND_OPTS, GRID, SIMULATE, SUGGEST
from curate.core.options import Opt, apply_options, given
from curate.core.paths import RunPaths


class CliError(Exception):
    """A user-facing error: printed without a traceback, exit status 2."""


def _claims(folder: str, inputs: tuple[str, ...] = (), writes: tuple[str, ...] = (), must_exist: bool = False):
    """Run the command inside the claimed and locked folder ``args.<folder>``
    (:func:`curate.core.runfolder.claimed`; ``args.<inputs>``: the command's inputs;
    ``args.adopt`` when the command has it). Refusals are one-line errors (exit 2)."""
    import functools

    def deco(fn):
        @functools.wraps(fn)
        def wrapper(args):
            from curate.core import runfolder
            try:
                with runfolder.claimed(getattr(args, folder), [getattr(args, i, None) for i in inputs],
                                       adopt=getattr(args, "adopt", False), writes=writes, must_exist=must_exist):
                    return fn(args)
            except runfolder.RunFolderError as e:
                raise CliError(str(e))
        return wrapper
    return deco


def run_config(args, base=None):
    """The RunConfig of a command: ``base`` (default: the defaults) with the flags the user gave."""
    from curate.config import RunConfig
    try:
        return apply_options(base if base is not None else RunConfig(), args, COMMAND_OPTS[args.command])
    except ValueError as e:
        raise CliError(str(e))


def _check_trainer(cfg) -> None:
    """``--trainer gsplat`` where it cannot run (no CUDA, no gsplat): one line, before any work."""
    if cfg.run_evaluation and cfg.evaluate.trainer == "gsplat":
        from curate.field.splat import unavailable
        why = unavailable()
        if why:
            raise CliError(why)


def _check_device(device: str | None) -> None:
    if device is None:
        return
    import torch
    try:
        d = torch.device(device)
    except RuntimeError as e:
        raise CliError(f"--device {device!r}: {e}")
    if d.type == "cuda" and not torch.cuda.is_available():
        raise CliError(f"--device {device!r}: this machine has no CUDA device")


# ---------------------------------------------------------------------- helpers
def saved_config(run_dir: Path):
    """(the RunConfig saved in RUN/run.json, the whole record): :func:`curate.pipeline.saved_config`, its errors
    as CliError."""
    from curate.pipeline import saved_config as saved
    try:
        return saved(run_dir)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e))


# ---------------------------------------------------------------------- commands
def cmd_score(args) -> int:
    """``curate score POSES``: the energy of a set of cameras (:func:`curate.select.posed.score_posed`)."""
    from curate.select.posed import score_lines, score_posed
    cfg = run_config(args)
    _check_device(cfg.select.device)
    try:
        out = score_posed(cfg, args.input)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e))
    print(json.dumps(out) if args.json else "\n".join(score_lines(out)))
    return 0


def cmd_select(args) -> int:
    inp = Path(args.input)
    if RunPaths(inp).run_json.is_file():
        return _select_run_folder(args)
    if not inp.exists():
        raise CliError(f"{args.input}: no such run folder or pose file")
    if args.out is None:
        from curate.select.posed import read_poses
        try:
            read_poses(inp)
        except (FileNotFoundError, ValueError) as e:
            raise CliError(f"{args.input} is neither a run folder (no run.json) nor a pose file "
                           f"(transforms.json, a COLMAP model, cameras.json): {e}")
        if RunPaths(inp).record("sfm").is_file():   # a folder of `curate sfm`: poses, no run yet
            raise CliError(f"{args.input} holds the cameras of `curate sfm`, not a run of `curate run`: "
                           f"`curate select {args.input} --out DIR` chooses from those cameras into DIR, or "
                           f"`curate run PHOTOS --out {args.input}` goes on from them to a selection, its export and "
                           "report")
        raise CliError(f"--out is required for a pose file: where to write the subset of {args.input}")
    return _select_posed(args)


@_claims("out", ("input",), writes=("transforms.json", "selected.txt", "selection.json"))
def _select_posed(args) -> int:
    """``curate select POSES --out OUT`` (:func:`curate.select.posed.select_posed`)."""
    from curate.select.posed import select_posed
    if not hasattr(args, Opt("--budget", "budget").dest):
        raise CliError("--budget is required (except for a run folder, which keeps its own)")
    cfg = run_config(args)
    _check_device(cfg.select.device)
    try:
        r = select_posed(cfg, args.input, args.out, progress=not args.json, say=None if args.json else print)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e))
    if args.json:
        print(json.dumps({k: r[k] for k in ("chosen", "energy", "seconds", "out")}))
    else:
        e = f", E = {r['energy']:.1f}" if r["has_energy"] else ""
        print(f"selected {len(r['chosen'])} of {r['n_cameras']} cameras ({r['method']}{e}) in {r['seconds']:.2f}s "
              f"-> {r['out']}")
    return 0


@_claims("input", must_exist=True)
def _select_run_folder(args) -> int:
    """``curate select RUN``: the select stage of a run folder, its saved options overridden by the flags given."""
    bad = [o.flag for o in given(args, GRID)]
    if bad:
        raise CliError(f"{' and '.join(bad)} belong to the occupancy stage of a run folder: "
                       f"`curate occupancy {args.input} {bad[0]} ...` first")
    if args.out is not None:
        raise CliError("--out is for a pose file; a run folder's selection goes to RUN/select/")
    return _stage(args, Path(args.input))


def _stage(args, run_dir: Path) -> int:
    """Run the stage ``args.command`` of a run folder with its saved options (overridden by the flags given,
    which are saved); then redo the cheap stages computed from it and the report, and name the evaluation
    when it is now out of date (:func:`curate.pipeline.refresh_after`)."""
    from curate.core.graph import BY_NAME, RunContext
    from curate.core.runner import run_stage
    from curate.pipeline import refresh_after, save_run_config
    from curate.pipeline import check_needs
    base, rec = saved_config(run_dir)
    try:
        check_needs(args.command, run_dir, rec)
    except FileNotFoundError as e:
        raise CliError(str(e))
    cfg = run_config(args, base)
    if args.command == "evaluate":
        _check_trainer(cfg)
    if cfg != base:
        save_run_config(cfg, run_dir, rec.get("photos"), rec.get("poses"))
    ctx = RunContext(cfg, run_dir, args.force, rec.get("photos"), rec.get("poses"))
    try:
        res = run_stage(BY_NAME[args.command], ctx)
        print(res.line(), flush=True)
        if args.command != "report":
            refresh_after(ctx, args.command)
    except (FileNotFoundError, ValueError, RuntimeError) as e:
        raise CliError(str(e))
    return 0


@_claims("run", must_exist=True)
def cmd_stage(args) -> int:
    """occupancy / evaluate / export / report on an existing run folder."""
    return _stage(args, Path(args.run))


@_claims("out", ("photos", "poses"), writes=("sfm",))
def cmd_sfm(args) -> int:
    from curate.core.graph import BY_NAME, RunContext
    from curate.core.runner import run_stage
    from curate.core.stage import read_stage
    cfg = run_config(args)
    if not args.photos and not args.poses:
        raise CliError("give a photo folder, or --poses with a transforms.json or a COLMAP model")
    try:
        res = run_stage(BY_NAME["sfm"], RunContext(cfg, Path(args.out), args.force, args.photos, args.poses))
    except (FileNotFoundError, NotADirectoryError, RuntimeError, ValueError) as e:
        raise CliError(str(e))
    st = (read_stage(res.path) or {}).get("stats", {})
    print(f"sfm: {res.summary}" + (f" of {st['n_kept']} kept photos" if "n_kept" in st else "")
          + (f", {st['n_points']} points" if "n_points" in st and "points" not in res.summary else "")
          + ("" if res.ran else " (unchanged: skipped)") + f" in {res.seconds:.1f}s -> {res.path}")
    if res.warning:
        print(f"WARNING: {res.warning}", file=sys.stderr)
    return 0


def cmd_simulate(args) -> int:
    from curate.simulate.experiment import SimulateConfig, run_simulation
    try:
        cfg = apply_options(SimulateConfig(), args, SIMULATE)
    except ValueError as e:
        raise CliError(str(e))
    rep = run_simulation(cfg, Path(args.out))
    if args.json:
        print(json.dumps({"table": rep["table"], "wall_seconds": rep["wall_seconds"], "out": args.out}))
        return 0
    cols = ("hemisphere", "random", "ours", "average")
    print("train/test  " + "".join(f"{t:>12s}" for t in cols))
    for m, row in rep["table"].items():
        print(f"{m:12s}" + "".join(f"{row[t]:12.2f}" for t in cols))
    print(f"PSNR (dB) on held-out test views; ours' occupancy: {rep['occupancy']}; {rep['wall_seconds']:.0f}s; "
          f"report in {args.out}/report.json")
    return 0


@_claims("run", must_exist=True)
def cmd_suggest(args) -> int:
    """``curate suggest RUN --add K``: where to shoot next (:mod:`curate.suggest.stage`)."""
    from curate.suggest.config import SuggestConfig
    from curate.suggest.stage import run as suggest
    try:
        cfg = apply_options(SuggestConfig(), args, SUGGEST)
        res = suggest(cfg, Path(args.run), args.force, progress=not args.json)
    except (FileNotFoundError, ValueError, RuntimeError) as e:
        raise CliError(str(e))
    except OSError as e:     # a full disk met by a library that names no file: the stage's folder
        if e.filename is None and e.errno is not None:
            raise OSError(e.errno, e.strerror or str(e), str(Path(args.run) / "suggest")) from None
        raise
    if args.json:
        print(json.dumps({"out": str(res.path), "ran": res.ran, "suggestions": str(res.path / "suggestions.json"),
                          "page": str(res.path / "suggest.html"), "seconds": round(res.seconds, 2)}))
    else:
        print(res.line(), flush=True)
    return 0


def cmd_run(args) -> int:
    from curate.pipeline import run
    cfg = run_config(args)
    _check_device(cfg.select.device)
    _check_trainer(cfg)
    if not args.photos and not args.poses:
        raise CliError("give a photo folder, or --poses with a transforms.json or a COLMAP model")
    try:
        out = run(cfg, args.photos, args.out, poses=args.poses, force=args.force, adopt=args.adopt)
    except (FileNotFoundError, NotADirectoryError, RuntimeError, ValueError) as e:
        raise CliError(str(e))
    from curate.core.reads import read_json
    print_verdict(read_json(out), Path(args.out))     # the report just written: read once (curate.core.reads)
    return 0


def print_verdict(rep: dict, run_dir: Path) -> None:
    """The last lines of ``curate run``: what was exported, what it sees, how it compares (the
    report's own verdict, :func:`curate.report.verdict.verdict`), and where the report is."""
    from curate.report.verdict import verdict
    v = rep.get("verdict") or verdict(rep)
    print(f"{v['exported']} -> {run_dir / 'export'}")
    if v.get("frames"):
        print(v["frames"])
    if v.get("coverage"):
        print(v["coverage"])
    print(f"verdict: {v['short']}")
    if v.get("how_many"):
        print(v["how_many"])
    secs = rep.get("wall_seconds")
    print(f"report: {RunPaths(run_dir).report_html}" + (f" ({secs:.0f} s)" if secs is not None else ""))
    if RunPaths(run_dir).export_transforms.is_file():
        from curate.export.trainable import train_commands
        cmds = dict((t, c) for t, c in train_commands(RunPaths(run_dir).export))
        print(f"train on it: {cmds['nerfstudio, Gaussian splatting']}   (3DGS: "
              f"{cmds['3D Gaussian splatting (reference code)']}; more in the report)")


def cmd_batch(args) -> int:
    from curate.batch.runner import read_list, run_batch
    from curate.core.executors import RayMissing
    cfg = run_config(args)
    _check_device(cfg.select.device)
    _check_trainer(cfg)
    folders = list(args.folders)
    if args.list:
        try:
            folders += read_list(args.list)
        except OSError as e:
            raise CliError(f"--list: {e}")
    if not folders:
        raise CliError("give photo folders, or --list FILE")
    try:
        summ = run_batch(folders, args.out, cfg, executor=args.executor, jobs=args.jobs,
                         ray_address=args.ray_address, force=args.force, adopt=args.adopt)
    except (RayMissing, ValueError) as e:
        raise CliError(str(e))
    for r in summ["rows"]:
        p = r["psnr"]
        ok = r["status"] == "ok"
        print(f"{r['name']:24s} {r['status']:6s} " + (f"{r['chosen']} of {r['registered']} chosen; "
              + (r.get("verdict") or ("PSNR selection {:.2f}, random {:.2f}".format(p["selection"], p["random"])
                                      if p.get("selection") is not None and p.get("random") is not None
                                      else "not evaluated")) if ok else r["reason"]))
    print(f"summary: {Path(args.out) / 'summary.html'} ({summ['n_ok']} ok, {summ['n_failed']} failed, "
          f"{summ['wall_seconds']:.0f}s)")
    return 0 if summ["n_failed"] == 0 else 1
