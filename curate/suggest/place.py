"""Progressive placement (Algorithm 1 of Kopanas & Drettakis 2023) starting from the user's capture.

The energy's incremental state (:class:`curate.select.greedy.NodeState`) is first filled with every camera of
the capture. Each step then draws ``n_candidates`` feasible poses (:meth:`curate.suggest.candidates.Feasibility.draw`),
scores them all in one pass over their visibility pairs (:meth:`~curate.select.greedy.NodeState.scores_of`:
``E(capture + placed + {c})`` for each candidate c) and adds the best; the next step's candidates are scored
against the capture and every pose placed so far, so two suggestions do not repeat each other.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from curate.core.cameras import Cameras
from curate.select.config import EnergyConfig
from curate.select.energy import EnergyTerms, energy_from_hist
from curate.select.greedy import NodeState
from curate.select.visibility import build_pair_index
from curate.suggest.candidates import Feasibility


@dataclass
class Placement:
    """The placed poses and what each step did.

    Attributes:
        cams: [K] the placed poses, in the order placed.
        energy_before: E of the capture alone.
        energy, angular, frequency: [K] E and its parts after each placed pose.
        n_candidates: [K] feasible candidates scored at each step.
        step_seconds: [K] wall time of each step (drawing, visibility and scoring of its candidates).
        draw_seconds, score_seconds: [K] its drawing and its visibility + scoring parts.
        setup_seconds: filling the energy's state with the capture.
        before, after: per-node energy terms of the capture, and of the capture plus the placed poses.
    """

    cams: Cameras
    energy_before: float
    energy: list[float] = field(default_factory=list)
    angular: list[float] = field(default_factory=list)
    frequency: list[float] = field(default_factory=list)
    n_candidates: list[int] = field(default_factory=list)
    step_seconds: list[float] = field(default_factory=list)
    draw_seconds: list[float] = field(default_factory=list)
    score_seconds: list[float] = field(default_factory=list)
    setup_seconds: float = 0.0
    before: EnergyTerms | None = None
    after: EnergyTerms | None = None

    @property
    def gains(self) -> list[float]:
        """[K] the energy each placed pose added."""
        e = [self.energy_before] + list(self.energy)
        return [float(b - a) for a, b in zip(e[:-1], e[1:])]

    def timing(self) -> dict:
        """Milliseconds per placed camera and per scored candidate (medians over the steps)."""
        n = np.asarray(self.n_candidates, float)
        st = np.asarray(self.step_seconds, float)
        ok = n > 0
        return {"ms_per_camera": float(np.median(st) * 1e3) if st.size else None,
                "ms_per_candidate": float(np.median(st[ok] / n[ok]) * 1e3) if ok.any() else None,
                "ms_per_candidate_scoring": float(np.median(np.asarray(self.score_seconds)[ok] / n[ok]) * 1e3)
                if ok.any() else None,
                "setup_ms": self.setup_seconds * 1e3, "steps": len(st)}


def _terms(state: NodeState, cfg: EnergyConfig) -> EnergyTerms:
    return energy_from_hist(state.hist, state.N, cfg, per_node=True)


def place_cameras(capture: Cameras, nodes: np.ndarray, feas: Feasibility, k: int, n_candidates: int = 1000,
                  energy: EnergyConfig = EnergyConfig(), seed: int = 0, progress: bool = False) -> Placement:
    """Place up to ``k`` poses greedily by the energy over ``nodes`` [M, 3] (module docstring); fewer when no
    feasible candidate is left to draw."""
    rng = np.random.default_rng(seed)
    nodes = np.asarray(nodes, float).reshape(-1, 3)
    t0 = time.perf_counter()
    state = NodeState(len(nodes), energy)
    if len(capture):
        idx0 = build_pair_index(capture, nodes, energy.bins)
        for j in range(len(capture)):
            state.add(*idx0.camera_pairs(j))
    pl = Placement(Cameras.empty(), state.energy()[0], setup_seconds=time.perf_counter() - t0)
    pl.before = _terms(state, energy)
    placed: list[Cameras] = []
    steps = range(int(k))
    if progress:
        from tqdm import tqdm
        steps = tqdm(steps, desc="suggest", unit="cam", leave=False)
    for _ in steps:
        ts = time.perf_counter()
        cands = feas.draw(rng, n_candidates)
        td = time.perf_counter()
        if len(cands) == 0:
            break
        best = state.add_best_of(build_pair_index(cands, nodes, energy.bins))
        te = time.perf_counter()
        placed.append(cands[best])
        e, a, f = state.energy()
        pl.energy.append(e)
        pl.angular.append(a)
        pl.frequency.append(f)
        pl.n_candidates.append(len(cands))
        pl.step_seconds.append(te - ts)
        pl.draw_seconds.append(td - ts)
        pl.score_seconds.append(te - td)
    pl.cams = Cameras.concat(placed)
    pl.after = _terms(state, energy)
    return pl
