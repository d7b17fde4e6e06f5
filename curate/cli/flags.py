"""The flags of ``curate``: each binds a flag to a field of a config dataclass (:class:`curate.config.RunConfig` and
the stage configs it nests, :class:`curate.simulate.experiment.SimulateConfig`, :class:`curate.suggest.config.
SuggestConfig`), whose default and help it reads (:mod:`curate.core.options`); and which flags each command reads
(:data:`COMMAND_OPTS`). Options are declared once, in the configs: a flag's name is the user's word for its field
(``--eval-size`` for ``evaluate.max_side``), and tests/test_cli_options.py checks that every flag reaches its field.
"""

from __future__ import annotations

import argparse
from typing import get_args

from curate.core.options import Opt
from curate.select.methods import METHODS, method_help
from curate.sfm.config import CAMERA_MODES, GUIDED, MAPPERS, MATCHERS, ON_SPLIT, TRIANGULATE
from curate.export.config import MODES, UNDISTORT
from curate.field.config import TRAINERS
from curate.simulate.choices import Scene, SimOccupancy
from curate.suggest.choices import FIELD_MODES, NODE_MODES


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
BUDGET = [Opt("--budget", "budget", metavar="N|P%|auto|default"),
          Opt("--budget-tolerance", "budget_tolerance", parse=float, metavar="DB")]
BUDGET_CHECK = [Opt("--no-budget-check", "budget_check", const=False,
                    help="with --budget auto: skip the two extra trainings that measure how many photos this "
                         "capture needs")]
METHOD = [Opt("--method", "select.method", choices=METHODS, help=method_help()),
          Opt("--path-weights", "select.medoids.path_weights"),
          Opt("--seed", "select.seed", parse=int)]
ENERGY = [Opt("--gamma", "select.energy.gamma", parse=float),
          Opt("--bins", ("select.energy.n_theta", "select.energy.n_phi"), parse=_bins, metavar="THETAxPHI",
              help="direction bins THETAxPHI over the sphere"),
          Opt("--equal-area", "select.energy.binning", const="equal-area",
              help="direction bins uniform in cos(theta) instead of theta (the paper's)"),
          Opt("--device", "select.device", parse=str, metavar="DEVICE")]
GRID = [Opt("--res", "occupancy.res", parse=int),
        Opt("--box", "box", parse=_box, metavar="X0,Y0,Z0,X1,Y1,Z1"),
        Opt("--refine-iters", "refine.iters", parse=int),
        Opt("--refine-size", "refine.max_side", parse=int, metavar="PX")]
TRAIN = [Opt("--holdout-every", "evaluate.holdout_every", parse=int),
         Opt("--iters", "evaluate.iters", parse=int),
         Opt("--eval-size", "evaluate.max_side", parse=int),
         Opt("--trainer", "evaluate.trainer", choices=TRAINERS),
         Opt("--splat-steps", "evaluate.splat.steps", parse=int),
         Opt("--splat-size", "evaluate.splat.max_side", parse=int, metavar="PX")]
EVAL = [Opt("--eval-minutes", "evaluate.minutes", parse=float, metavar="MIN"),
        Opt("--folds", "evaluate.folds", parse=int),
        Opt("--equivalence-db", "evaluate.margin_db", parse=float, metavar="DB"),
        Opt("--resolution-db", "evaluate.resolution_db", parse=float, metavar="DB"),
        Opt("--random-seeds", "evaluate.random_seeds", parse=int),
        Opt("--workers", "evaluate.workers", parse=int)]
NO_EVAL = [Opt("--no-evaluate", "run_evaluation", const=False,
               help="skip the trainings: selection, report and export only")]
def _factors(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(w) for w in _words(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--downscale wants factors such as 2,4,8, got {text!r}") from None


def _export_opts(mode_flag: str) -> list[Opt]:
    return [Opt(mode_flag, "export.mode", choices=MODES),
            Opt("--undistort", "export.undistort", choices=UNDISTORT),
            Opt("--keep-distorted", "export.keep_distorted"),
            Opt("--downscale", "export.downscale", parse=_factors, metavar="2,4,8")]


EXPORT = _export_opts("--export-mode")
SFM = [Opt("--max-size", "sfm.max_image_size", parse=int),
       Opt("--recursive", "sfm.recursive"),
       Opt("--matcher", "sfm.matcher", choices=MATCHERS),
       Opt("--camera-mode", "sfm.camera_mode", choices=CAMERA_MODES),
       Opt("--mapper", "sfm.mapper", choices=MAPPERS),
       Opt("--drop-blurry", "sfm.drop_blurry"),
       Opt("--keep-duplicates", "sfm.drop_duplicates", const=False, help="keep near-duplicate photos"),
       Opt("--sift-peak-threshold", "sfm.sift_peak_threshold", parse=float),
       Opt("--sift-upsample-below", "sfm.sift_upsample_below", parse=int, metavar="PX"),
       Opt("--guided-matching", "sfm.guided_matching", choices=GUIDED),
       Opt("--no-dense", "sfm.dense", const="off", help="skip dense MVS even with CUDA"),
       Opt("--on-split", "sfm.on_split", choices=ON_SPLIT),
       Opt("--max-frames", "sfm.video.max_frames", parse=int),
       Opt("--triangulate", "sfm.triangulate", choices=TRIANGULATE)]
RUN = BUDGET + BUDGET_CHECK + METHOD + ENERGY + GRID + TRAIN + EVAL + NO_EVAL + EXPORT + SFM

SIMULATE = [Opt("--scene", "scene", choices=get_args(Scene)),
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
            Opt("--occupancy", "occupancy", choices=get_args(SimOccupancy)),
            Opt("--train-between", "train_between", parse=int),
            Opt("--seed", "seed", parse=int)]

SUGGEST = [Opt("--add", "add", parse=int, metavar="K"),
           Opt("--candidates", "n_candidates", parse=int),
           Opt("--nodes", "nodes", choices=NODE_MODES),
           Opt("--field", "field", choices=FIELD_MODES),
           Opt("--field-iters", "field_iters", parse=int),
           Opt("--field-size", "field_side", parse=int),
           Opt("--preview-size", "preview_side", parse=int),
           Opt("--metres", "metres"),
           Opt("--seed", "seed", parse=int)]

# the options each command reads (a run folder's stage commands: only what their stage uses)
COMMAND_OPTS: dict[str, list[Opt]] = {
    "run": RUN, "batch": RUN, "sfm": SFM, "score": ENERGY + GRID,
    "select": BUDGET + METHOD + ENERGY + GRID,
    "occupancy": GRID, "evaluate": TRAIN + EVAL, "export": _export_opts("--mode"),
    "report": [], "simulate": SIMULATE, "suggest": SUGGEST,
}
