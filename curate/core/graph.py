"""The stage graph of ``curate run``, declared once.

Each stage is one :class:`Stage` row of :data:`STAGES`: what it reads, what must have finished before its
command, whether it is cheap, its start line, where it writes, what its key holds and the function that computes
it. A keyed stage (:attr:`Stage.key`) is run by one runner, :func:`curate.core.runner.run_keyed`, which computes its
key, skips it when up to date, clears and begins it, calls its computation and writes its record; the stage's own
code only computes. The pipeline's order, the stage commands' checks and refreshes (:mod:`curate.cli`), the
record's ``inputs`` and the staleness (:mod:`curate.core.stage`) and the batch summary's failed stage are all
derived from this table.

Light: the functions are named as ``module:function`` and imported only when a stage runs.
"""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from curate.config import RunConfig


@dataclasses.dataclass
class RunContext:
    """What every stage function is given: the run's options, its folder and its inputs."""

    cfg: "RunConfig"
    """The run's resolved options (``RUN/run.json``)."""
    run_dir: Path
    """The run folder."""
    force: bool = False
    """Redo the stage even when its key is unchanged."""
    photos: str | Path | None = None
    """The photo folder (or video) the run was given; None when the poses name their own photos."""
    poses: str | Path | None = None
    """Known poses (a transforms.json or a COLMAP model) instead of SfM; None: SfM."""
    executor: Any = None
    """A ``concurrent.futures.Executor`` for the trainings (None: local processes)."""
    timings: list[dict] | None = None
    """The stages' timings so far (the report's table); None when a stage runs on its own."""
    seconds: float | None = None
    """Wall seconds of the whole run so far (the report's), None when a stage runs on its own."""

    def __post_init__(self) -> None:
        self.run_dir = Path(self.run_dir)


@dataclasses.dataclass(frozen=True)
class Stage:
    """One stage of a run folder."""

    name: str
    """The stage's name: its folder in the run folder and its command (``curate NAME RUN``)."""
    runs: str
    """``module:function`` of what it computes: with a :attr:`key`, ``(ctx: RunContext, keyed: Keyed) -> Done``, a
    pure computation that writes its files, called by :func:`curate.core.runner.run_keyed` only when the stage is out
    of date; without one, ``(ctx: RunContext) -> StageResult``, which keys and skips by itself (the evaluation:
    each of its trainings is a stage of its own; SfM: its key hashes the photos it finds; the report: no key)."""
    start: str
    """What its start line says on a terminal (its end line replaces it)."""
    reads: tuple[str, ...] = ()
    """The stages its result is computed from: its record's ``inputs`` (their keys when it ran) and what
    makes it out of date."""
    needs: tuple[str, ...] = ()
    """The stages that must have finished before its command runs on a run folder."""
    cheap: bool = False
    """Seconds, not minutes: a stage command it depends on redoes it, so the run folder stays consistent.
    A stage that trains (occupancy's field, the budget's curve, the evaluation) is only said to be out of date."""
    when: str | None = None
    """``module:function`` of ``(cfg, run_dir) -> bool``: whether the stage runs in this run (None: always)."""
    writes: tuple[str, ...] = ()
    """The entries of the run folder it writes (default: its folder)."""
    record: str = ""
    """The file, relative to the run folder, whose presence says it finished (default ``NAME/stage.json``)."""
    owns: tuple[str, ...] | None = None
    """Glob patterns (relative to its folder; ``*`` crosses ``/``) of every file it writes there: what its
    record lists and all a re-run may remove. A file the user puts into the folder that matches none is kept
    (:func:`curate.core.runfolder.sort_files`); one that matches is refused, never written over."""
    spare: tuple[str, ...] = ()
    """Patterns of files it writes that nothing reads again (a log, COLMAP's database): their absence does not
    make it out of date."""
    key: str | None = None
    """``module:function`` of ``(ctx: RunContext) -> Keyed``: the options its key hashes (and any input's hash)
    beside the keys of :attr:`keyed_on`. None: :attr:`runs` keys and skips by itself."""
    keyed_on: tuple[str, ...] = ()
    """The stages whose keys its key holds (a stage it reads whose result is already in its options, as the
    measured budget is in the selection's, is not keyed on twice)."""
    warns: str = ""
    """A field of its record that a skipped stage repeats as its warning (the export's points warning)."""

    def __post_init__(self) -> None:
        if not self.writes:
            object.__setattr__(self, "writes", (self.name,))
        if not self.record:
            object.__setattr__(self, "record", f"{self.name}/stage.json")

    def applies(self, cfg: "RunConfig", run_dir: str | Path) -> bool:
        """The stage is part of this run (its :attr:`when`)."""
        return self.when is None or bool(_function(self.when)(cfg, Path(run_dir)))

    def finished(self, run_dir: str | Path) -> bool:
        """Its record is in ``run_dir``."""
        return (Path(run_dir) / self.record).is_file()


def _function(ref: str) -> Callable:
    module, name = ref.split(":")
    return getattr(importlib.import_module(module), name)


UNIT_OWNS = ("metrics.json", "renders/*", "field.pt", "train.json", ".progress")
"""What one training of the evaluation writes in its folder (``RUN/evaluate/<unit>``)."""

STAGES: tuple[Stage, ...] = (
    Stage("sfm", "curate.sfm.stage:reconstruct", "photos to cameras",
          owns=("images/*", "sparse/*", "mapper/*", "dense/*", "triangulation/*", "database.db", "database.db-*",
                "vocab_tree.bin", "visual_words.npz", "*_pairs.txt", "retrieval_second_round.txt", "match_*",
                "cameras.json", "transforms.json", "images.json", "normalization.json", "points.npy",
                "points_rgb.npy", "points_error.npy", "colmap.log"),
          spare=("database.db", "database.db-*", "colmap.log", "vocab_tree.bin", "visual_words.npz",
                 "*_pairs.txt", "retrieval_second_round.txt", "match_*")),
    Stage("occupancy", "curate.occupancy.stage:compute", "where the scene is", reads=("sfm",), needs=("sfm",),
          owns=("occupancy.npz", "field.pt", "train.json"), key="curate.occupancy.stage:key", keyed_on=("sfm",)),
    Stage("budget", "curate.evaluate.budget:measure", "measuring how many photos this capture needs",
          reads=("occupancy",), needs=("sfm", "occupancy"), when="curate.evaluate.budget:wanted",
          owns=("budget.json",), key="curate.evaluate.budget:key", keyed_on=("occupancy", "sfm")),
    Stage("select", "curate.select.stage:choose", "choosing photos", reads=("occupancy", "budget"),
          needs=("sfm", "occupancy"), cheap=True, owns=("selection.json", "nodes.npz"),
          key="curate.select.stage:key", keyed_on=("occupancy",)),
    Stage("evaluate", "curate.evaluate.stage:evaluate", "training on the subsets", reads=("select",),
          needs=("sfm", "occupancy", "select"), when="curate.evaluate.stage:wanted",
          owns=("summary.json", "gt/*") + tuple(f"*/{g}" for g in UNIT_OWNS)),
    Stage("export", "curate.export.stage:export", "writing the export", reads=("select",),
          needs=("sfm", "select"), cheap=True, key="curate.export.stage:key", keyed_on=("select",),
          warns="export_warning", owns=("images/*", "images_2/*", "images_4/*", "images_8/*", "sparse/0/cameras.bin",
                            "sparse/0/images.bin", "sparse/0/points3D.bin", "sparse/0/rigs.bin", "sparse/0/frames.bin",
                            "distorted/images/*", "distorted/sparse/0/*.bin", ".curate-undistort-*",
                            "transforms.json", "images.txt", "export.json", "sparse_pc.ply")),
    Stage("report", "curate.report.stage:write_report", "writing the report", needs=("sfm", "occupancy", "select"),
          cheap=True, writes=("report.json", "report.html"), record="report.json"),
)
"""The stages of ``curate run``, in order."""

NAMES = tuple(s.name for s in STAGES)
"""The stages' names, in order."""

BY_NAME = {s.name: s for s in STAGES}
"""Each stage by its name."""

READS = {s.name: s.reads for s in STAGES if s.reads}
"""{stage: the stages it reads}, for the stages that read any."""

RUN_WRITES = ("run.json", "parts") + tuple(w for s in STAGES for w in s.writes)
"""Top-level entries of a run folder that ``curate run`` writes (``parts``: the other models of a capture that
split, each a run folder of its own)."""


def downstream(name: str) -> tuple[str, ...]:
    """The stages computed, directly or not, from ``name``'s result, in order."""
    out: list[str] = []
    for s in STAGES:
        if any(r == name or r in out for r in s.reads):
            out.append(s.name)
    return tuple(out)


def redone_after(name: str) -> tuple[str, ...]:
    """The stages a stage command redoes after ``name``: the cheap ones computed from it (the report, which
    reads every stage, is written last by the command itself)."""
    return tuple(s for s in downstream(name) if BY_NAME[s].cheap)


def first_unfinished(cfg: "RunConfig", run_dir: str | Path) -> str:
    """The first stage of this run without a finished record ('report' when all the others have one)."""
    for s in STAGES:
        if s.applies(cfg, run_dir) and not s.finished(run_dir):
            return s.name
    return "report"
