"""Every option of ``curate run`` in one dataclass tree: :class:`RunConfig`.

The command line is built from these dataclasses (:mod:`curate.cli`, :mod:`curate.core.options`):
each default and each help text lives here or in the stage configs it nests, nowhere else.
A run saves its resolved config in ``RUN/run.json``; every stage re-run starts from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from curate.core.budget import parse_budget
from curate.evaluate.config import EvalConfig
from curate.export.config import ExportConfig
from curate.occupancy.config import OccupancyConfig, RefineConfig
from curate.select.config import SelectConfig
from curate.sfm.config import SfmConfig


@dataclass
class RunConfig:
    """Every option of ``curate run``."""

    budget: str = "default"
    """How many photos to choose: a count (60), a share of the pool (15%), auto: the fewest
    predicted, from the poses alone, to come within --budget-tolerance of all photos, or default:
    15% of a walk-through, auto on an object capture (which needs most of its photos)."""
    budget_tolerance: float = 0.5
    """With --budget auto: how much held-out PSNR, in dB, the chosen photos may lose against all
    photos (as predicted).

    The predictor's measured error is in docs/investigations/selection.md (``budget_auto``)."""
    budget_check: bool = True
    """With --budget auto and the evaluation: train the same field on two more budgets of the
    evaluation's split (half and twice its own) to measure how the loss falls on this capture, and
    advise a budget from that beside the prediction (two more trainings).

    curate.evaluate.check fits the measured losses; docs/evaluation.md#how-many."""
    sfm: SfmConfig = field(default_factory=SfmConfig)
    """SfM stage options."""
    occupancy: OccupancyConfig = field(default_factory=OccupancyConfig)
    """Occupancy from the sparse points; ``occupancy.res`` is also the selection's node grid."""
    refine: RefineConfig = field(default_factory=RefineConfig)
    """Refinement of the occupancy by the pool field's density."""
    surface_band: int = 1
    """Selection nodes: the refined occupied set's surface, widened by this many voxels on each side."""
    box: tuple[float, float, float, float, float, float] | None = None
    """Scene box x0,y0,z0,x1,y1,z1 of the grid the selection is scored on, in the poses' frame
    (default: from the sparse points and the cameras)."""
    select: SelectConfig = field(default_factory=SelectConfig)
    """Selection method and energy."""
    evaluate: EvalConfig = field(default_factory=EvalConfig)
    """Evaluation protocol (hold-out split, trainings)."""
    run_evaluation: bool = True
    """Train and score the subsets (off: selection, report and export only)."""
    export: ExportConfig = field(default_factory=ExportConfig)
    """How the chosen subset is exported (``RUN/export``)."""

    def __post_init__(self) -> None:
        try:                                # the one check of the budget's form (its fit: the run's plan)
            b = parse_budget(str(self.budget))
        except ValueError:
            raise ValueError(f"--budget wants a count (200), a percentage (15%), 'auto' or 'default', "
                             f"got {self.budget!r}") from None
        if isinstance(b, int) and b < 2:
            raise ValueError(f"--budget {self.budget}: choose at least 2 images")
        if not (math.isfinite(self.budget_tolerance) and self.budget_tolerance > 0):
            raise ValueError(f"--budget-tolerance must be > 0 dB, got {self.budget_tolerance}")
        if self.surface_band < 0:
            raise ValueError(f"surface band must be >= 0, got {self.surface_band}")
        if self.box is not None:
            b = tuple(float(v) for v in self.box)
            if len(b) != 6 or not all(math.isfinite(v) for v in b):
                raise ValueError(f"--box wants six finite numbers x0,y0,z0,x1,y1,z1, got {self.box!r}")
            if any(b[i + 3] <= b[i] for i in range(3)):
                raise ValueError("--box: each max (x1,y1,z1) must be > its min (x0,y0,z0)")
            self.box = b


OLD_DEFAULTS = {("evaluate", "methods"): ["selection", "random", "fvs", "all"], ("evaluate", "random_seeds"): 3,
                ("evaluate", "iters"): 800, ("evaluate", "max_side"): 240,
                ("evaluate", "field", "batch_rays"): 4096, ("evaluate", "field", "n_inner"): 64,
                ("evaluate", "field", "n_outer"): 32, ("evaluate", "field", "trans_thresh"): 0.001}
"""Options whose default changed in curate 0.3 (the evaluation over folds, with every n-th frame as a rival,
one random draw per fold and a cheaper field), with their 0.1-0.2 default (a key path into the config)."""


def upgrade_config(d: dict, version: str | None) -> dict:
    """A ``run.json`` config ``d`` written by curate ``version``: before 0.3, an option still at that version's
    default (:data:`OLD_DEFAULTS`) takes today's, so a stage command on an older run evaluates as a new run
    would; an option the user had changed is kept."""
    import copy
    d = copy.deepcopy(d)
    if "export_mode" in d:      # before 0.4: the export's mode alone, now one of ExportConfig's fields
        d.setdefault("export", {})["mode"] = d.pop("export_mode")
    try:
        major, minor = (int(x) for x in str(version).split(".")[:2])
    except ValueError:
        return d
    if (major, minor) >= (0, 3):
        return d
    from curate.core.stage import config_dict
    today = config_dict(RunConfig())
    for (*path, name), old in OLD_DEFAULTS.items():
        sub, now = d, today
        for k in path:
            sub = sub.get(k) if isinstance(sub, dict) else None
            now = now[k]
        if isinstance(sub, dict) and sub.get(name) == old:
            sub[name] = now[name]       # today's default, also inside a nested option (the field's)
    return d
