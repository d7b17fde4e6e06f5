"""Selections that were measured and not adopted, runnable by the harness beside the product's methods.

A :class:`Variant` is the product's :class:`curate.select.config.SelectConfig` plus the knobs the
product no longer has: pool coverage (:mod:`research.coverage`), a medoid cost power, an energy
share and a sharpness prior (:mod:`research.medoids_variants`), and a rotation weight for
farthest-view sampling. :func:`select_variant` runs one and returns a product ``Selection``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from curate.select.config import SelectConfig
from curate.select.select import Selection
from research.coverage import CoverageConfig
from research.medoids_variants import MedoidsVariantConfig


@dataclass(frozen=True)
class Variant:
    """A measured, not adopted selection."""

    method: str
    """'medoids', 'fvs', 'path_stride', 'coverage' or 'coverage+energy'."""
    base: SelectConfig = field(default_factory=SelectConfig)
    """The product's options it shares (energy bins, device, seed)."""
    medoids: MedoidsVariantConfig = field(default_factory=MedoidsVariantConfig)
    """'medoids': power, energy share, sharpness prior, path weights."""
    fvs_rot_weight: float = 0.0
    """'fvs': weight of the viewing-direction angle against the centre distance."""
    coverage: CoverageConfig = field(default_factory=CoverageConfig)
    """'coverage*': the similarity between pool views."""
    energy_weight: float = 0.5
    """'coverage+energy': weight of the energy's relative gain."""
    look_scale: float = 1.0
    """'path_stride': scale of the look-at depths (below 1: turning counts for less than walking)."""
    arc_power: float = 1.0
    """'path_stride': power of each step (in median steps) in the arc length (0: every n-th frame)."""

    @property
    def energy(self):
        return self.base.energy

    @property
    def device(self):
        return self.base.device


def select_variant(v: Variant, cams, grid, budget: int, index=None, sharpness=None) -> Selection:
    """Run the variant ``v`` on the pool ``cams`` [K] over ``grid``; ``sharpness`` [K] for the prior."""
    from curate.select.baselines import farthest_view
    from curate.select.greedy import greedy_select, trace_energy
    from curate.select.visibility import build_pair_index
    t0 = time.perf_counter()
    if index is None:
        index = build_pair_index(cams, grid.nodes(), v.energy.bins, device=v.device)
    objective = None
    if v.method == "medoids":
        from research.medoids_variants import medoids_select
        from curate.select.baselines import stride_subset
        n_med = budget - int(round(v.medoids.energy_share * max(0, budget)))
        first = stride_subset(len(cams), int(round(v.medoids.stride_share * max(0, n_med))))
        chosen, objective = medoids_select(cams, n_med - len(first), v.medoids, first, grid.nodes(), index,
                                           sharpness)
        chosen = list(first) + list(chosen)
        if n_med < budget:                   # the rest by the paper's energy, on top of the medoids
            chosen += greedy_select(index, budget - n_med, v.energy, chosen).chosen
    elif v.method == "fvs":
        chosen = farthest_view(cams, budget, (), v.fvs_rot_weight)
    elif v.method == "path_stride":
        from research.path_stride import path_stride
        chosen = path_stride(cams, budget, grid.nodes(), index, look_scale=v.look_scale, power=v.arc_power)
        if chosen is None:                   # not in capture order: the product's view medoids
            from curate.select.medoids import medoids_select as product_medoids
            chosen, objective = product_medoids(cams, budget, nodes=grid.nodes(), index=index)
    elif v.method in ("coverage", "coverage+energy"):
        from research.coverage import coverage_select
        chosen, objective = coverage_select(cams, index, budget, v.coverage, (),
                                            energy=v.energy if v.method == "coverage+energy" else None,
                                            energy_weight=v.energy_weight)
    else:
        raise ValueError(f"unknown variant method {v.method!r}")
    e, a, f = trace_energy(index, v.energy, [], chosen)
    sel = Selection(v.method, list(chosen), [], e, a, f, objective=objective)
    sel.seconds = time.perf_counter() - t0
    return sel
