"""Progressive camera placement (Algorithm 1 of Kopanas & Drettakis 2023).

Each step draws ``n_candidates`` random cameras (uniform centre in a box, random yaw,
pitch uniform in +-``max_pitch``, no roll), rejects those whose centre is occupied or
that see occupied space closer than ``margin``, scores the rest by the energy of the
cameras placed so far plus the candidate (:meth:`curate.greedy.NodeState.scores_of`, one
pass over the candidates' visibility pairs), and adds the best. The first
``n_free_first`` cameras are drawn in the free box B^f, the rest in the whole box B.

Occupancy is a pair of callables, so the same loop runs on the scene's exact occupancy
(the oracle variant) or on the density of a field trained as cameras are added (the
paper's setting): ``occupied(points [n, 3]) -> bool [n]`` and
``min_depth(cams) -> [N]`` (nearest occupied surface seen by each camera, e.g. from a
low-resolution depth render). ``on_add(k, cams_so_far)`` is called after each addition
(e.g. to render the new photo and train the field some iterations).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .cameras import Cameras, look_at
from .energy import EnergyConfig
from .greedy import NodeState, argmax_lowest
from .visibility import build_pair_index

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CameraSpec:
    """Intrinsics of placed cameras."""

    width: int = 160
    """Image width in pixels."""
    height: int = 120
    """Image height in pixels."""
    hfov_deg: float = 60.0
    """Horizontal field of view in degrees (square pixels, centred principal point)."""

    @property
    def fx(self) -> float:
        return 0.5 * self.width / np.tan(np.radians(self.hfov_deg) / 2)


@dataclass(frozen=True)
class ProgressiveConfig:
    """Settings of the progressive placement loop."""

    budget: int = 100
    """Cameras to place."""
    n_candidates: int = 1000
    """Random candidates drawn per step (the paper: 1000)."""
    n_free_first: int = 20
    """The first cameras are drawn in the free box B^f (the paper: 20)."""
    margin: float = 0.3
    """Reject candidates that see occupied space closer than this (scene units)."""
    max_pitch_deg: float = 45.0
    """Candidate pitch is uniform in +- this angle (up is +z)."""
    energy: EnergyConfig = field(default_factory=EnergyConfig)
    """Energy parameters."""
    camera: CameraSpec = field(default_factory=CameraSpec)
    """Intrinsics of the placed cameras."""
    seed: int = 0
    """Seed of the candidate draws."""


def random_cameras(rng: np.random.Generator, lo, hi, n: int, spec: CameraSpec, max_pitch_deg: float = 45.0) -> Cameras:
    """n cameras with centres uniform in the box [lo, hi], random yaw, pitch in +-max_pitch, up = +z."""
    c = rng.uniform(np.asarray(lo, float), np.asarray(hi, float), (n, 3))
    yaw = rng.uniform(-np.pi, np.pi, n)
    pitch = np.radians(rng.uniform(-max_pitch_deg, max_pitch_deg, n))
    d = np.stack([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)], 1)
    return Cameras(look_at(c, c + d), spec.fx, spec.fx, spec.width / 2, spec.height / 2, spec.width, spec.height)


def acceptable(cams: Cameras, occupied: Callable, min_depth: Callable, margin: float) -> np.ndarray:
    """[N] bool: centre free and nothing occupied nearer than ``margin``."""
    ok = ~np.asarray(occupied(cams.centres), bool)
    if np.any(ok):
        idx = np.flatnonzero(ok)
        ok[idx] = np.asarray(min_depth(cams[idx])) >= margin
    return ok


def draw_acceptable(rng, lo, hi, n: int, cfg: ProgressiveConfig, occupied: Callable, min_depth: Callable,
                    max_rounds: int = 20) -> Cameras:
    """Up to n acceptable random cameras in [lo, hi] (draws in rounds until n or max_rounds)."""
    got: list[Cameras] = []
    total = 0
    for _ in range(max_rounds):
        c = random_cameras(rng, lo, hi, max(n - total, 1) * 2, cfg.camera, cfg.max_pitch_deg)
        c = c[acceptable(c, occupied, min_depth, cfg.margin)]
        got.append(c[: n - total])
        total += min(len(c), n - total)
        if total >= n:
            break
    return Cameras.concat(got)


@dataclass
class PlacementTrace:
    """What the loop did: per step the energy, the number of acceptable candidates and the time."""

    energy: list[float] = field(default_factory=list)
    angular: list[float] = field(default_factory=list)
    frequency: list[float] = field(default_factory=list)
    n_acceptable: list[int] = field(default_factory=list)
    propose_seconds: list[float] = field(default_factory=list)


def progressive_placement(nodes: np.ndarray, box: tuple, free_box: tuple, cfg: ProgressiveConfig,
                          occupied: Callable, min_depth: Callable, on_add: Callable | None = None,
                          initial: Cameras | None = None, progress: bool = False) -> tuple[Cameras, PlacementTrace]:
    """Place ``cfg.budget`` cameras one at a time (see the module docstring).

    Args:
        nodes: [M, 3] nodes the energy is summed over (e.g. near occupied surfaces).
        box: (lo [3], hi [3]) the scene box B; free_box: (lo, hi) B^f.
        initial: cameras already placed (count towards B^f's first cameras, not the budget).
    Returns:
        (placed cameras, initial ones excluded; trace).
    """
    rng = np.random.default_rng(cfg.seed)
    state = NodeState(len(nodes), cfg.energy)
    placed: list[Cameras] = []
    if initial is not None and len(initial):
        ii = build_pair_index(initial, nodes, cfg.energy.bins)
        for k in range(len(initial)):
            state.add(*ii.camera_pairs(k))
    n_before = 0 if initial is None else len(initial)
    trace = PlacementTrace()
    steps = range(cfg.budget)
    if progress:
        from tqdm import tqdm
        steps = tqdm(steps, desc="place", unit="cam", leave=False)
    for step in steps:
        t0 = time.perf_counter()
        lo, hi = free_box if n_before + step < cfg.n_free_first else box
        cands = draw_acceptable(rng, lo, hi, cfg.n_candidates, cfg, occupied, min_depth)
        if len(cands) == 0:
            log.warning("no acceptable candidate at step %d: stopping", step)
            break
        idx = build_pair_index(cands, nodes, cfg.energy.bins)
        k = argmax_lowest(state.scores_of(idx), np.ones(len(cands), bool))
        state.add(*idx.camera_pairs(k))
        placed.append(cands[k])
        e, a, f = state.energy()
        trace.energy.append(e)
        trace.angular.append(a)
        trace.frequency.append(f)
        trace.n_acceptable.append(len(cands))
        trace.propose_seconds.append(time.perf_counter() - t0)
        if on_add is not None:
            on_add(step, Cameras.concat(placed))
    return Cameras.concat(placed), trace


def scene_oracle(scene, probe: tuple[int, int] = (32, 24)):
    """(occupied, min_depth) callables from a :class:`curate.synthetic.Scene`'s exact geometry.

    ``min_depth`` renders a ``probe``-sized depth image per camera (same field of view) and
    returns its minimum; a camera whose probe sees nothing returns inf.
    """
    def occupied(points):
        return scene.occupied(points)

    def min_depth(cams: Cameras):
        small = Cameras(cams.c2w, cams.fx * probe[0] / cams.width, cams.fy * probe[1] / cams.height,
                        cams.cx * probe[0] / cams.width, cams.cy * probe[1] / cams.height, probe[0], probe[1])
        return scene.depth(small).reshape(len(cams), -1).min(1)

    return occupied, min_depth


def grid_oracle(box_min, box_max, occ: np.ndarray, margin: float, steps: int = 12, probe: tuple[int, int] = (16, 12)):
    """(occupied, min_depth) callables from a boolean occupancy volume ``occ`` [R, R, R] over a box.

    Points outside the box count as occupied. ``min_depth`` marches ``probe``-sized rays
    from each camera up to ``margin`` (``steps`` samples each) and returns the distance of
    the first occupied sample along z, or ``margin`` when none is found within it (enough
    for the rejection test, far cheaper than a full depth render).
    """
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    occ = np.asarray(occ, bool)
    R = np.array(occ.shape)

    def occupied(points):
        p = np.asarray(points, float).reshape(-1, 3)
        inside = np.all((p >= lo) & (p <= hi), axis=1)
        ijk = np.clip(np.rint((p - lo) / np.where(hi > lo, hi - lo, 1) * (R - 1)).astype(int), 0, R - 1)
        return ~inside | occ[ijk[:, 0], ijk[:, 1], ijk[:, 2]]

    def min_depth(cams: Cameras):
        W, H = probe
        uu, vv = np.meshgrid((np.arange(W) + 0.5) / W, (np.arange(H) + 0.5) / H)
        x = (uu.ravel()[None] * cams.width[:, None] - cams.cx[:, None]) / cams.fx[:, None]   # [N, W*H]
        y = (vv.ravel()[None] * cams.height[:, None] - cams.cy[:, None]) / cams.fy[:, None]
        d = np.stack([x, y, np.ones_like(x)], -1) @ np.transpose(cams.rotations, (0, 2, 1))
        out = np.full(len(cams), float(margin))
        for z in np.linspace(margin / steps, margin, steps)[::-1]:  # far to near: the nearest wins
            hit = occupied((cams.centres[:, None, :] + z * d).reshape(-1, 3)).reshape(len(cams), -1).any(1)
            out[hit] = z
        return out

    return occupied, min_depth
