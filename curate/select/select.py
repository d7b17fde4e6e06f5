"""Selection of a subset of a camera pool: the energy (greedy) and the baselines behind one call.

:func:`select` takes a pool of cameras, a node grid, a budget and a
:class:`SelectConfig`, and returns a :class:`Selection`. Scoring an existing set is
:func:`score_cameras`.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass, field, replace

from curate.core.cameras import Cameras
from curate.select.energy import EnergyConfig, EnergyTerms
from curate.core.grid import NodeGrid
from curate.select.medoids import MedoidsConfig
from curate.select.path import PathConfig, path_select
from curate.select.methods import DEFAULT_METHOD, METHODS, OBJECT_METHOD, WALK_METHOD  # noqa: F401  (METHODS re-exported)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SelectConfig:
    """How to choose a subset."""

    method: str = DEFAULT_METHOD
    """One of "auto" (the default, chosen by the harness: ``WALK_METHOD`` for a walk-through,
    ``OBJECT_METHOD`` for an object capture, see :func:`capture_kind`), "path" (frames evenly
    spaced along the capture path by view change, :mod:`curate.select.path`; view medoids when
    the photos are not in capture order), "medoids" (k-medoids of the
    pool's views, :mod:`curate.select.medoids`), "energy" (the paper: greedy on its energy),
    "random", "fvs" (farthest-view sampling), "stride" (every n-th camera in name order: every
    n-th frame of a video)."""
    energy: EnergyConfig = field(default_factory=EnergyConfig)
    """Energy parameters (method "energy", and the energy reported for every method)."""
    seed: int = 0
    """Seed of the random baseline."""
    device: str | None = None
    """Torch device for the visibility test (None: CUDA when available, else CPU)."""
    medoids: MedoidsConfig = field(default_factory=MedoidsConfig)
    """Method "medoids": its look-at depth and iterations."""
    path: PathConfig = field(default_factory=PathConfig)
    """Method "path": the scale of its look-at depths."""

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")


@dataclass
class Selection:
    """A chosen subset.

    Attributes:
        method: the method's name.
        chosen: pool indices in the order chosen (``initial`` excluded).
        initial: pool indices taken as already chosen.
        energy: [len(chosen)] E of ``initial + chosen[:i+1]`` after each step.
        angular, frequency: the two parts of ``energy`` after each step.
        seconds: wall time of the selection (visibility included).
    """

    method: str
    chosen: list[int]
    initial: list[int] = field(default_factory=list)
    energy: list[float] = field(default_factory=list)
    angular: list[float] = field(default_factory=list)
    frequency: list[float] = field(default_factory=list)
    seconds: float = 0.0
    objective: list[float] = field(default_factory=list)
    """Methods "coverage*": the coverage F after each step; "medoids": the mean view distance
    to the nearest chosen view after each iteration (empty for the others)."""

    note: str = ""
    """Method "auto": which method it ran and why (``method`` is the one it ran); view medoids:
    an option that did not apply (path weights on photos not in capture order)."""

    def to_dict(self) -> dict:
        return {"method": self.method, "chosen": self.chosen, "initial": self.initial, "energy": self.energy,
                "angular": self.angular, "frequency": self.frequency, "seconds": self.seconds,
                **({"objective": self.objective} if self.objective else {}),
                **({"note": self.note} if self.note else {})}


OBJECT_MAX_ANGLE_DEG = 20.0
""":func:`capture_kind`: an object capture when the median camera looks within this angle of
the point nearest all viewing axes (measured: object sets 0.6-7.2 deg, walks 55-56 deg)."""


def capture_kind(cams: Cameras) -> tuple[str, float]:
    """("object" | "walk", median angle in degrees) for a pool of cameras.

    The point p nearest every viewing axis (least squares, ``sum_i (I - v_i v_i^T)(p - c_i) = 0``)
    is where an object capture's cameras look; the angle between each camera's viewing
    direction and the direction from its centre to p is then small for almost every camera.
    On a walk-through the axes do not meet: the angles are large. Near-parallel axes
    (a forward-facing capture with little convergence) count as a walk; a forward-facing
    capture whose axes converge on the subject counts as an object capture. Fewer than 3 cameras, or axes all parallel, count as a walk.
    """
    import numpy as np
    if len(cams) < 3:
        return "walk", 180.0
    c, v = cams.centres, cams.view_dirs                       # [K, 3], [K, 3]
    P = np.eye(3)[None] - v[:, :, None] * v[:, None, :]        # [K, 3, 3] projectors off each axis
    A, b = P.sum(0), np.einsum("kij,kj->i", P, c)
    if np.linalg.eigvalsh(A / len(c))[0] < 1e-3:               # (near) parallel axes: no meeting point
        return "walk", 180.0
    p = np.linalg.solve(A, b)
    to = p - c
    n = np.linalg.norm(to, axis=1)
    cos = np.sum(to * v, axis=1) / np.maximum(n, 1e-300)
    ang = float(np.median(np.degrees(np.arccos(np.clip(np.where(n > 0, cos, -1.0), -1.0, 1.0)))))
    return ("object" if ang < OBJECT_MAX_ANGLE_DEG else "walk"), ang


def resolve_method(cams: Cameras, method: str) -> tuple[str, str]:
    """(method that runs, note) for ``method`` on ``cams``: "auto" becomes ``OBJECT_METHOD``
    on an object capture and ``WALK_METHOD`` on a walk (:func:`capture_kind`), with a note
    saying why; any other method runs as given, with no note."""
    if method != "auto":
        return method, ""
    kind, ang = capture_kind(cams)
    method = OBJECT_METHOD if kind == "object" else WALK_METHOD
    return method, (f"auto: {'an object capture' if kind == 'object' else 'a walk-through'} (median angle to "
                    f"the viewing axes' meeting point {ang:.1f} deg) -> {method}")


def select(cams: Cameras, grid: NodeGrid, budget: int, cfg: SelectConfig = SelectConfig(), initial=(),
           progress: bool = False, index=None) -> Selection:
    """Choose ``budget`` more cameras of the pool ``cams`` (fewer if it runs out).

    The energy curve is filled for every method (for baselines, it is evaluated after
    the choice, so they can be compared on the same footing). ``index``: the pair index
    of ``cams`` over the grid's nodes with ``cfg.energy.bins`` when the caller already
    built it (its time is then not in ``Selection.seconds``).
    """
    from curate.select.baselines import farthest_view, random_subset, stride_subset
    from curate.select.greedy import greedy_select, trace_energy
    from curate.select.visibility import build_pair_index

    t0 = time.perf_counter()
    initial = [int(k) for k in dict.fromkeys(initial)]
    method, note = resolve_method(cams, cfg.method)
    if note:
        cfg = replace(cfg, method=method)
        log.info("select %s", note)
    if index is None:
        index = build_pair_index(cams, grid.nodes(), cfg.energy.bins, device=cfg.device, progress=progress)
    if cfg.method == "energy" and index.n_pairs == 0:
        # no camera sees any node: every subset scores E = 0 and the greedy would return the first
        # cameras; a loud, recorded fallback instead
        fallback = ("the energy sees no node (no camera observes the scene's nodes: check --box and the "
                    "occupancy): fell back to farthest-view sampling")
        log.warning("select: %s", fallback)
        note = "; ".join(x for x in (note, fallback) if x)
        cfg = replace(cfg, method="fvs")
    if cfg.method == "energy":
        tr = greedy_select(index, budget, cfg.energy, initial, progress=progress)
        sel = Selection("energy", tr.chosen, initial, tr.energy, tr.angular, tr.frequency)
    elif cfg.method == "path" and (chosen := path_select(cams, budget, cfg.path, initial, grid.nodes(), index)) is not None:
        e, a, f = trace_energy(index, cfg.energy, initial, chosen)
        sel = Selection("path", chosen, initial, e, a, f)
    elif cfg.method in ("medoids", "path"):
        from curate.select.medoids import PathOrderWarning, medoids_select
        if cfg.method == "path":                                      # not in capture order: no path
            fallback = ("path: the photos are not in capture order (or too few), so there is no path to "
                        "space frames along: fell back to view medoids")
            log.info("select %s", fallback)
            note = "; ".join(x for x in (note, fallback) if x)
            cfg = replace(cfg, method="medoids")
        with warnings.catch_warnings(record=True) as caught:          # path weights ignored: a note
            warnings.simplefilter("always")
            chosen, cost = medoids_select(cams, budget, cfg.medoids, initial, grid.nodes(), index)
        for w in caught:
            if issubclass(w.category, PathOrderWarning):
                log.info("select %s", w.message)
                note = "; ".join(x for x in (note, str(w.message)) if x)
            else:                                                     # any other warning: passed on
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        e, a, f = trace_energy(index, cfg.energy, initial, chosen)
        sel = Selection(cfg.method, chosen, initial, e, a, f, objective=cost)
    else:
        if cfg.method == "random":
            chosen = random_subset(len(cams), budget, cfg.seed, initial)
        elif cfg.method == "fvs":
            chosen = farthest_view(cams, budget, initial)
        elif cfg.method == "stride":
            chosen = stride_subset(len(cams), budget, initial)
        else:
            raise ValueError(f"unknown selection method {cfg.method!r}")
        e, a, f = trace_energy(index, cfg.energy, initial, chosen)
        sel = Selection(cfg.method, chosen, initial, e, a, f)
    sel.seconds = time.perf_counter() - t0
    sel.note = note
    log.info("select %s: %d cameras of %d in %.2fs", cfg.method, len(sel.chosen), len(cams), sel.seconds)
    return sel


def score_cameras(cams: Cameras, grid: NodeGrid, cfg: EnergyConfig = EnergyConfig(), per_node: bool = False,
                  device: str | None = None) -> EnergyTerms:
    """E of the whole set ``cams`` over the grid's active nodes."""
    from curate.select.energy import energy_from_hist, histogram
    from curate.select.visibility import build_pair_index

    index = build_pair_index(cams, grid.nodes(), cfg.bins, device=device)
    return energy_from_hist(histogram(index), len(cams), cfg, per_node)

