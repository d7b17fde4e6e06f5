"""Options of the evaluation (:class:`EvalConfig`). A leaf module: importing it imports no torch."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from dataclasses import field as _field

from curate.field.config import TRAINERS, FieldConfig, SplatConfig, Trainer

EVAL_METHODS = ("selection", "random", "fvs", "stride", "all")
"""What the evaluation can train: the selection (whatever its method), its rivals of the same size (random
subsets, farthest-view sampling, every n-th frame) and all photos left (the ceiling)."""

RIVALS = ("random", "fvs", "stride")
"""The subsets the selection is compared with, paired per held-out photo."""


def evaluation_field() -> FieldConfig:
    """The evaluation's field: :class:`FieldConfig` with 2,048 rays an iteration (was 4,096), 48 samples a ray in
    the box and 24 outside at the finest grid (was 64 and 32), and no transmittance pre-pass (``trans_thresh`` 0):
    2.2 times fewer CPU seconds a training on the office walk, its per-photo differences correlated 0.98-1.00
    with the field's before on four real captures (docs/evaluation.md#cheaper-field-2048). The occupancy's refining
    field keeps :class:`FieldConfig`'s own settings."""
    return FieldConfig(batch_rays=2048, n_inner=48, n_outer=24, trans_thresh=0.0)


@dataclass
class EvalConfig:
    """How the exported selection is judged: hold-out folds, the rivals, the field trained on each subset."""

    holdout_every: int = 14
    """Each fold holds out every n-th registered photo, from its own offset: over n folds every photo is held
    out once."""
    folds: int = 0
    """Hold-out folds to train: 0 adds folds until the verdict is decided, every photo has been held out or
    --eval-minutes is spent; N trains N folds (at most --holdout-every), whatever they show."""
    minutes: float = 15.0
    """Time for the evaluation, in minutes: no fold is started that is not expected to finish within it (the
    first two always run).

    Counted from the start of this evaluation; trainings finished by an earlier one are reused and cost
    nothing, so a second `curate evaluate RUN --eval-minutes M` narrows an undecided verdict."""
    margin_db: float = 0.3
    """The selection and a rival count as level when the interval of their difference lies within this many
    dB of 0."""
    resolution_db: float = 0.5
    """A rival is trained no more once the interval of its difference is at most this many dB wide on each side,
    even where it still holds 0 (the verdict: not told apart, measured to within this many dB); 0 trains on until
    the interval excludes 0 or lies within --equivalence-db, or the folds or the time run out.

    0.5 dB: the office walk's verdict then took 5 folds (461 CPU seconds) where it took 13 (998), FVS and every
    n-th frame measured to +-0.47 and +-0.37 dB (docs/evaluation.md#resolved)."""
    max_side: int = 160
    """Training and test images are resized so that their longer side is at most this (pixels).

    160 px and 400 iterations: the cheapest field measured whose per-photo differences agree with 240 px and
    800 iterations (correlation 0.93-0.99 on real captures; docs/evaluation.md#cheaper-field)."""
    iters: int = 400
    """Training iterations per subset (the same for every subset)."""
    time_budget_s: float | None = None
    """Optional cap on each training's seconds (None: iterations only, independent of machine load)."""
    random_seeds: int = 1
    """Random subsets of the selection's size drawn in each fold (each fold draws its own)."""
    train_seed: int = 0
    """Seed of every field training (weights, ray batches)."""
    methods: tuple[str, ...] = EVAL_METHODS
    """Which subsets to train: the selection (whatever its method), 'random', 'fvs', 'stride' (every n-th
    frame: only for photos in capture order), 'all'."""
    workers: int = 0
    """Trainings in parallel (0: one per CPU core, capped by memory; 1 on CUDA)."""
    field: FieldConfig = field(default_factory=evaluation_field)
    """The radiance field and its training settings (:func:`evaluation_field`)."""
    trainer: Trainer = "field"
    """What is trained on each subset: 'field' (curate's radiance field at --eval-size, on CUDA when torch sees
    one, else the CPU) or 'gsplat' (3D Gaussian splatting at the capture's resolution, for users who train 3DGS:
    needs CUDA and the gsplat package, ``pip install 'curate[gsplat]'``)."""
    splat: SplatConfig = _field(default_factory=SplatConfig)
    """3D Gaussian splatting's settings (``trainer`` 'gsplat')."""

    def __post_init__(self) -> None:
        checks = (("--holdout-every", self.holdout_every, 2), ("--iters", self.iters, 1),
                  ("--eval-size", self.max_side, 16), ("--random-seeds", self.random_seeds, 0),
                  ("--workers", self.workers, 0), ("--folds", self.folds, 0))
        for flag, v, lo in checks:
            if not isinstance(v, int) or isinstance(v, bool) or v < lo:
                raise ValueError(f"{flag} must be an integer >= {lo}, got {v!r}")
        for flag, v in (("--eval-minutes", self.minutes), ("--equivalence-db", self.margin_db)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"{flag} must be a number > 0, got {v!r}")
        v = self.resolution_db
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            raise ValueError(f"--resolution-db must be a number >= 0, got {v!r}")
        if self.time_budget_s is not None and not (math.isfinite(self.time_budget_s) and self.time_budget_s > 0):
            raise ValueError(f"time_budget_s must be > 0 or None, got {self.time_budget_s}")
        if self.trainer not in TRAINERS:
            raise ValueError(f"--trainer must be one of {', '.join(TRAINERS)}, got {self.trainer!r}")
        unknown = set(self.methods) - set(EVAL_METHODS)
        if unknown:
            raise ValueError(f"unknown evaluation methods {sorted(unknown)} (known: {', '.join(EVAL_METHODS)})")

    def training(self) -> dict:
        """What a trained unit's result depends on (its stage key hashes this with its subset and held-out
        photos): not the folds, the time or the rivals, so a unit is reused whatever those become. A field's
        training is the same whatever device it runs on (its key names no device)."""
        if self.trainer == "gsplat":
            return {"trainer": "gsplat", "splat": self.splat, "train_seed": self.train_seed}
        return {"max_side": self.max_side, "iters": self.iters, "time_budget_s": self.time_budget_s,
                "train_seed": self.train_seed, "field": replace(self.field, device="auto")}

    def train_steps(self) -> int:
        """Steps of one training: --iters for the field, the splat trainer's own for gsplat."""
        return self.splat.steps if self.trainer == "gsplat" else self.iters

    def train_side(self) -> int:
        """The longer side, in pixels, that subsets are trained and scored at: --eval-size for the field, the
        splat trainer's own (0: the photos' own size) for gsplat."""
        if self.trainer == "gsplat":
            return self.splat.max_side or 1 << 30
        return self.max_side
