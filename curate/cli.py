"""``curate`` command line. Heavy modules are imported inside each command, so
``curate --help`` answers at once."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from curate.core.budget import budget_text, parse_budget, resolve_budget
from curate.select.methods import (DEFAULT_METHOD, METHOD_HELP, METHODS, PATH_HELP, PATH_WEIGHTS, SHARPNESS_HELP,
                      SHARPNESS_WEIGHT)
from curate.sfm.config import CAMERA_MODES, MATCHERS
from curate.sfm.config import SfmConfig as _SfmDefaults  # a plain dataclass: nothing heavy


class CliError(Exception):
    """A user-facing error: printed without a traceback, exit status 2."""


def _claims(folder: str, inputs: tuple[str, ...] = (), writes: tuple[str, ...] = (), must_exist: bool = False):
    """runsafe: run the command inside the claimed and locked folder ``args.<folder>``
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


# ---------------------------------------------------------------------- argument helpers
def _box(text: str):
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--box wants six numbers x0,y0,z0,x1,y1,z1, got {text!r}")
    if len(v) != 6:
        raise argparse.ArgumentTypeError(f"--box wants six numbers x0,y0,z0,x1,y1,z1, got {len(v)}")
    if any(v[i + 3] < v[i] for i in range(3)):
        raise argparse.ArgumentTypeError("--box: each max (x1,y1,z1) must be >= its min (x0,y0,z0)")
    return v


def _bins(text: str):
    try:
        a, b = text.lower().split("x")
        nt, nph = int(a), int(b)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--bins wants THETAxPHI, e.g. 5x10, got {text!r}")
    if nt < 1 or nph < 1:
        raise argparse.ArgumentTypeError("--bins: both counts must be >= 1")
    return nt, nph


def _budget(text: str):
    """argparse type of ``--budget``: :func:`curate.core.budget.parse_budget`."""
    try:
        return parse_budget(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--budget wants a count (200) or a percentage (15%), got {text!r}")


def _add_budget(p: argparse.ArgumentParser) -> None:
    p.add_argument("--budget", type=_budget, required=True, help="a count (60) or a fraction of the pool (15%%)")


def _add_matcher(p: argparse.ArgumentParser) -> None:
    p.add_argument("--matcher", default="auto", choices=MATCHERS,
                   help="SfM image pairs (default auto: exhaustive up to 150 photos, else sequential or spatial)")


def _add_energy_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("energy")
    g.add_argument("--box", type=_box, help="scene box x0,y0,z0,x1,y1,z1 (default: from the cameras)")
    g.add_argument("--res", type=int, default=32, help="nodes per axis (default 32)")
    g.add_argument("--gamma", type=float, default=0.05, help="exponent on the observation frequency (default 0.05)")
    g.add_argument("--bins", type=_bins, default=(5, 10), help="direction bins THETAxPHI (default 5x10)")
    g.add_argument("--equal-area", action="store_true", help="bins uniform in cos(theta) instead of theta")
    g.add_argument("--device", default=None, help="torch device for visibility (default: cuda if available)")


def _add_method(s: argparse.ArgumentParser) -> None:
    s.add_argument("--method", default=DEFAULT_METHOD, choices=METHODS, help=METHOD_HELP)
    s.add_argument("--sharpness-weight", type=float, default=SHARPNESS_WEIGHT, help=SHARPNESS_HELP)
    s.add_argument("--path-weights", action=argparse.BooleanOptionalAction, default=PATH_WEIGHTS, help=PATH_HELP)


def _select_cfg(args, base=None):
    """SelectConfig from the options of ``_add_method`` and ``_add_energy_args`` (over ``base``)."""
    from dataclasses import replace
    from curate.select.select import SelectConfig
    base = base if base is not None else SelectConfig(device=args.device)
    try:
        return replace(base, method=args.method, energy=_energy_cfg(args), seed=args.seed,
                       medoids=replace(base.medoids, sharpness_weight=args.sharpness_weight,
                                       path_weights=args.path_weights))
    except ValueError as e:
        raise CliError(str(e))


def _energy_cfg(args):
    from curate.select.energy import EnergyConfig
    try:
        return EnergyConfig(gamma=args.gamma, n_theta=args.bins[0], n_phi=args.bins[1],
                            binning="equal-area" if args.equal_area else "paper")
    except ValueError as e:
        raise CliError(str(e))


def _grid(args, cams):
    from curate.core.grid import NodeGrid, box_from_cameras
    if args.res < 1:
        raise CliError("--res must be >= 1")
    if args.box is not None:
        lo, hi = args.box[:3], args.box[3:]
    else:
        if len(cams) == 0:
            raise CliError("no cameras: give --box or a non-empty input")
        lo, hi = box_from_cameras(cams)
    return NodeGrid(lo, hi, args.res)


def load_cameras(path: Path):
    """Cameras from a transforms.json, the project's cameras.json, a COLMAP model folder
    (binary or text, or a folder with sparse/0) or a run folder; (cameras, image paths)."""
    from curate.core.cameras import Cameras
    from curate.core.transforms_json import read_transforms
    if not path.exists():
        raise CliError(f"{path}: no such file or folder")
    if path.is_dir():
        if any((path / f).is_file() for f in ("cameras.bin", "cameras.txt")) or (path / "sparse" / "0").is_dir():
            from curate.sfm.colmap import read_cameras
            try:
                return read_cameras(path)
            except (OSError, ValueError, RuntimeError) as e:
                raise CliError(f"{path}: cannot read the COLMAP model ({e})")
        for name in ("transforms.json", "cameras.json", "sfm/cameras.json"):
            if (path / name).is_file():
                return load_cameras(path / name)
        raise CliError(f"{path}: a folder without a COLMAP model, transforms.json or cameras.json")
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CliError(f"{path}: not a readable JSON file ({e})")
    try:
        if isinstance(data, dict) and "convention" in data:
            cams = Cameras.from_dict(data)
            return cams, list(cams.names)
        return read_transforms(path)
    except (ValueError, KeyError, TypeError) as e:
        raise CliError(f"{path}: {e}")


# ---------------------------------------------------------------------- commands
def cmd_score(args) -> int:
    import numpy as np
    from curate.select.select import score_cameras

    cams, _ = load_cameras(Path(args.input))
    cfg = _energy_cfg(args)
    grid = _grid(args, cams)
    t = score_cameras(cams, grid, cfg, per_node=True, device=args.device)
    views = t.views_per_node
    seen = views > 0
    out = {**t.summary(), "res": grid.res, "box": grid.box_min.tolist() + grid.box_max.tolist(),
           "gamma": cfg.gamma, "bins": [cfg.n_theta, cfg.n_phi], "binning": cfg.binning,
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
          f" (gamma {cfg.gamma}: near 1 once a node is seen at all)")
    print(f"  coverage   {100 * out['observed_fraction']:.1f}% of nodes seen by at least one camera;"
          f" median {out['median_views_observed']:.0f} views per seen node")
    return 0


def cmd_select(args) -> int:
    if (Path(args.input) / "occupancy" / "stage.json").is_file():
        return _select_stage(args)
    if args.out is None:
        raise CliError("--out is required (except for a run folder)")
    return _select_posed(args)


@_claims("out", ("input",), writes=("transforms.json", "selected.txt", "selection.json"))  # runsafe
def _select_posed(args) -> int:
    """``curate select POSES --out OUT``."""
    from curate.select.select import select, uses_sharpness
    from curate.core.transforms_json import write_transforms
    from curate.core.stage import write_json_atomic, config_dict
    cams, files = load_cameras(Path(args.input))
    if len(cams) == 0:
        raise CliError("the pool has no cameras")
    budget = resolve_budget(args.budget, len(cams))
    cfg = _select_cfg(args)
    grid = _grid(args, cams)
    sharp = None
    if uses_sharpness(cams, cfg):
        from curate.sfm.quality import files_sharpness
        if all(Path(f).is_file() for f in files):
            sharp = files_sharpness(files, progress=not args.json)      # [K]
        else:
            logging.getLogger(__name__).warning("select: the pool's photos are not all found: sharpness ignored")
    sel = select(cams, grid, budget, cfg, progress=not args.json, sharpness=sharp)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    chosen = sel.chosen
    write_transforms(out / "transforms.json", cams[chosen], [files[k] for k in chosen])
    (out / "selected.txt").write_text("".join(Path(files[k]).name + "\n" for k in chosen))
    rec = {**sel.to_dict(), "names": [cams.names[k] for k in chosen], "pool": len(cams), "budget": budget,
           "config": config_dict(cfg), "res": grid.res, "box": grid.box_min.tolist() + grid.box_max.tolist()}
    write_json_atomic(out / "selection.json", rec)
    if args.json:
        print(json.dumps({"chosen": chosen, "energy": sel.energy[-1] if sel.energy else 0.0,
                          "seconds": sel.seconds, "out": str(out)}))
    else:
        e = f", E = {sel.energy[-1]:.1f}" if sel.energy else ""
        print(f"selected {len(chosen)} of {len(cams)} cameras ({args.method}{e}) in {sel.seconds:.2f}s -> {out}")
    return 0


@_claims("out", ("photos", "poses"), writes=("sfm",))  # runsafe
def cmd_sfm(args) -> int:
    import time
    from curate.sfm.config import SfmConfig

    try:
        cfg = SfmConfig(max_image_size=args.max_size, recursive=args.recursive, matcher=args.matcher,
                        camera_mode=args.camera_mode, drop_blurry=args.drop_blurry,
                        drop_duplicates=not args.keep_duplicates, dense="off" if args.no_dense else "auto",
                        sift_peak_threshold=args.sift_peak_threshold, guided_matching=args.guided_matching)
    except ValueError as e:
        raise CliError(str(e))
    if not args.photos and not args.poses:
        raise CliError("give a photo folder, or --poses with a COLMAP model or transforms.json")
    t0 = time.perf_counter()
    from curate.sfm.colmap import import_poses, run_sfm
    try:
        if args.poses:
            out = import_poses(cfg, args.poses, args.out, photos=args.photos, force=args.force)
        else:
            out = run_sfm(cfg, args.photos, args.out, force=args.force)
    except (FileNotFoundError, NotADirectoryError, RuntimeError, ValueError) as e:
        raise CliError(str(e))
    rec = json.loads((out / "stage.json").read_text())
    st = rec.get("stats", {})
    n_cams = len(json.loads((out / "cameras.json").read_text())["cameras"])
    print(f"sfm: {n_cams} cameras registered" + (f" of {st['n_kept']} kept photos" if "n_kept" in st else "")
          + (f", {st['n_points']} points" if "n_points" in st else "")
          + f" in {time.perf_counter() - t0:.1f}s -> {out}")
    return 0


def cmd_simulate(args) -> int:
    from dataclasses import replace
    from curate.simulate.progressive import ProgressiveConfig, CameraSpec
    from curate.simulate.experiment import SimulateConfig, run_simulation
    from curate.select.energy import EnergyConfig

    w, h = args.size
    cfg = SimulateConfig(scene=args.scene, scene_seed=args.scene_seed, budget=args.budget, n_test=args.n_test,
                         node_res=args.res, train_seconds=args.train_seconds,
                         train_iters=args.train_iters or None, seed=args.seed,
                         occupancy=args.occupancy, train_between=args.train_between,
                         placement=ProgressiveConfig(n_candidates=args.candidates, energy=EnergyConfig(gamma=args.gamma),
                                                     camera=CameraSpec(w, h)))
    if args.methods:
        cfg = replace(cfg, methods=tuple(args.methods.split(",")))
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


def _run_cfg(args):
    """RunConfig from ``curate run`` options."""
    from curate.evaluate.units import EvalConfig
    from curate.occupancy.masks import OccupancyConfig
    from curate.pipeline import RunConfig
    from curate.sfm.config import SfmConfig
    try:
        ev = EvalConfig(holdout_every=args.holdout_every, max_side=args.eval_size, iters=args.iters,
                        random_seeds=args.random_seeds, workers=args.workers)
        return RunConfig(budget=budget_text(args.budget), sfm=SfmConfig(max_image_size=args.max_size, matcher=args.matcher),
                         occupancy=OccupancyConfig(res=args.res),
                         select=_select_cfg(args),
                         evaluate=ev, run_evaluation=not args.no_evaluate, export_mode=args.export_mode)
    except ValueError as e:
        raise CliError(str(e))


def _saved_cfg(run_dir: Path):
    """The RunConfig saved in RUN/run.json by ``curate run``."""
    from curate.pipeline import RunConfig
    from curate.core.stage import config_from_dict
    p = run_dir / "run.json"
    if not p.is_file():
        raise CliError(f"{run_dir}: not a run folder of `curate run` (run.json missing)")
    try:
        return config_from_dict(RunConfig, json.loads(p.read_text())["config"]), json.loads(p.read_text())
    except (ValueError, KeyError, TypeError, json.JSONDecodeError) as e:
        raise CliError(f"{p}: {e}")


def cmd_run(args) -> int:
    from curate.pipeline import run
    cfg = _run_cfg(args)
    if not args.photos and not args.poses:
        raise CliError("give a photo folder, or --poses with a COLMAP model or transforms.json")
    try:
        out = run(cfg, args.photos, args.out, poses=args.poses, force=args.force, adopt=args.adopt)
    except (FileNotFoundError, NotADirectoryError, RuntimeError, ValueError) as e:
        raise CliError(str(e))
    rep = json.loads(Path(out).read_text())
    m = rep.get("methods", {})
    if m:
        sel = f"selection ({(rep.get('selection') or {}).get('method', cfg.select.method)})"  # key "energy": any method
        print("held-out PSNR (dB): " + ", ".join(f"{sel if k == 'energy' else k} {v['psnr']:.2f}" for k, v in m.items())
              + (f"; {sel} - random {rep['paired']['energy-random']['mean']:+.2f} dB"
                 if "energy-random" in rep.get("paired", {}) else ""))
    print(f"report: {Path(args.out) / 'report.html'} ({rep['wall_seconds']:.0f}s)")
    return 0


def cmd_batch(args) -> int:
    from curate.batch.runner import read_list, run_batch
    from curate.core.executors import RayMissing
    cfg = _run_cfg(args)
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
              f"{p['energy'] or float('nan'):.2f} random {p['random'] or float('nan'):.2f}" if r["status"] == "ok"
              else r["reason"]))
    print(f"summary: {Path(args.out) / 'summary.html'} ({summ['n_ok']} ok, {summ['n_failed']} failed, "
          f"{summ['wall_seconds']:.0f}s)")
    return 0 if summ["n_failed"] == 0 else 1


@_claims("run", must_exist=True)  # runsafe
def cmd_stage(args) -> int:
    """occupancy / evaluate / report / export on an existing run folder, with its saved config."""
    from curate import pipeline as pl
    run_dir = Path(args.run)
    cfg, rec = _saved_cfg(run_dir)
    try:
        if args.command == "occupancy":
            pl.stage_occupancy(cfg, run_dir, args.force)
        elif args.command == "evaluate":
            pl.stage_evaluate(cfg, run_dir, args.force)
        elif args.command == "export":
            from dataclasses import replace
            pl.stage_export(replace(cfg, export_mode=args.mode or cfg.export_mode), run_dir, args.force)
        else:
            pl.stage_report(cfg, run_dir, rec.get("photos"), [], None)
            print(f"report: {run_dir / 'report.json'}, {run_dir / 'report.html'}")
    except (FileNotFoundError, ValueError, RuntimeError) as e:
        raise CliError(str(e))
    return 0


@_claims("input", must_exist=True)  # runsafe
def _select_stage(args) -> int:
    """``curate select RUN``: the select stage of a run folder, with its saved config."""
    from dataclasses import replace
    from curate import pipeline as pl
    run_dir = Path(args.input)
    cfg, _ = _saved_cfg(run_dir)
    sel = _select_cfg(args, cfg.select)
    cfg = replace(cfg, budget=budget_text(args.budget), select=sel)
    try:
        pl.stage_select(cfg, run_dir, getattr(args, "force", False))
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e))
    return 0


def _size(text: str):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        assert w > 0 and h > 0
        return w, h
    except (ValueError, AssertionError):
        raise argparse.ArgumentTypeError(f"--size wants WIDTHxHEIGHT, e.g. 160x120, got {text!r}")


def _add_run_options(s: argparse.ArgumentParser) -> None:
    """The options of `curate run` that `curate batch` shares."""
    _add_budget(s)
    _add_method(s)
    s.add_argument("--seed", type=int, default=0, help="seed of the random selection method")
    s.add_argument("--holdout-every", type=int, default=14, help="hold out every n-th image (default 14)")
    s.add_argument("--random-seeds", type=int, default=3, help="random subsets to compare with (default 3)")
    s.add_argument("--iters", type=int, default=800, help="field training iterations per subset (default 800)")
    s.add_argument("--eval-size", type=int, default=240, help="longer side of training/test images (default 240)")
    s.add_argument("--workers", type=int, default=0, help="parallel trainings (default: one per core)")
    s.add_argument("--no-evaluate", action="store_true", help="skip the trainings (selection, report, export only)")
    s.add_argument("--export-mode", default="link", choices=["link", "copy"], help="export links or copies")
    s.add_argument("--max-size", type=int, default=1600, help="SfM working copies' longer side (default 1600)")
    _add_matcher(s)
    s.add_argument("--force", action="store_true", help="redo every stage")
    _add_energy_args(s)


_ADOPT = "use --out although it is a non-empty folder curate did not create (its files are never touched)"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="curate", description="Pick the best photos of a capture for NeRF / "
                                "Gaussian splatting (Kopanas & Drettakis 2023, extended).")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("sfm", help="calibrate a photo folder (COLMAP) or import known poses into a run folder",
                       description="Find and decode the photos (JPEG, PNG, TIFF, camera RAW), flag blurry and "
                       "near-duplicate ones, and run COLMAP (pycolmap) offline; or, with --poses, import a COLMAP "
                       "model or a transforms.json instead. Writes RUN/sfm/ (see curate/sfm.py). The photo folder is "
                       "never written to; an unchanged re-run is skipped.")
    s.add_argument("photos", nargs="?", default=None, help="the photo folder (optional with --poses)")
    s.add_argument("--out", required=True, help="run folder")
    s.add_argument("--poses", default=None, help="import this COLMAP model folder or transforms.json instead of SfM")
    s.add_argument("--max-size", type=int, default=1600, help="longer side of the working copies (default 1600)")
    s.add_argument("--recursive", action="store_true", help="also take photos from sub-folders")
    _add_matcher(s)
    s.add_argument("--camera-mode", default="auto", choices=CAMERA_MODES)
    s.add_argument("--drop-blurry", action="store_true", help="drop blurry photos (default: flag them only)")
    s.add_argument("--keep-duplicates", action="store_true", help="keep near-duplicate photos")
    s.add_argument("--sift-peak-threshold", type=float, default=_SfmDefaults.sift_peak_threshold,
                   help="SIFT detector threshold (default COLMAP's 0.0067; 0.004 finds more features on dark, "
                   "low-contrast photos: skull registers 66 of 66 instead of 65, slower)")
    s.add_argument("--guided-matching", action="store_true",
                   help="COLMAP guided matching: more matches, about twice the matching time")
    s.add_argument("--no-dense", action="store_true", help="skip dense MVS even with CUDA")
    s.add_argument("--force", action="store_true", help="redo the stage even if its inputs did not change")
    s.add_argument("--adopt", action="store_true", help=_ADOPT)
    s.set_defaults(func=cmd_sfm)

    s = sub.add_parser("score", help="score an existing capture with the energy (no NeRF needed)",
                       description="Score how well a set of cameras covers the scene box: prints the energy "
                       "and its two parts (angular uniformity, observation frequency).")
    s.add_argument("input", help="transforms.json, a COLMAP model folder (binary or text), the project's "
                   "cameras.json, or a run folder")
    _add_energy_args(s)
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_score)

    s = sub.add_parser("select", help="choose a subset of a posed pool",
                       description="Choose a budget of cameras from a posed pool and write them as "
                       "transforms.json, selected.txt and selection.json in --out.")
    s.add_argument("input", help="transforms.json, a COLMAP model folder, cameras.json, or a run folder")
    _add_budget(s)
    _add_method(s)
    s.add_argument("--seed", type=int, default=0, help="seed of the random baseline")
    s.add_argument("--out", default=None, help="output folder (not for a run folder: its select/ stage is written)")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.add_argument("--force", action="store_true", help="run folder: redo the stage even if unchanged")
    s.add_argument("--adopt", action="store_true", help=_ADOPT)
    _add_energy_args(s)
    s.set_defaults(func=cmd_select)

    s = sub.add_parser("run", help="the whole pipeline: photos -> best subset, report and export",
                       description="SfM (or --poses), occupancy, selection, evaluation against random subsets, "
                       "farthest-view sampling and all images on held-out views, report (RUN/report.json, "
                       "RUN/report.html) and export (RUN/export). Unchanged stages are skipped on a re-run.")
    s.add_argument("photos", nargs="?", default=None, help="the photo folder")
    s.add_argument("--out", required=True, help="run folder")
    s.add_argument("--poses", default=None, help="import this COLMAP model or transforms.json instead of SfM")
    _add_run_options(s)
    s.add_argument("--adopt", action="store_true", help=_ADOPT)
    s.set_defaults(func=cmd_run)

    s = sub.add_parser("batch", help="curate many photo folders (locally or on a Ray cluster), with a summary",
                       description="`curate run` on every folder: RUNS/<name>/ per folder, RUNS/summary.json and "
                       "RUNS/summary.html. A folder's poses: its transforms.json, else its sparse/0 (COLMAP), else "
                       "SfM. A failing folder is reported failed, the others go on; a re-run resumes.")
    s.add_argument("folders", nargs="*", help="photo folders")
    s.add_argument("--list", default=None, help="a text file listing folders, one a line (relative to the file)")
    s.add_argument("--out", required=True, help="the batch folder (RUNS)")
    s.add_argument("--executor", default="local", choices=["local", "ray"],
                   help="local: a process per folder (default); ray: Ray tasks, trainings in parallel on the cluster")
    s.add_argument("--ray-address", default=None,
                   help="with --executor ray: 'auto' or HOST:PORT of a running cluster (default: a local instance)")
    s.add_argument("--jobs", type=int, default=0,
                   help="folders at once (default: one per core, capped by memory; ray: the cluster's CPUs)")
    _add_run_options(s)
    s.add_argument("--adopt", action="store_true", help=_ADOPT)
    s.set_defaults(func=cmd_batch)

    for name, text in (("occupancy", "occupancy grid and pool field of a run folder"),
                       ("evaluate", "train and score the subsets of a run folder"),
                       ("report", "write RUN/report.json and RUN/report.html"),
                       ("export", "export the chosen subset (COLMAP, transforms.json, list, links)")):
        s = sub.add_parser(name, help=text, description=text + ", with the options saved by `curate run`.")
        s.add_argument("run", help="run folder")
        s.add_argument("--force", action="store_true", help="redo the stage even if unchanged")
        if name == "export":
            s.add_argument("--mode", default=None, choices=["link", "copy"], help="links (default) or copies")
        s.set_defaults(func=cmd_stage)

    s = sub.add_parser("simulate", help="compare camera placements in a synthetic room (the paper's experiment)",
                       description="Place cameras in a procedural room with the energy (progressive, Algorithm 1), "
                       "at random, on a hemisphere and by farthest-view sampling; render, train the same field on "
                       "each and report PSNR on three test sets.")
    s.add_argument("--scene", default="livingroom", choices=["livingroom", "office", "kitchen"])
    s.add_argument("--scene-seed", type=int, default=0)
    s.add_argument("--budget", type=int, default=100, help="cameras per method (default 100)")
    s.add_argument("--n-test", type=int, default=50, help="views per test set (default 50)")
    s.add_argument("--candidates", type=int, default=1000, help="random candidates per step (default 1000)")
    s.add_argument("--size", type=_size, default=(160, 120), help="image size WxH (default 160x120)")
    s.add_argument("--res", type=int, default=32, help="node grid resolution (default 32)")
    s.add_argument("--gamma", type=float, default=0.05)
    s.add_argument("--train-seconds", type=float, default=120.0, help="field training per method (default 120)")
    s.add_argument("--train-iters", type=int, default=0, help="fixed training iterations instead of seconds")
    s.add_argument("--methods", default="", help="comma list (default ours,random,hemisphere,fvs)")
    s.add_argument("--occupancy", default="oracle", choices=["oracle", "field"],
                   help="ours' occupancy: the scene's geometry (default) or the field trained as cameras are added")
    s.add_argument("--train-between", type=int, default=250,
                   help="--occupancy field: field iterations after each added camera (default 250)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--out", required=True)
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_simulate)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except CliError as e:
        print(f"curate {args.command}: error: {e}", file=sys.stderr)
        return 2
