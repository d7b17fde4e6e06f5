"""``curate`` command line.

Options are declared once, in the config dataclasses (:class:`curate.config.RunConfig` and
the stage configs it nests, :class:`curate.simulate.experiment.SimulateConfig`): the tables
below only bind a flag to a field, and its default and help come from the field
(:mod:`curate.core.options`). Only the chosen command's options are built, so
``curate --help`` answers at once; heavy modules are imported inside each command.
"""

from __future__ import annotations

import argparse
import difflib
import errno
import json
import logging
import re
import sys
from pathlib import Path
from typing import get_args

from curate import __version__
from curate.core.paths import RunPaths
from curate.core.options import HelpFormatter, Opt, add_options, apply_options, given
from curate.select.methods import METHODS, method_help
from curate.sfm.config import CAMERA_MODES, GUIDED, MAPPERS, MATCHERS, ON_SPLIT, TRIANGULATE
from curate.export.config import MODES, UNDISTORT
from curate.field.config import TRAINERS
from curate.simulate.choices import Scene, SimOccupancy
from curate.suggest.choices import FIELD_MODES, NODE_MODES


class CliError(Exception):
    """A user-facing error: printed without a traceback, exit status 2."""


def nearest(word: str, candidates: list[str]) -> list[str]:
    """The candidates nearest to a mistyped ``word`` (difflib; those almost as near as the nearest, at most 3)."""
    ranked = sorted(((difflib.SequenceMatcher(None, word, c).ratio(), c) for c in candidates), reverse=True)
    ranked = [(r, c) for r, c in ranked if r >= 0.6]
    return [c for r, c in ranked[:3] if r >= ranked[0][0] - 0.1]


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error that names the command's own help and, for a mistyped flag,
    command or choice, the nearest ones (the usage of a command with 30 options buries the message)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        self._argv: list[str] = []

    def parse_known_args(self, args=None, namespace=None):
        self._argv = list(sys.argv[1:] if args is None else args)  # for error(): the tokens this parser read
        return super().parse_known_args(args, namespace)

    def parse_args(self, args=None, namespace=None):
        ns, extras = self.parse_known_args(args, namespace)
        if extras:  # report them as the command's, not as `curate`'s
            sub = self._subparsers_action()
            cmd = sub.choices.get(getattr(ns, "command", None)) if sub is not None else None
            (cmd or self)._unrecognized(extras)
        return ns

    def _subparsers_action(self):
        return next((a for a in self._actions if isinstance(a, argparse._SubParsersAction)), None)

    def _own_tokens(self) -> list[str]:
        """The tokens this parser reads itself: up to ``--``, and for ``curate`` those before the command."""
        out = []
        for t in self._argv:
            if t == "--" or (self._subparsers_action() is not None and not t.startswith("-")):
                break
            out.append(t)
        return out

    @staticmethod
    def _is_flag(token: str) -> bool:
        """A token that names a flag (not a value such as -1 or -1,-2,-3,4,5,6)."""
        return re.match(r"--?[A-Za-z][\w-]*(=|$)", token) is not None

    def _known(self, flag: str) -> bool:
        """A flag of this parser, or an abbreviation argparse accepts (or reports as ambiguous itself)."""
        if flag in self._option_string_actions:
            return True
        return flag.startswith("--") and any(o.startswith(flag) for o in self._option_string_actions)

    def _unrecognized(self, tokens: list[str]) -> None:
        flags = [t.split("=", 1)[0] for t in tokens if self._is_flag(t)]
        if not flags:
            self._fail(f"unexpected argument{'s' if len(tokens) > 1 else ''} {' '.join(tokens)}")
        longs = [o for o in self._option_string_actions if o.startswith("--")]
        said = []
        for f in flags:
            near = ["--" + w for w in nearest(f.lstrip("-"), [o[2:] for o in longs])]
            said.append((f, f"did you mean {' or '.join(near)}?" if near else ""))
        if len(said) == 1:
            f, hint = said[0]
            self._fail(f"unrecognized argument {f}" + (f"; {hint}" if hint else ""))
        self._fail("unrecognized arguments " + ", ".join(f + (f" ({hint})" if hint else "") for f, hint in said))

    def _fail(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def error(self, message: str):
        unknown = [t for t in self._own_tokens() if self._is_flag(t) and not self._known(t.split("=", 1)[0])]
        if unknown:  # a mistyped flag explains the errors that follow from it (a value taken for a positional...)
            self._unrecognized(unknown)
        m = re.match(r"argument (\S+): invalid choice: '([^']*)'", message)
        if m and m.group(1) == "COMMAND":
            near = nearest(m.group(2), list(COMMANDS))
            self._fail(f"unknown command {m.group(2)!r}" + (f"; did you mean {' or '.join(near)}?" if near else
                                                             f"; the commands are {', '.join(COMMANDS)}"))
        if m:
            action = self._option_string_actions.get(m.group(1))
            near = nearest(m.group(2), [str(c) for c in (action.choices if action else ()) or ()])
            if near:
                message += f"; did you mean {' or '.join(near)}?"
        if "required: COMMAND" in message:
            message = f"give a command: {', '.join(COMMANDS)}"
        self._fail(message)


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


# ---------------------------------------------------------------------- the parser
COMMANDS = {
    "run": "the whole pipeline: photos -> best subset, report and export",
    "sfm": "calibrate a photo folder (COLMAP) or import known poses into a run folder",
    "select": "choose a subset of a posed pool (a pose file, or a run folder's select stage)",
    "score": "score an existing capture with the energy (no NeRF needed)",
    "occupancy": "where the scene is (the occupancy grid the selection reads) in a run folder",
    "evaluate": "estimate how good a run folder's selection is (trainings with photos held out)",
    "export": "export the chosen subset (COLMAP, transforms.json, list, links)",
    "report": "write RUN/report.json and RUN/report.html",
    "batch": "curate many photo folders (locally or on a Ray cluster), with a summary",
    "simulate": "compare camera placements in a synthetic room (the paper's experiment)",
    "suggest": "where to shoot next: K new camera poses that most improve a run's capture",
}

EXAMPLES = """examples:
  choose 60 photos, compare them with random subsets, export and report:
    curate run photos/ --budget 60 --out runs/room
  from a video, the subset and its export only (no trainings):
    curate run walk.mp4 --budget 15% --no-evaluate --out runs/walk
  choose 40 cameras of a pose file:
    curate select transforms.json --budget 40 --out chosen/

`curate COMMAND --help` lists a command's options with their defaults."""

DESCRIPTIONS = {
    "sfm": "Find and decode the photos (JPEG, PNG, TIFF, camera RAW), flag blurry and near-duplicate ones, and run "
           "COLMAP (pycolmap) offline; or, with --poses, import a COLMAP model or a transforms.json instead. Writes "
           "RUN/sfm/. The photo folder is never written to; an unchanged re-run is skipped.",
    "score": "Score how well a set of cameras covers the scene box: prints the energy and its two parts "
             "(angular uniformity, observation frequency).",
    "select": "Choose a budget of cameras from a posed pool and write transforms.json (image paths relative to it), "
              "selected.txt and selection.json in --out; or, for a run folder, redo its select stage with its "
              "saved options and the flags given.",
    "run": "SfM (or --poses), occupancy, the selection among every registered photo, its export (RUN/export) "
           "and report (RUN/report.html, RUN/report.json). Unless --no-evaluate, an estimate of how good it is: the "
           "same method chooses again with every 14th photo held out, and the same small radiance field is trained "
           "on that choice, on random subsets, on farthest-view sampling and on all photos. The exported photos "
           "are the same with and without the evaluation. Unchanged stages are skipped on a re-run.",
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
                "Gaussian splatting (Kopanas & Drettakis 2023, extended).", epilog=EXAMPLES)
    p.add_argument("--version", action="version", version=f"curate {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(title="commands", dest="command", required=True, metavar="COMMAND",
                           parser_class=_Parser)
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
        s.add_argument("photos", nargs="?", default=None, metavar="PHOTOS",
                       help="the photo folder, a video, or a folder of both. With --poses: the folder of the photos "
                            "the poses describe, each found by its path in the folder, else by its unique file name "
                            "(optional: without it, the pose file's own image paths)")
        s.add_argument("--out", required=True, metavar="RUN", help="the run folder to write (created if new)")
        s.add_argument("--poses", default=None, metavar="POSES",
                       help="known poses instead of SfM: a transforms.json, a COLMAP model folder, a cameras.json, "
                            "or a folder holding one")
    elif name == "score":
        s.add_argument("input", metavar="POSES", help="transforms.json, a COLMAP model folder (binary or text), "
                       "curate's cameras.json, or a run folder")
        s.add_argument("--json", action="store_true", help="print one JSON object")
    elif name == "select":
        s.add_argument("input", metavar="POSES|RUN", help="a pose file (transforms.json, a COLMAP model folder, "
                       "curate's cameras.json) or a run folder")
        s.add_argument("--out", default=None, metavar="DIR",
                       help="where to write the subset of a pose file (a run folder's goes to RUN/select/)")
        s.add_argument("--json", action="store_true", help="print one JSON object")
    elif name == "batch":
        s.add_argument("folders", nargs="*", metavar="FOLDER", help="photo folders (or videos: one capture each)")
        s.add_argument("--list", default=None, metavar="FILE",
                       help="a text file listing folders, one a line (relative to the file)")
        s.add_argument("--out", required=True, metavar="RUNS", help="the batch folder: one run folder per photo folder")
        s.add_argument("--executor", default="local", choices=["local", "ray"],
                       help="local: a process per folder (default); ray: Ray tasks, trainings in parallel "
                            "on the cluster")
        s.add_argument("--ray-address", default=None, metavar="ADDRESS",
                       help="with --executor ray: 'auto' or HOST:PORT of a running cluster (default: a local instance)")
        s.add_argument("--jobs", type=int, default=0, metavar="N",
                       help="folders at once (default: one per core, capped by memory; ray: the cluster's CPUs)")
    elif name == "suggest":
        s.add_argument("run", help="run folder (of `curate run`)")
        s.add_argument("--json", action="store_true", help="print one JSON object")
    elif name == "simulate":
        s.add_argument("--out", required=True, metavar="DIR", help="output folder (report.json, report.html, renders)")
        s.add_argument("--json", action="store_true", help="print one JSON object")
    else:
        s.add_argument("run", metavar="RUN", help="a run folder of `curate run`")
    if name not in ("simulate", "score"):
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


def _negative_values(argv: list[str]) -> list[str]:
    """``--budget -5%`` as ``--budget=-5%``: argparse takes a value that starts with '-' for a flag unless it is
    a plain number, and says only "expected one argument"; joined, the value reaches the option's own check,
    which says what is wrong with it."""
    out: list[str] = []
    for tok in argv:
        if out and re.match(r"^-[\d.]", tok) and out[-1].startswith("--") and "=" not in out[-1] \
                and out[-1] != "--":
            out[-1] = f"{out[-1]}={tok}"
        else:
            out.append(tok)
    return out


def main(argv: list[str] | None = None) -> int:
    argv = _negative_values(list(sys.argv[1:] if argv is None else argv))
    try:
        args = build_parser(_command_of(argv)).parse_args(argv)
    except SystemExit as e:  # --help, --version (0) or a one-line usage error (2)
        return e.code if isinstance(e.code, int) else 2
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    from curate.core import signals
    signals.install(f"curate {args.command}")   # SIGTERM and SIGHUP stop curate as Ctrl-C does
    try:
        return args.func(args)
    except CliError as e:
        print(f"curate {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:       # Ctrl-C, or SIGTERM / SIGHUP (curate.core.signals.Terminated)
        signals.unwound()
        word, code = signals.said(e)
        print(f"curate {args.command}: {word}", file=sys.stderr)
        return code
    except OSError as e:
        if e.errno in (errno.EACCES, errno.EPERM, errno.EROFS) and e.filename:
            print(f"curate {args.command}: error: {denied(e)}", file=sys.stderr)
            return 2
        if e.errno != errno.ENOSPC:
            return _internal_error(args.command, e)
        print(f"curate {args.command}: error: the disk is full: no space left writing {e.filename or 'a file'}; "
              "free some space, then run the same command again (what finished is kept, nothing half-written is "
              "taken for finished)", file=sys.stderr)
        return 2
    except Exception as e:  # noqa: BLE001 - an internal error: one line, the trace in a file
        return _internal_error(args.command, e)


def denied(e: OSError) -> str:
    """What a permission error says: the file, or the folder above it that cannot be entered or read, and why."""
    import os
    p = Path(e.filename)
    if e.errno == errno.EROFS:
        return f"{p}: the file system is read-only: curate cannot write there; choose another --out"
    blocked = next((d for d in reversed(p.parents) if os.path.isdir(d) and not os.access(d, os.R_OK | os.X_OK)), None)
    if blocked is not None:
        return (f"{blocked}: cannot read this folder (permission denied): give it back read permission "
                f"(chmod u+rwx {blocked}), then run again")
    how = "cannot write it" if os.path.exists(p) and os.access(p, os.R_OK) else "cannot read it"
    return f"{p}: permission denied ({how}): give it back the permission (chmod u+rw {p}), then run again"


def _internal_error(command: str, e: BaseException) -> int:
    """An error curate did not expect: one line, the trace in a file; exit status 1."""
    log = _crash_log(e)
    print(f"curate {command}: internal error: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''} "
          f"(full trace in {log})", file=sys.stderr)
    return 1
