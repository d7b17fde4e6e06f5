"""``curate`` command line.

Options are declared once, in the config dataclasses (:class:`curate.config.RunConfig` and
the stage configs it nests, :class:`curate.simulate.experiment.SimulateConfig`): the tables
below only bind a flag to a field, and its default and help come from the field
(:mod:`curate.core.options`). Only the chosen command's options are built, so
``curate --help`` answers at once; heavy modules are imported inside each command.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from curate import __version__
from curate.core.options import Opt, add_options, apply_options, given
from curate.select.methods import METHODS
from curate.sfm.config import CAMERA_MODES, MAPPERS, MATCHERS, ON_SPLIT


class CliError(Exception):
    """A user-facing error: printed without a traceback, exit status 2."""


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (the usage of a command with 30 options buries the message)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")


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


_ADOPT = "use --out although it is a non-empty folder curate did not create (its files are never touched)"


# ---------------------------------------------------------------------- value parsers
def _box(text: str):
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--box wants six numbers x0,y0,z0,x1,y1,z1, got {text!r}")
    if len(v) != 6:
        raise argparse.ArgumentTypeError(f"--box wants six numbers x0,y0,z0,x1,y1,z1, got {len(v)}")
    return tuple(v)


def _bins(text: str):
    try:
        a, b = text.lower().split("x")
        nt, nph = int(a), int(b)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--bins wants THETAxPHI, e.g. 5x10, got {text!r}")
    if nt < 1 or nph < 1:
        raise argparse.ArgumentTypeError("--bins: both counts must be >= 1")
    return nt, nph


def _budget(text: str) -> str:
    """argparse type of ``--budget``: the text as given, checked by :func:`curate.core.budget.parse_budget`."""
    from curate.core.budget import parse_budget
    try:
        parse_budget(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--budget wants a count (200), a percentage (15%) or 'auto', got {text!r}")
    return text.strip()


def _size(text: str):
    from curate.simulate.progressive import CameraSpec
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w <= 0 or h <= 0:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size wants WIDTHxHEIGHT, e.g. 160x120, got {text!r}")
    return CameraSpec(w, h)


def _words(text: str) -> tuple[str, ...]:
    return tuple(w.strip() for w in text.split(",") if w.strip())


# ---------------------------------------------------------------------- flag -> field tables (paths in RunConfig)
BUDGET = [Opt("--budget", "budget", parse=_budget, metavar="N|P%|auto"),
          Opt("--budget-tolerance", "budget_tolerance", parse=float, metavar="DB")]
METHOD = [Opt("--method", "select.method", choices=METHODS),
          Opt("--path-weights", "select.medoids.path_weights"),
          Opt("--seed", "select.seed", parse=int)]
ENERGY = [Opt("--gamma", "select.energy.gamma", parse=float),
          Opt("--bins", ("select.energy.n_theta", "select.energy.n_phi"), parse=_bins, metavar="THETAxPHI",
              help="direction bins THETAxPHI over the sphere"),
          Opt("--equal-area", "select.energy.binning", const="equal-area",
              help="direction bins uniform in cos(theta) instead of theta (the paper's)"),
          Opt("--device", "select.device", parse=str, metavar="DEVICE")]
GRID = [Opt("--res", "occupancy.res", parse=int),
        Opt("--box", "box", parse=_box, metavar="X0,Y0,Z0,X1,Y1,Z1")]
TRAIN = [Opt("--holdout-every", "evaluate.holdout_every", parse=int),
         Opt("--iters", "evaluate.iters", parse=int),
         Opt("--eval-size", "evaluate.max_side", parse=int)]
EVAL = [Opt("--random-seeds", "evaluate.random_seeds", parse=int),
        Opt("--workers", "evaluate.workers", parse=int)]
NO_EVAL = [Opt("--no-evaluate", "run_evaluation", const=False,
               help="skip the trainings: selection, report and export only")]
EXPORT = [Opt("--export-mode", "export_mode", choices=("link", "copy"))]
SFM = [Opt("--max-size", "sfm.max_image_size", parse=int),
       Opt("--recursive", "sfm.recursive"),
       Opt("--matcher", "sfm.matcher", choices=MATCHERS),
       Opt("--camera-mode", "sfm.camera_mode", choices=CAMERA_MODES),
       Opt("--mapper", "sfm.mapper", choices=MAPPERS),
       Opt("--drop-blurry", "sfm.drop_blurry"),
       Opt("--keep-duplicates", "sfm.drop_duplicates", const=False, help="keep near-duplicate photos"),
       Opt("--sift-peak-threshold", "sfm.sift_peak_threshold", parse=float),
       Opt("--guided-matching", "sfm.guided_matching"),
       Opt("--no-dense", "sfm.dense", const="off", help="skip dense MVS even with CUDA"),
       Opt("--on-split", "sfm.on_split", choices=ON_SPLIT),
       Opt("--max-frames", "sfm.video.max_frames", parse=int)]
RUN = BUDGET + METHOD + ENERGY + GRID + TRAIN + EVAL + NO_EVAL + EXPORT + SFM

SIMULATE = [Opt("--scene", "scene", choices=("livingroom", "office", "kitchen")),
            Opt("--scene-seed", "scene_seed", parse=int),
            Opt("--budget", "budget", parse=int),
            Opt("--n-test", "n_test", parse=int),
            Opt("--candidates", "placement.n_candidates", parse=int),
            Opt("--size", "placement.camera", parse=_size, metavar="WxH",
                help="image size WIDTHxHEIGHT of the placed cameras"),
            Opt("--res", "node_res", parse=int),
            Opt("--gamma", "placement.energy.gamma", parse=float),
            Opt("--train-seconds", "train_seconds", parse=float),
            Opt("--train-iters", "train_iters", parse=int),
            Opt("--methods", "methods", parse=_words, metavar="A,B,..."),
            Opt("--occupancy", "occupancy", choices=("oracle", "field")),
            Opt("--train-between", "train_between", parse=int),
            Opt("--seed", "seed", parse=int)]

SUGGEST = [Opt("--add", "add", parse=int, metavar="K"),
           Opt("--candidates", "n_candidates", parse=int),
           Opt("--nodes", "nodes", choices=("surface", "surface+frontier")),
           Opt("--field", "field", choices=("auto", "train", "none")),
           Opt("--field-iters", "field_iters", parse=int),
           Opt("--field-size", "field_side", parse=int),
           Opt("--preview-size", "preview_side", parse=int),
           Opt("--seed", "seed", parse=int)]

# the options each command reads (a run folder's stage commands: only what their stage uses)
COMMAND_OPTS: dict[str, list[Opt]] = {
    "run": RUN, "batch": RUN, "sfm": SFM, "score": ENERGY + GRID,
    "select": BUDGET + METHOD + ENERGY + GRID,
    "occupancy": GRID + TRAIN, "evaluate": EVAL, "export": [Opt("--mode", "export_mode", choices=("link", "copy"))],
    "report": [], "simulate": SIMULATE, "suggest": SUGGEST,
}


def run_config(args, base=None):
    """The RunConfig of a command: ``base`` (default: the defaults) with the flags the user gave."""
    from curate.config import RunConfig
    try:
        return apply_options(base if base is not None else RunConfig(), args, COMMAND_OPTS[args.command])
    except ValueError as e:
        raise CliError(str(e))


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
def read_poses(path: Path):
    """(cameras, image paths) of a pose source (:func:`curate.sfm.poses.read_poses`), errors as CliError."""
    from curate.sfm.poses import read_poses as _read
    try:
        p = _read(path)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e))
    return p.cameras, p.files


def _grid(cfg, cams):
    from curate.core.grid import NodeGrid, box_from_cameras
    if cfg.box is not None:
        lo, hi = cfg.box[:3], cfg.box[3:]
    else:
        if len(cams) == 0:
            raise CliError("no cameras: give --box or a non-empty input")
        lo, hi = box_from_cameras(cams)
    return NodeGrid(lo, hi, cfg.occupancy.res)


def saved_config(run_dir: Path):
    """(the RunConfig saved in RUN/run.json, the whole record)."""
    from curate.config import RunConfig
    from curate.core.stage import config_from_dict
    p = run_dir / "run.json"
    if not p.is_file():
        raise CliError(f"{run_dir}: not a run folder of `curate run` (run.json missing)")
    try:
        rec = json.loads(p.read_text())
        return config_from_dict(RunConfig, rec["config"]), rec
    except (ValueError, KeyError, TypeError) as e:
        raise CliError(f"{p}: not a run record of this curate version ({e})")


# ---------------------------------------------------------------------- commands
def cmd_score(args) -> int:
    import numpy as np
    from curate.select.select import score_cameras

    cfg = run_config(args)
    _check_device(cfg.select.device)
    cams, _ = read_poses(Path(args.input))
    ecfg = cfg.select.energy
    grid = _grid(cfg, cams)
    t = score_cameras(cams, grid, ecfg, per_node=True, device=cfg.select.device)
    views = t.views_per_node
    seen = views > 0
    out = {**t.summary(), "res": grid.res, "box": grid.box_min.tolist() + grid.box_max.tolist(),
           "gamma": ecfg.gamma, "bins": [ecfg.n_theta, ecfg.n_phi], "binning": ecfg.binning,
           "observed_fraction": float(seen.mean()) if views.size else 0.0,
           "median_views_observed": float(np.median(views[seen])) if np.any(seen) else 0.0}
    if args.json:
        print(json.dumps(out))
        return 0
    n = max(t.n_nodes, 1)
    box = ", ".join(f"{v:.4g}" for v in out["box"])
    print(f"{t.n_cameras} cameras, {t.n_nodes} nodes ({grid.res}^3) in box [{box}]")
    print(f"  energy     E = {t.energy:.2f}   (each node scores up to 2: at most {2 * t.n_nodes})")
    print(f"  angular    sum(1 - TV) = {t.angular:.2f}   mean {t.angular / n:.3f} per node"
          " (1: seen from directions spread evenly over the sphere; ~0.02: from one direction)")
    print(f"  frequency  sum(O_f^gamma) = {t.frequency:.2f}   mean {t.frequency / n:.3f} per node"
          f" (gamma {ecfg.gamma}: near 1 once a node is seen at all)")
    print(f"  coverage   {100 * out['observed_fraction']:.1f}% of nodes seen by at least one camera;"
          f" median {out['median_views_observed']:.0f} views per seen node")
    return 0


def cmd_select(args) -> int:
    if (Path(args.input) / "run.json").is_file():
        return _select_run_folder(args)
    if args.out is None:
        raise CliError("--out is required (except for a run folder)")
    return _select_posed(args)


@_claims("out", ("input",), writes=("transforms.json", "selected.txt", "selection.json"))
def _select_posed(args) -> int:
    """``curate select POSES --out OUT``."""
    from curate.core.budget import AUTO, parse_budget, resolve_budget
    from curate.core.stage import write_json_atomic
    from curate.core.transforms_json import write_transforms
    from curate.occupancy.stage import check_budget_fits
    from curate.select.select import select
    from curate.select.stage import selection_record

    if not hasattr(args, Opt("--budget", "budget").dest):
        raise CliError("--budget is required (except for a run folder, which keeps its own)")
    cfg = run_config(args)
    _check_device(cfg.select.device)
    cams, files = read_poses(Path(args.input))
    if len(cams) == 0:
        raise CliError(f"{args.input}: the pool has no cameras")
    grid = _grid(cfg, cams)
    index = auto = None
    if parse_budget(cfg.budget) == AUTO:
        from curate.select.auto_budget import choose_for_pool
        from curate.select.visibility import build_pair_index
        index = build_pair_index(cams, grid.nodes(), cfg.select.energy.bins, device=cfg.select.device)
        try:
            auto = choose_for_pool(cams, grid.nodes(), index, cfg.budget_tolerance)
        except ValueError as e:
            raise CliError(f"{args.input}: {e}")
        budget = auto.budget
        if not args.json:
            print(auto.note)
    else:
        budget = resolve_budget(parse_budget(cfg.budget), len(cams))
        try:
            check_budget_fits(cfg.budget, budget, len(cams))
        except ValueError as e:
            raise CliError(str(e))
    sel = select(cams, grid, budget, cfg.select, progress=not args.json, index=index)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    chosen = sel.chosen
    # image paths relative to the written transforms.json, so the folder can move with its photos
    rel = [os_relpath(files[k], out) for k in chosen]
    write_transforms(out / "transforms.json", cams[chosen], rel)
    (out / "selected.txt").write_text("".join(Path(files[k]).name + "\n" for k in chosen))
    rec = {**selection_record(sel, cams, list(range(len(cams))), [], 0, cfg.budget, grid),
           **({"budget_auto": auto.to_dict()} if auto is not None else {}),
           "config": json.loads(json.dumps(_config_dict(cfg.select), default=str))}
    write_json_atomic(out / "selection.json", rec)
    if args.json:
        print(json.dumps({"chosen": chosen, "energy": sel.energy[-1] if sel.energy else 0.0,
                          "seconds": sel.seconds, "out": str(out)}))
    else:
        e = f", E = {sel.energy[-1]:.1f}" if sel.energy else ""
        print(f"selected {len(chosen)} of {len(cams)} cameras ({sel.method}{e}) in {sel.seconds:.2f}s -> {out}")
    return 0


def os_relpath(path: str, start: Path) -> str:
    """``path`` relative to the folder ``start`` when both are on one file system root; else absolute."""
    import os
    p = Path(path)
    if not p.is_absolute():
        p = Path.cwd() / p
    try:
        return os.path.relpath(p.resolve(), Path(start).resolve())
    except ValueError:  # pragma: no cover - another drive (Windows)
        return str(p.resolve())


def _config_dict(cfg) -> dict:
    from curate.core.stage import config_dict
    return config_dict(cfg)


@_claims("input", must_exist=True)
def _select_run_folder(args) -> int:
    """``curate select RUN``: the select stage of a run folder, its saved options overridden by the flags given."""
    from curate.select import stage
    bad = [o.flag for o in given(args, GRID)]
    if bad:
        raise CliError(f"{' and '.join(bad)} belong to the occupancy stage of a run folder: "
                       f"`curate occupancy {args.input} {bad[0]} ...` first")
    if args.out is not None:
        raise CliError("--out is for a pose file; a run folder's selection goes to RUN/select/")
    return _stage(args, stage.run, Path(args.input))


def _stage(args, fn, run_dir: Path) -> int:
    """Run one stage of a run folder with its saved options (overridden by the flags given, which are saved)."""
    from curate.pipeline import save_run_config
    base, rec = saved_config(run_dir)
    cfg = run_config(args, base)
    if cfg != base:
        save_run_config(cfg, run_dir, rec.get("photos"), rec.get("poses"))
    try:
        res = fn(cfg, run_dir, args.force)
    except (FileNotFoundError, ValueError, RuntimeError) as e:
        raise CliError(str(e))
    print(res.line(), flush=True)
    return 0


@_claims("run", must_exist=True)
def cmd_stage(args) -> int:
    """occupancy / evaluate / export / report on an existing run folder."""
    run_dir = Path(args.run)
    if args.command == "occupancy":
        from curate.occupancy.stage import run as fn
    elif args.command == "evaluate":
        from curate.evaluate.stage import run as fn
    elif args.command == "export":
        from curate.export.stage import run as fn
    else:
        from curate.report.stage import run as report
        _, rec = saved_config(run_dir)
        fn = lambda cfg, d, force: report(cfg, d, rec.get("photos"))  # noqa: E731
    return _stage(args, fn, run_dir)


@_claims("out", ("photos", "poses"), writes=("sfm",))
def cmd_sfm(args) -> int:
    from curate.sfm import stage
    cfg = run_config(args)
    if not args.photos and not args.poses:
        raise CliError("give a photo folder, or --poses with a COLMAP model or transforms.json")
    try:
        res = stage.run(cfg, Path(args.out), args.force, photos=args.photos, poses=args.poses)
    except (FileNotFoundError, NotADirectoryError, RuntimeError, ValueError) as e:
        raise CliError(str(e))
    st = json.loads((res.path / "stage.json").read_text()).get("stats", {})
    print(f"sfm: {res.summary}" + (f" of {st['n_kept']} kept photos" if "n_kept" in st else "")
          + (f", {st['n_points']} points" if "n_points" in st else "")
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
    if not args.photos and not args.poses:
        raise CliError("give a photo folder, or --poses with a COLMAP model or transforms.json")
    try:
        out = run(cfg, args.photos, args.out, poses=args.poses, force=args.force, adopt=args.adopt)
    except (FileNotFoundError, NotADirectoryError, RuntimeError, ValueError) as e:
        raise CliError(str(e))
    rep = json.loads(Path(out).read_text())
    m = rep.get("methods", {})
    if m:
        sel = f"selection ({(rep.get('selection') or {}).get('method', cfg.select.method)})"
        print("held-out PSNR (dB): " + ", ".join(f"{sel if k == 'selection' else k} {v['psnr']:.2f}"
                                                 for k, v in m.items())
              + (f"; {sel} - random {rep['paired']['selection-random']['mean']:+.2f} dB"
                 if "selection-random" in rep.get("paired", {}) else ""))
    print(f"report: {Path(args.out) / 'report.html'} ({rep['wall_seconds']:.0f}s)")
    return 0


def cmd_batch(args) -> int:
    from curate.batch.runner import read_list, run_batch
    from curate.core.executors import RayMissing
    cfg = run_config(args)
    _check_device(cfg.select.device)
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
        print(f"{r['name']:24s} {r['status']:6s} " + (f"{r['chosen']}/{r['registered']} chosen, PSNR selection "
              f"{p['selection'] or float('nan'):.2f} random {p['random'] or float('nan'):.2f}" if r["status"] == "ok"
              else r["reason"]))
    print(f"summary: {Path(args.out) / 'summary.html'} ({summ['n_ok']} ok, {summ['n_failed']} failed, "
          f"{summ['wall_seconds']:.0f}s)")
    return 0 if summ["n_failed"] == 0 else 1


# ---------------------------------------------------------------------- the parser
COMMANDS = {
    "sfm": "calibrate a photo folder (COLMAP) or import known poses into a run folder",
    "score": "score an existing capture with the energy (no NeRF needed)",
    "select": "choose a subset of a posed pool (a pose file, or a run folder's select stage)",
    "run": "the whole pipeline: photos -> best subset, report and export",
    "batch": "curate many photo folders (locally or on a Ray cluster), with a summary",
    "occupancy": "hold-out split, pool field and occupancy grid of a run folder",
    "evaluate": "train and score the subsets of a run folder",
    "report": "write RUN/report.json and RUN/report.html",
    "export": "export the chosen subset (COLMAP, transforms.json, list, links)",
    "simulate": "compare camera placements in a synthetic room (the paper's experiment)",
    "suggest": "where to shoot next: K new camera poses that most improve a run's capture",
}

DESCRIPTIONS = {
    "sfm": "Find and decode the photos (JPEG, PNG, TIFF, camera RAW), flag blurry and near-duplicate ones, and run "
           "COLMAP (pycolmap) offline; or, with --poses, import a COLMAP model or a transforms.json instead. Writes "
           "RUN/sfm/. The photo folder is never written to; an unchanged re-run is skipped.",
    "score": "Score how well a set of cameras covers the scene box: prints the energy and its two parts "
             "(angular uniformity, observation frequency).",
    "select": "Choose a budget of cameras from a posed pool and write transforms.json (image paths relative to it), "
              "selected.txt and selection.json in --out; or, for a run folder, redo its select stage with its "
              "saved options and the flags given.",
    "run": "SfM (or --poses), occupancy, selection, evaluation against random subsets, farthest-view sampling and "
           "all images on held-out views, export (RUN/export) and report (RUN/report.json, RUN/report.html). "
           "Unchanged stages are skipped on a re-run.",
    "batch": "`curate run` on every folder: RUNS/<name>/ per folder, RUNS/summary.json and RUNS/summary.html. A "
             "folder's poses: its transforms.json, else its sparse/0 (COLMAP), else SfM. A failing folder is "
             "reported failed, the others go on; a re-run resumes.",
    "simulate": "Place cameras in a procedural room with the energy (progressive, Algorithm 1), at random, on a "
                "hemisphere and by farthest-view sampling; render, train the same field on each and report PSNR "
                "on three test sets.",
    "suggest": "Propose K new camera poses for a run folder by the paper's energy, placed greedily as in its "
               "Algorithm 1 among hand-held poses in the space the capture observed as free. Writes RUN/suggest/: "
               "suggest.html (floor plan, numbered suggestions with walking instructions from the nearest frame and, "
               "with a field, previews), suggestions.json, transforms.json, images.txt and cameras.txt.",
}


def _base_for(command: str):
    if command == "simulate":
        from curate.simulate.experiment import SimulateConfig
        return SimulateConfig()
    if command == "suggest":
        from curate.suggest.config import SuggestConfig
        return SuggestConfig()
    from curate.config import RunConfig
    return RunConfig()


ALL = "*"
"""``build_parser(ALL)``: the options of every command (tests, documentation)."""


def build_parser(command: str | None = ALL) -> argparse.ArgumentParser:
    """The ``curate`` parser. Every command is listed; the options (whose defaults and help
    are read from the config dataclasses) are built for ``command`` only (None: for no
    command, as ``curate --help`` needs), or for every command (:data:`ALL`)."""
    p = _Parser(prog="curate", description="Pick the best photos of a capture for NeRF / "
                                "Gaussian splatting (Kopanas & Drettakis 2023, extended).")
    p.add_argument("--version", action="version", version=f"curate {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)
    for name, text in COMMANDS.items():
        desc = DESCRIPTIONS.get(name, text[0].upper() + text[1:] + ", with the options saved by `curate run`"
                                " (a flag given here overrides the saved option and is saved).")
        s = sub.add_parser(name, help=text, description=desc)
        if command != ALL and name != command:
            continue
        _add_command(name, s)
        add_options(s, _base_for(name), COMMAND_OPTS[name])
    return p


def _add_command(name: str, s: argparse.ArgumentParser) -> None:
    """The arguments of ``name`` that are not options of a config: inputs, outputs and switches."""
    if name in ("sfm", "run"):
        s.add_argument("photos", nargs="?", default=None, help="the photo folder (optional with --poses)")
        s.add_argument("--out", required=True, help="run folder")
        s.add_argument("--poses", default=None, help="import this COLMAP model folder or transforms.json instead of SfM")
    elif name == "score":
        s.add_argument("input", help="transforms.json, a COLMAP model folder (binary or text), the project's "
                       "cameras.json, or a run folder")
        s.add_argument("--json", action="store_true", help="print one JSON object")
    elif name == "select":
        s.add_argument("input", help="transforms.json, a COLMAP model folder, cameras.json, or a run folder")
        s.add_argument("--out", default=None, help="output folder (not for a run folder: its select/ stage is written)")
        s.add_argument("--json", action="store_true", help="print one JSON object")
    elif name == "batch":
        s.add_argument("folders", nargs="*", help="photo folders")
        s.add_argument("--list", default=None, help="a text file listing folders, one a line (relative to the file)")
        s.add_argument("--out", required=True, help="the batch folder (RUNS)")
        s.add_argument("--executor", default="local", choices=["local", "ray"],
                       help="local: a process per folder (default); ray: Ray tasks, trainings in parallel on the cluster")
        s.add_argument("--ray-address", default=None,
                       help="with --executor ray: 'auto' or HOST:PORT of a running cluster (default: a local instance)")
        s.add_argument("--jobs", type=int, default=0,
                       help="folders at once (default: one per core, capped by memory; ray: the cluster's CPUs)")
    elif name == "suggest":
        s.add_argument("run", help="run folder (of `curate run`)")
        s.add_argument("--json", action="store_true", help="print one JSON object")
    elif name == "simulate":
        s.add_argument("--out", required=True, help="output folder (report.json, report.html, renders)")
        s.add_argument("--json", action="store_true", help="print one JSON object")
    else:
        s.add_argument("run", help="run folder")
    if name != "simulate":
        s.add_argument("--force", action="store_true", help="redo the stage(s) even if unchanged")
    if name in ("run", "sfm", "select", "batch"):
        s.add_argument("--adopt", action="store_true", help=_ADOPT)
    s.set_defaults(func={"sfm": cmd_sfm, "score": cmd_score, "select": cmd_select, "run": cmd_run,
                         "batch": cmd_batch, "simulate": cmd_simulate, "suggest": cmd_suggest}.get(name, cmd_stage))


def _command_of(argv: list[str]) -> str | None:
    for a in argv:
        if a in COMMANDS:
            return a
        if not a.startswith("-"):
            return None
    return None


def _crash_log(exc: BaseException) -> Path:
    """Write the traceback of an unexpected error to a file; returns its path."""
    import tempfile
    import time
    import traceback
    p = Path(tempfile.gettempdir()) / f"curate-error-{time.strftime('%Y%m%d-%H%M%S')}-{__import__('os').getpid()}.log"
    p.write_text("".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser(_command_of(argv)).parse_args(argv)
    except SystemExit as e:  # --help, --version (0) or a one-line usage error (2)
        return e.code if isinstance(e.code, int) else 2
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except CliError as e:
        print(f"curate {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"curate {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # noqa: BLE001 - an internal error: one line, the trace in a file
        log = _crash_log(e)
        print(f"curate {args.command}: internal error: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''} "
              f"(full trace in {log})", file=sys.stderr)
        return 1
