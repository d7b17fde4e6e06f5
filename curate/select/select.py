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
from curate.core.grid import NodeGrid
from curate.select.config import EnergyConfig, SelectConfig
from curate.select.energy import EnergyTerms
from curate.select.methods import get_method, resolve_method
from curate.select.path import path_select

log = logging.getLogger(__name__)


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


def select(cams: Cameras, grid: NodeGrid, budget: int, cfg: SelectConfig = SelectConfig(), initial=(),
           progress: bool = False, index=None) -> Selection:
    """Choose ``budget`` more cameras of the pool ``cams`` (fewer if it runs out).

    "auto" is resolved first (:func:`resolve_method`); the method then runs through its entry
    in :data:`curate.select.methods.REGISTRY`. The energy curve is filled for every method
    (for baselines, it is evaluated after the choice, so they can be compared on the same
    footing). ``index``: the pair index of ``cams`` over the grid's nodes with
    ``cfg.energy.bins`` when the caller already built it (its time is then not in
    ``Selection.seconds``).
    """
    from curate.select.visibility import build_pair_index

    t0 = time.perf_counter()
    initial = [int(k) for k in dict.fromkeys(initial)]
    method, note = resolve_method(cams, cfg.method)
    if note:
        cfg = replace(cfg, method=method)
        log.info("select %s", note)
    if index is None:
        index = build_pair_index(cams, grid.nodes(), cfg.energy.bins, device=cfg.device, progress=progress)
    sel = get_method(cfg.method).run(cams, grid, budget, cfg, initial, index, progress)
    sel.seconds = time.perf_counter() - t0
    sel.note = _join(note, sel.note)
    log.info("select %s: %d cameras of %d in %.2fs", sel.method, len(sel.chosen), len(cams), sel.seconds)
    return sel


def _join(*notes: str) -> str:
    return "; ".join(n for n in notes if n)


# ---------------------------------------------------------------------- the methods (curate.select.methods.REGISTRY)
# Each: (cams, grid, budget, cfg, initial, index, progress) -> Selection; a fallback it takes goes into its note.

def _traced(method: str, chosen: list[int], initial: list[int], index, cfg: SelectConfig, **kw) -> Selection:
    """A Selection of ``chosen`` with its energy curve evaluated after the choice."""
    from curate.select.greedy import trace_energy
    e, a, f = trace_energy(index, cfg.energy, initial, chosen)
    return Selection(method, chosen, initial, e, a, f, **kw)


def run_energy(cams, grid, budget, cfg, initial, index, progress=False) -> Selection:
    """The paper's greedy on its energy; farthest-view sampling (with a note) when no camera sees any node."""
    from curate.select.greedy import greedy_select
    if index.n_pairs == 0:
        # no camera sees any node: every subset scores E = 0 and the greedy would return the first
        # cameras; a loud, recorded fallback instead
        fallback = ("the energy sees no node (no camera observes the scene's nodes: check --box and the "
                    "occupancy): fell back to farthest-view sampling")
        log.warning("select: %s", fallback)
        sel = run_fvs(cams, grid, budget, replace(cfg, method="fvs"), initial, index, progress)
        sel.note = _join(fallback, sel.note)
        return sel
    tr = greedy_select(index, budget, cfg.energy, initial, progress=progress)
    return Selection("energy", tr.chosen, initial, tr.energy, tr.angular, tr.frequency)


def run_path(cams, grid, budget, cfg, initial, index, progress=False) -> Selection:
    """Frames evenly spaced along the capture path; view medoids (with a note) when the photos are not in
    capture order."""
    chosen = path_select(cams, budget, cfg.path, initial, grid.nodes(), index)
    if chosen is not None:
        return _traced("path", chosen, initial, index, cfg)
    fallback = ("path: the photos are not in capture order (or too few), so there is no path to "
                "space frames along: fell back to view medoids")
    log.info("select %s", fallback)
    sel = run_medoids(cams, grid, budget, replace(cfg, method="medoids"), initial, index, progress)
    sel.note = _join(fallback, sel.note)
    return sel


def run_medoids(cams, grid, budget, cfg, initial, index, progress=False) -> Selection:
    """View medoids; path weights that do not apply (photos not in capture order) become a note."""
    from curate.select.medoids import PathOrderWarning, medoids_select
    note = ""
    with warnings.catch_warnings(record=True) as caught:          # path weights ignored: a note
        warnings.simplefilter("always")
        chosen, cost = medoids_select(cams, budget, cfg.medoids, initial, grid.nodes(), index)
    for w in caught:
        if issubclass(w.category, PathOrderWarning):
            log.info("select %s", w.message)
            note = _join(note, str(w.message))
        else:                                                     # any other warning: passed on
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return _traced("medoids", chosen, initial, index, cfg, objective=cost, note=note)


def run_fvs(cams, grid, budget, cfg, initial, index, progress=False) -> Selection:
    """Farthest-view sampling."""
    from curate.select.baselines import farthest_view
    return _traced("fvs", farthest_view(cams, budget, initial), initial, index, cfg)


def run_stride(cams, grid, budget, cfg, initial, index, progress=False) -> Selection:
    """Every n-th camera in name order."""
    from curate.select.baselines import stride_subset
    return _traced("stride", stride_subset(len(cams), budget, initial), initial, index, cfg)


def run_random(cams, grid, budget, cfg, initial, index, progress=False) -> Selection:
    """A random subset (``cfg.seed``)."""
    from curate.select.baselines import random_subset
    return _traced("random", random_subset(len(cams), budget, cfg.seed, initial), initial, index, cfg)


def score_cameras(cams: Cameras, grid: NodeGrid, cfg: EnergyConfig = EnergyConfig(), per_node: bool = False,
                  device: str | None = None) -> EnergyTerms:
    """E of the whole set ``cams`` over the grid's active nodes."""
    from curate.select.energy import energy_from_hist, histogram
    from curate.select.visibility import build_pair_index

    index = build_pair_index(cams, grid.nodes(), cfg.bins, device=device)
    return energy_from_hist(histogram(index), len(cams), cfg, per_node)

