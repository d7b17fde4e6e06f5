"""Options of ``curate suggest`` (:class:`SuggestConfig`); the CLI binds its flags to these fields."""

from __future__ import annotations

import math
from dataclasses import dataclass, field as dc_field

from curate.select.config import EnergyConfig
from curate.suggest.choices import FIELD_MODES, NODE_MODES, FieldMode, NodeMode  # noqa: F401  (re-exported)


MAX_ADD = 200
"""The most poses ``--add`` may ask for (each one scores ``--candidates`` poses: about a second each)."""


@dataclass(frozen=True)
class SuggestConfig:
    """How ``curate suggest`` proposes new camera poses for a run folder."""

    add: int = 8
    """Camera poses to suggest (K), placed one at a time, each where it raises the energy of the capture
    plus the poses placed before it the most."""
    metres: bool = False
    """The poses are in metres (e.g. from a phone's AR session, a survey, or a rig you calibrated): distances
    are given in metres and walking steps. Off: in the capture's own units (SfM does not know the scale, and
    a transforms.json is often rescaled), with the captured path's length for scale."""
    n_candidates: int = 1000
    """Feasible random poses drawn and scored for each placed camera (Algorithm 1 of the paper: 1000)."""
    nodes: NodeMode = "surface"
    """Nodes the energy is summed over: 'surface' (the run's selection nodes, the occupied surface band) or
    'surface+frontier' (also the unobserved voxels next to observed free space: the edges of what the capture
    has seen)."""
    clearance_percentile: float = 10.0
    """A suggested camera keeps at least the distance to the nearest occupied node that this percentile of the
    capture's own cameras keep (never less than one voxel, never more than a quarter of the capture's typical
    viewing distance): no closer to things than the user went."""
    view_percentile: float = 10.0
    """Nothing occupied may lie in a suggested view nearer than this percentile of the capture's own nearest
    seen surfaces (never less than one voxel, never more than half the capture's typical viewing distance)."""
    height_percentiles: tuple[float, float] = (5.0, 95.0)
    """Suggested camera heights (along the capture's up direction) stay within this percentile range of the
    capture's camera heights: heights a hand-held camera takes."""
    pitch_percentiles: tuple[float, float] = (5.0, 95.0)
    """Suggested pitches (up/down tilt) stay within this percentile range of the capture's pitches."""
    probe: tuple[int, int] = (32, 24)
    """Rays (columns, rows) each capture camera casts through the occupancy grid to find the free space it
    observed."""
    field: FieldMode = "auto"
    """Radiance field for the preview renders: 'auto' (the run's field when it has one; a field is trained only
    when the run's occupancy cannot place cameras, e.g. imported poses without points), 'train' (the run's
    field, else train one: previews for every run), 'none' (never train)."""
    field_iters: int = 600
    """Iterations of the field `curate suggest` trains when the run has none (kept in the run folder)."""
    field_side: int = 160
    """Longer image side, in pixels, the field is trained at."""
    preview_side: int = 240
    """Longer side, in pixels, of each suggestion's preview render."""
    energy: EnergyConfig = dc_field(default_factory=EnergyConfig)
    """The paper's energy (its direction bins and gamma)."""
    seed: int = 0
    """Seed of the candidate draws (and of the field's training)."""

    def __post_init__(self) -> None:
        if not isinstance(self.add, int) or isinstance(self.add, bool) or not 1 <= self.add <= MAX_ADD:
            raise ValueError(f"--add must be an integer from 1 to {MAX_ADD}, got {self.add!r} (each pose is placed "
                             f"by scoring --candidates poses: more than {MAX_ADD} is a new capture, not a re-shoot; "
                             "shoot the first ones and run curate again)")
        if not isinstance(self.n_candidates, int) or self.n_candidates < 1:
            raise ValueError(f"--candidates must be an integer >= 1, got {self.n_candidates!r}")
        if self.nodes not in NODE_MODES:
            raise ValueError(f"nodes must be one of {NODE_MODES}, got {self.nodes!r}")
        if self.field not in FIELD_MODES:
            raise ValueError(f"--field must be one of {FIELD_MODES}, got {self.field!r}")
        for name in ("clearance_percentile", "view_percentile"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 <= v <= 100):
                raise ValueError(f"{name} must be in [0, 100], got {v}")
        for name in ("height_percentiles", "pitch_percentiles"):
            lo, hi = getattr(self, name)
            if not (0 <= lo <= hi <= 100):
                raise ValueError(f"{name} must be (lo, hi) with 0 <= lo <= hi <= 100, got {(lo, hi)}")
        if len(self.probe) != 2 or min(self.probe) < 1:
            raise ValueError(f"probe must be two positive counts, got {self.probe}")
        for flag, v, lo in (("--field-iters", self.field_iters, 1), ("--field-size", self.field_side, 16),
                            ("--preview-size", self.preview_side, 16)):
            if not isinstance(v, int) or v < lo:
                raise ValueError(f"{flag} must be an integer >= {lo}, got {v!r}")
