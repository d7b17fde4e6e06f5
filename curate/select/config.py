"""The selection's options: the method and each method's parameters (a leaf module: imports nothing heavy, so that
``curate COMMAND --help`` stays light)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from curate.select.bins import Binning, DirectionBins
from curate.select.methods import DEFAULT_METHOD, PATH_WEIGHTS, REGISTRY

GAMMA_MAX = 20.0
"""Largest ``EnergyConfig.gamma``. The greedy's exact incremental form works on view counts
``n ** gamma`` (n up to the pool size), which must stay finite: 10^6 cameras ** 20 = 1e120. Beyond
it the frequency term is 0 in practice anyway (a node seen by half the cameras scores 0.5 ** 20 = 1e-6)."""


@dataclass(frozen=True)
class EnergyConfig:
    """Parameters of the paper's energy."""

    gamma: float = 0.05
    """The paper's gamma: the exponent on how often each point is seen.

    The exponent on the observation frequency O_f (authors' code: 0.05), in [0, ``GAMMA_MAX``]."""
    n_theta: int = 5
    """Direction bins along theta, the angle from the scene's +z axis (authors' code: 5)."""
    n_phi: int = 10
    """Direction bins along the azimuth phi = atan2(y, x) (authors' code: 10)."""
    binning: Binning = "paper"
    """"paper": uniform in theta, solid-angle shares; "equal-area": uniform in cos(theta)."""

    def __post_init__(self) -> None:
        if not (0 <= self.gamma <= GAMMA_MAX):
            raise ValueError(f"--gamma must be in [0, {GAMMA_MAX:g}], got {self.gamma}")
        DirectionBins(self.n_theta, self.n_phi, self.binning)  # validates

    @property
    def bins(self) -> DirectionBins:
        return DirectionBins(self.n_theta, self.n_phi, self.binning)


@dataclass(frozen=True)
class MedoidsConfig:
    """Method "medoids": k-medoids of the pool's views."""

    depth: float | None = None
    """Look-at depth D in world units for every camera (None: each camera's median depth of
    the nodes it observes)."""
    max_iters: int = 100
    """Voronoi iterations at most (it usually stops in under 20)."""
    path_weights: bool = PATH_WEIGHTS
    """View medoids: weigh each photo by the stretch of the capture path it stands for, so a
    stretch walked fast (or with dropped frames) counts as much as one where the walker
    lingered; ignored, with a note, when the photos are not in capture order (name order).

    Each view's weight is half the view distance to the previous plus to the next view in name
    order (capture order for numbered video frames), capped at ``PATH_CAP`` times the median
    step, mean 1: the mean is then taken along the path, not over the frames. Ignored (uniform
    weights, a warning) when the views are not in path order (:func:`path_weights`)."""

    def __post_init__(self) -> None:
        if self.depth is not None and not (math.isfinite(self.depth) and self.depth > 0):
            raise ValueError(f"depth must be finite and > 0, got {self.depth}")
        if self.max_iters < 0:
            raise ValueError(f"max_iters must be >= 0, got {self.max_iters}")


@dataclass(frozen=True)
class PathConfig:
    """Method "path": frames evenly spaced along the capture path."""

    look_scale: float = 0.5
    """Scale of every camera's look-at depth in the view distance along the path (1: view
    medoids' distance; below 1 a turn of the head counts for less against a step)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.look_scale) and self.look_scale > 0):
            raise ValueError(f"look_scale must be finite and > 0, got {self.look_scale}")


@dataclass(frozen=True)
class SelectConfig:
    """How to choose a subset."""

    method: str = DEFAULT_METHOD
    """How to choose the photos: a key of :data:`curate.select.methods.REGISTRY`, where each method
    has its label, its one line of ``--help`` and its function ("auto", the default, is resolved by
    :func:`resolve_method`)."""
    energy: EnergyConfig = field(default_factory=EnergyConfig)
    """Energy parameters (method "energy", and the energy reported for every method)."""
    seed: int = 0
    """Seed of the random subsets (method random)."""
    device: str | None = None
    """Device that tests which cameras see which points, e.g. cpu or cuda:0 (default: CUDA when
    available, else the CPU).

    A torch device name; None picks one."""
    medoids: MedoidsConfig = field(default_factory=MedoidsConfig)
    """Method "medoids": its look-at depth and iterations."""
    path: PathConfig = field(default_factory=PathConfig)
    """Method "path": the scale of its look-at depths."""

    def __post_init__(self) -> None:
        if self.method not in REGISTRY:
            raise ValueError(f"--method must be one of {', '.join(REGISTRY)}, got {self.method!r}")
