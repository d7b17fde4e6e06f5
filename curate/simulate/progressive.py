"""Progressive camera placement (Algorithm 1 of Kopanas & Drettakis 2023).

Each step draws ``n_candidates`` random cameras (uniform centre in a box, random yaw,
pitch uniform in +-``max_pitch``, no roll), rejects those whose centre is occupied or
that see occupied space closer than ``margin``, scores the rest by the energy of the
cameras placed so far plus the candidate (:meth:`curate.select.greedy.NodeState.scores_of`, one
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

from curate.core.cameras import Cameras, look_at
from curate.select.config import EnergyConfig
from curate.select.greedy import NodeState
from curate.select.visibility import build_pair_index

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
    field_loop: dict | None = None
    """Set by callers whose ``on_add`` trains a field (per-camera timings)."""


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
        k = state.add_best_of(build_pair_index(cands, nodes, cfg.energy.bins))
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
    """(occupied, min_depth) callables from a :class:`curate.simulate.synthetic.Scene`'s exact geometry.

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


class GridOracle:
    """Occupancy callables over a boolean volume ``occ`` [R, R, R] spanning a box, re-read at every
    call, so the volume may be replaced between steps (e.g. in ``on_add``).

    Points outside the box count as occupied. :meth:`min_depth` marches ``probe``-sized rays
    from each camera up to ``margin`` (``steps`` samples each) and returns the distance of
    the first occupied sample along z, or ``margin`` when none is found within it (enough
    for the rejection test, far cheaper than a full depth render).
    """

    def __init__(self, box_min, box_max, occ: np.ndarray, margin: float, steps: int = 12,
                 probe: tuple[int, int] = (16, 12)):
        self.lo, self.hi = np.asarray(box_min, float), np.asarray(box_max, float)
        self.occ = np.asarray(occ, bool)
        self.margin, self.steps, self.probe = float(margin), int(steps), probe

    def occupied(self, points) -> np.ndarray:
        """[n] bool for points [n, 3]."""
        lo, hi, occ = self.lo, self.hi, self.occ
        R = np.array(occ.shape)
        p = np.asarray(points, float).reshape(-1, 3)
        inside = np.all((p >= lo) & (p <= hi), axis=1)
        ijk = np.clip(np.rint((p - lo) / np.where(hi > lo, hi - lo, 1) * (R - 1)).astype(int), 0, R - 1)
        return ~inside | occ[ijk[:, 0], ijk[:, 1], ijk[:, 2]]

    def min_depth(self, cams: Cameras) -> np.ndarray:
        """[N] distance of the nearest occupied sample seen within ``margin`` (``margin`` if none)."""
        W, H = self.probe
        margin = self.margin
        uu, vv = np.meshgrid((np.arange(W) + 0.5) / W, (np.arange(H) + 0.5) / H)
        x = (uu.ravel()[None] * cams.width[:, None] - cams.cx[:, None]) / cams.fx[:, None]   # [N, W*H]
        y = (vv.ravel()[None] * cams.height[:, None] - cams.cy[:, None]) / cams.fy[:, None]
        d = np.stack([x, y, np.ones_like(x)], -1) @ np.transpose(cams.rotations, (0, 2, 1))
        out = np.full(len(cams), margin)
        for z in np.linspace(margin / self.steps, margin, self.steps)[::-1]:  # far to near: the nearest wins
            hit = self.occupied((cams.centres[:, None, :] + z * d).reshape(-1, 3)).reshape(len(cams), -1).any(1)
            out[hit] = z
        return out


def grid_oracle(box_min, box_max, occ: np.ndarray, margin: float, steps: int = 12, probe: tuple[int, int] = (16, 12)):
    """(occupied, min_depth) callables from a boolean occupancy volume ``occ`` [R, R, R] over a box
    (a fixed :class:`GridOracle`)."""
    o = GridOracle(box_min, box_max, occ, margin, steps, probe)
    return o.occupied, o.min_depth


@dataclass(frozen=True)
class FieldOccupancyConfig:
    """How the field-driven loop derives occupancy from the field being trained."""

    threshold: float = 0.1
    """A node is occupied where the field's opacity across one voxel exceeds this
    (:func:`curate.occupancy.masks.field_occupancy`)."""
    res: int = 32
    """Nodes per axis of the occupancy volume over the box B."""
    supersample: int = 2
    """Density probes per axis and voxel."""
    warmup: int | None = None
    """Photos taken before the field's occupancy is used (before: only B^f is known free);
    None: the loop's ``n_free_first``, i.e. the field takes over when candidates leave B^f
    (the paper's field has then trained 20 x 250 iterations)."""
    min_iters: int = 1000
    """...and field iterations trained before it is used (an under-trained field explains the
    photos with surfaces at wrong depths: it would carve through furniture)."""
    carve: bool = True
    """Space no taken photo has seen (beyond the field's depth, or outside every frustum)
    counts as occupied: a camera is never proposed where nothing was observed."""
    probe: tuple = (32, 24)
    """Rays cast through the field's density per taken camera, for the carving."""
    hit_opacity: float = 0.5
    """A probe ray's surface is its first occupied sample (``threshold``) or, if nearer, where its
    accumulated opacity reaches this; a ray with no occupied sample carves nothing."""
    slack_voxels: float = 1.0
    """Free space is carved up to this many voxels before a ray's surface."""


def first_hit_depth(density_world: Callable, origins: np.ndarray, dirs: np.ndarray, t_max: float, step: float,
                    voxel: float, threshold: float = 0.1, opacity: float = 0.5, chunk: int = 1 << 20) -> np.ndarray:
    """[R] depth of the surface along unit rays (origins, dirs [R, 3]) through a world density
    ``density_world(points [n, 3]) -> [n]``, sampled every ``step`` up to ``t_max``.

    A ray hits at its first sample that is occupied by the occupancy volume's criterion (the
    opacity across one ``voxel``, ``1 - exp(-sigma voxel)``, exceeds ``threshold``); the depth
    is that of the hit or, if nearer, where the opacity accumulated along the ray reaches
    ``opacity``. A ray with no occupied sample returns inf: haze that never forms a surface
    (an under-trained field) is no evidence of free space.
    """
    ts = np.arange(0.5 * step, t_max, step)  # [S]
    out = np.full(len(origins), np.inf)
    per = max(1, chunk // max(len(ts), 1))
    for s in range(0, len(origins), per):
        o, d = origins[s:s + per], dirs[s:s + per]
        sig = np.clip(np.asarray(density_world((o[:, None, :] + ts[None, :, None] * d[:, None, :]).reshape(-1, 3)),
                                 float).reshape(len(o), len(ts)), 0, None)
        occ = 1 - np.exp(-sig * voxel) > threshold  # [n, S]
        acc = 1 - np.exp(-np.cumsum(sig * step, 1)) >= opacity
        t_occ = np.where(occ.any(1), ts[occ.argmax(1)], np.inf)
        t_acc = np.where(acc.any(1), ts[acc.argmax(1)], np.inf)
        out[s:s + per] = np.where(np.isfinite(t_occ), np.minimum(t_occ, t_acc), np.inf)
    return out


def observed_free(density_world: Callable, cams: Cameras, points: np.ndarray, t_max: float, step: float,
                  voxel: float, threshold: float = 0.1, probe: tuple = (32, 24), slack: float = 0.1,
                  opacity: float = 0.5, box: tuple | None = None) -> np.ndarray:
    """[M] bool: points [M, 3] seen as free space by some camera of ``cams``.

    Each camera casts a ``probe``-sized grid of rays through the density and finds each
    ray's surface (:func:`first_hit_depth`); a point is observed free when it projects into
    a probe pixel whose ray hit a surface, and lies closer than that depth minus ``slack``.
    Rays that hit no surface (the field has not converged there), or (``box`` given) hit
    one outside ``box`` grown by ``voxel``, carve nothing.
    """
    W, H = probe
    pts = np.asarray(points, float).reshape(-1, 3)
    free = np.zeros(len(pts), bool)
    if len(cams) == 0:
        return free
    small = Cameras(cams.c2w, cams.fx * W / cams.width, cams.fy * H / cams.height,
                    cams.cx * W / cams.width, cams.cy * H / cams.height, W, H)
    uu, vv = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    for k in range(len(small)):
        x, y = (uu.ravel() - small.cx[k]) / small.fx[k], (vv.ravel() - small.cy[k]) / small.fy[k]
        d = np.stack([x, y, np.ones_like(x)], 1) @ small.rotations[k].T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        depth = first_hit_depth(density_world, np.broadcast_to(small.centres[k], d.shape), d, t_max, step,
                                voxel, threshold, opacity)
        if box is not None:
            hit = small.centres[k] + np.where(np.isfinite(depth), depth, 0)[:, None] * d
            inside = np.all((hit >= np.asarray(box[0]) - voxel) & (hit <= np.asarray(box[1]) + voxel), axis=1)
            depth = np.where(inside, depth, np.inf)
        uv, z = small[k].project(pts)
        u, v, z = uv[0, :, 0], uv[0, :, 1], z[0]
        ok = (z > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
        pix = np.clip(v.astype(int), 0, H - 1) * W + np.clip(u.astype(int), 0, W - 1)
        dist = np.linalg.norm(pts - small.centres[k], axis=1)
        free |= ok & (dist < depth[pix] - slack)
    return free


class FieldOracle(GridOracle):
    """Occupancy from a radiance field trained as cameras are added (the paper's setting).

    The volume is a ``cfg.res``^3 node grid over the box B. The free box B^f is free at all
    times (the user's word). Until :meth:`update` is first called (the loop calls it once
    ``cfg.warmup`` photos are taken and the field trained ``cfg.min_iters`` iterations),
    everything outside B^f is unknown and counts as occupied, so the first cameras stay in
    B^f. Each update sets: occupied = the field's opacity across a voxel > ``cfg.threshold``,
    or (``cfg.carve``) not observed free by any taken camera (:func:`observed_free`, whose
    ray surfaces must lie in B, give or take a voxel: a surface beyond B is the field's
    background, no evidence of free space); minus B^f.
    """

    def __init__(self, box: tuple, free_box: tuple, margin: float, cfg: FieldOccupancyConfig = FieldOccupancyConfig(),
                 steps: int = 12, probe: tuple[int, int] = (16, 12)):
        from curate.core.grid import NodeGrid
        self.cfg = cfg
        self.grid = NodeGrid(box[0], box[1], cfg.res)
        nodes = self.grid.all_nodes()
        flo, fhi = (np.asarray(b, float) for b in free_box)
        self.in_free = np.all((nodes >= flo) & (nodes <= fhi), axis=1).reshape((cfg.res,) * 3)
        super().__init__(self.grid.box_min, self.grid.box_max, ~self.in_free, margin, steps, probe)
        self.updates = 0

    def update(self, field, cams: Cameras) -> float:
        """Re-derive the volume from ``field`` and the cameras taken so far; returns the occupied fraction."""
        from curate.occupancy.masks import RefineConfig, field_occupancy
        c = self.cfg
        occ = field_occupancy(field, self.grid,
                              RefineConfig(threshold=c.threshold, supersample=c.supersample)) > c.threshold
        if c.carve:
            vox = float(np.max((self.grid.box_max - self.grid.box_min) / max(c.res - 1, 1)))
            diag = float(np.linalg.norm(self.grid.box_max - self.grid.box_min))
            seen = observed_free(field.density_world, cams, self.grid.all_nodes(), t_max=diag, step=0.5 * vox,
                                 voxel=vox, threshold=c.threshold, probe=tuple(c.probe), slack=c.slack_voxels * vox,
                                 opacity=c.hit_opacity, box=(self.grid.box_min, self.grid.box_max))
            occ |= ~seen.reshape(occ.shape)
        self.occ = occ & ~self.in_free
        self.updates += 1
        return float(self.occ.mean())
