"""The ``curate`` parser: every command listed, the options of the chosen command only (``curate --help`` answers
at once), and one-line errors that name the nearest flag, command or choice.
"""

from __future__ import annotations

import argparse
import difflib
import re
import sys

from curate import __version__
from curate.cli.commands import (cmd_batch, cmd_run, cmd_score, cmd_select, cmd_sfm, cmd_simulate, cmd_stage,
                                 cmd_suggest)
from curate.cli.flags import COMMAND_OPTS
from curate.core.options import HelpFormatter, add_options


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


_ADOPT = "use --out although it is a non-empty folder curate did not create (its files are never touched)"


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
