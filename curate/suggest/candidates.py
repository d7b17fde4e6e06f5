"""Feasible poses for a new photo: where and how the capture's own hand-held camera could stand and look.

The capture's *envelope* (:func:`capture_envelope`) is read from its cameras: the up direction
(:func:`up_vector`), the range of their heights along it and of their pitches (percentiles), their intrinsics,
and how close they went to things (the distance from each centre to the nearest occupied node, and the nearest
surface each one saw; at most :data:`MAX_CLEARANCE_SHARE` and :data:`MAX_VIEW_MARGIN_SHARE` of the typical
viewing distance, at least one voxel). A pose is *feasible* (:class:`Feasibility`) when its centre lies in an
observed-free, unoccupied voxel (:mod:`curate.suggest.freespace`), at a height and pitch within the envelope, no
nearer to an occupied node than the envelope's clearance, no nearer than the clearance either (in its horizontal
plane) to space the capture has not seen to be empty (a plain wall gives no points, so only the rays that stop
beside it say where it is: what lies beyond what the capture saw is taken as a wall), and nothing occupied lies in
its view nearer than the envelope's view margin. Candidates (:meth:`Feasibility.draw`) are drawn in the feasible
voxels (each equally likely, the position
uniform across the voxel and the height uniform in the envelope's range), with a uniform yaw, a pitch uniform in
the envelope's range and no roll (the image's x axis level).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from curate.core.cameras import Cameras, look_at
from curate.suggest.freespace import FreeSpace, voxel_index, voxel_size


MAX_CLEARANCE_SHARE = 0.25
"""The clearance never exceeds this share of the capture's typical viewing distance (``Envelope.look_depth``)."""
MAX_VIEW_MARGIN_SHARE = 0.5
"""The view margin never exceeds this share of the capture's typical viewing distance."""
SEEN_DIRECTIONS = 16
"""Directions of the ring a suggestion must see empty around it (:meth:`Feasibility.seen_around`)."""


def up_vector(cams: Cameras) -> np.ndarray:
    """[3] unit up direction of a capture.

    A hand-held camera keeps its image's x axis level, so up is the direction most orthogonal to every camera's x
    axis (the eigenvector of ``sum x x^T`` with the smallest eigenvalue), signed like the cameras' mean image up
    (OpenCV -y). The mean image up alone leans towards where the cameras look when they all pitch the same way
    (a walk looking down). When the x axes do not span a plane (every camera facing one way), the mean image up
    with its component along the x axes removed; +z when even that vanishes.
    """
    if len(cams) == 0:
        return np.array([0.0, 0.0, 1.0])
    mean_up = -cams.c2w[:, :3, 1].mean(0)
    x = cams.c2w[:, :3, 0]
    w, v = np.linalg.eigh(x.T @ x / len(x))                     # ascending
    if w[1] > 4 * w[0] + 1e-3:                                  # the x axes span a plane: its normal
        up = v[:, 0] * (1.0 if v[:, 0] @ mean_up >= 0 else -1.0)
    else:
        up = mean_up - v[:, 2] * (v[:, 2] @ mean_up)
    n = float(np.linalg.norm(up))
    return up / n if n > 1e-6 else np.array([0.0, 0.0, 1.0])


def horizontal_basis(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (e1, e2) spanning the plane orthogonal to ``up``, with ``e1 x e2 = up``."""
    ref = np.array([1.0, 0, 0]) if abs(up[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = ref - up * (ref @ up)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(up, e1)


@dataclass(frozen=True)
class Envelope:
    """What the capture's hand-held camera does (see the module docstring). Lengths in the capture's units."""

    up: np.ndarray
    """[3] unit up direction."""
    heights: tuple[float, float]
    """Range of camera heights (``centre @ up``)."""
    pitches: tuple[float, float]
    """Range of pitches in radians (``asin(view_dir @ up)``; positive looks up)."""
    clearance: float
    """Least distance from a camera centre to the nearest occupied node."""
    view_margin: float
    """Least z-depth of an occupied voxel seen in a view."""
    intrinsics: tuple[float, float, float, float, int, int]
    """fx, fy, cx, cy, width, height of the suggested photos (a typical camera of the capture)."""
    look_depth: float
    """Median distance of the surfaces the capture's cameras look at (walking instructions, view distances)."""

    def to_dict(self) -> dict:
        return {"up": self.up.tolist(), "heights": list(self.heights), "pitch_deg": np.degrees(self.pitches).tolist(),
                "clearance": self.clearance, "view_margin": self.view_margin, "intrinsics": list(self.intrinsics),
                "look_depth": self.look_depth}


def occupied_points(occ: np.ndarray, box_min, box_max) -> np.ndarray:
    """[Q, 3] coordinates of the occupied nodes of ``occ`` [R, R, R]."""
    R = occ.shape[0]
    axes = [np.linspace(box_min[a], box_max[a], R) for a in range(3)]
    ijk = np.argwhere(occ)
    return np.stack([axes[a][ijk[:, a]] for a in range(3)], 1) if len(ijk) else np.zeros((0, 3))


def capture_envelope(cams: Cameras, fs: FreeSpace, occ: np.ndarray, box_min, box_max,
                     clearance_percentile: float = 10.0, view_percentile: float = 10.0,
                     height_percentiles=(5.0, 95.0), pitch_percentiles=(5.0, 95.0)) -> Envelope:
    """The envelope of ``cams`` (module docstring)."""
    from scipy.spatial import cKDTree
    if len(cams) == 0:
        raise ValueError("a capture without cameras has no envelope")
    up = up_vector(cams)
    vmax = float(voxel_size(box_min, box_max, occ.shape[0]).max())
    h = cams.centres @ up
    p = np.arcsin(np.clip(cams.view_dirs @ up, -1, 1))
    pts = occupied_points(occ, box_min, box_max)
    clear = cKDTree(pts).query(cams.centres)[0] if len(pts) else np.full(len(cams), np.inf)
    fin = clear[np.isfinite(clear)]
    md = fs.median_depth[np.isfinite(fs.median_depth)]
    look = float(np.median(md)) if md.size else float(np.linalg.norm(np.subtract(box_max, box_min))) / 4
    near = fs.nearest_surface()
    near = near[np.isfinite(near)]
    # a capture taken from one spot keeps its distance to everything, which says nothing of how close its user
    # could go: the margins never exceed a share of the typical viewing distance (and never go below a voxel)
    clearance = max(min(float(np.percentile(fin, clearance_percentile)) if fin.size else vmax,
                        MAX_CLEARANCE_SHARE * look), vmax)
    view_margin = max(min(float(np.percentile(near, view_percentile)) if near.size else vmax,
                          MAX_VIEW_MARGIN_SHARE * look), vmax)
    ref = int(np.argsort(cams.fx, kind="stable")[len(cams) // 2])   # a typical camera of the capture
    intr = (float(cams.fx[ref]), float(cams.fy[ref]), float(cams.cx[ref]), float(cams.cy[ref]),
            int(cams.width[ref]), int(cams.height[ref]))
    return Envelope(up,
                    (float(np.percentile(h, height_percentiles[0])), float(np.percentile(h, height_percentiles[1]))),
                    (float(np.percentile(p, pitch_percentiles[0])), float(np.percentile(p, pitch_percentiles[1]))),
                    clearance, view_margin, intr, look)


def make_cameras(centres: np.ndarray, yaw: np.ndarray, pitch: np.ndarray, env: Envelope) -> Cameras:
    """Cameras at ``centres`` [n, 3] looking along yaw / pitch [n] (radians, in the envelope's frame), no roll."""
    e1, e2 = horizontal_basis(env.up)
    cp = np.cos(pitch)[:, None]
    d = cp * (np.cos(yaw)[:, None] * e1 + np.sin(yaw)[:, None] * e2) + np.sin(pitch)[:, None] * env.up
    fx, fy, cx, cy, w, h = env.intrinsics
    return Cameras(look_at(centres, centres + d, up=env.up), fx, fy, cx, cy, w, h)


class PoseSet:
    """What the feasible poses of a walk (:class:`Feasibility`) and of an object capture
    (:class:`curate.suggest.orbit.OrbitFeasibility`) share: the clearance from occupied nodes, the tests of
    ``checks`` all passed, and uniform draws of ``_sample`` kept when feasible. A subclass sets ``kind``, ``cells``
    (non-empty when anything is feasible) and ``_tree`` (the occupied nodes' KD tree, None without one)."""

    kind = ""
    """'walk' or 'object'."""

    def checks(self, cams: Cameras) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def _sample(self, rng: np.random.Generator, m: int) -> Cameras:
        raise NotImplementedError

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """[n] distance from each point [n, 3] to the nearest occupied node (inf when none is occupied)."""
        p = np.asarray(points, float).reshape(-1, 3)
        return self._tree.query(p)[0] if self._tree is not None else np.full(len(p), np.inf)

    def feasible(self, cams: Cameras) -> np.ndarray:
        """[N] bool: every test of ``checks`` passes."""
        ch = self.checks(cams)
        return np.logical_and.reduce(list(ch.values())) if len(cams) else np.zeros(0, bool)

    def draw(self, rng: np.random.Generator, n: int, max_rounds: int = 40) -> Cameras:
        """Up to ``n`` feasible poses, drawn by ``_sample`` in rounds of twice what is missing and 16 more; fewer
        only when ``max_rounds`` rounds do not find them (a nearly infeasible capture; none without ``cells``)."""
        if len(self.cells) == 0 or n <= 0:
            return Cameras.empty()
        got: list[Cameras] = []
        total = 0
        for _ in range(max_rounds):
            cams = self._sample(rng, 2 * (n - total) + 16)
            cams = cams[self.feasible(cams)]
            take = min(len(cams), n - total)
            got.append(cams[:take])
            total += take
            if total >= n:
                break
        return Cameras.concat(got)


class Feasibility(PoseSet):
    """Which poses of a walk-through are feasible (module docstring), and uniform draws of them."""

    kind = "walk"

    def __init__(self, occ: np.ndarray, box_min, box_max, free: np.ndarray, env: Envelope):
        from scipy.spatial import cKDTree
        from curate.simulate.progressive import GridOracle
        self.occ = np.asarray(occ, bool)
        self.R = self.occ.shape[0]
        self.lo, self.hi = np.asarray(box_min, float), np.asarray(box_max, float)
        self.vox = voxel_size(self.lo, self.hi, self.R)
        self.env = env
        self.allowed = np.asarray(free, bool) & ~self.occ                 # [R, R, R]
        # the ring a suggestion must see empty around it, in its horizontal plane (walls stand upright; the capture's
        # heights bound it up and down): the clearance, and half a voxel (the surface that stopped the carving lies
        # somewhere in the last free voxel), and half that, in SEEN_DIRECTIONS directions
        e1, e2 = horizontal_basis(env.up)
        a = np.linspace(0, 2 * np.pi, SEEN_DIRECTIONS, endpoint=False)
        ring = np.cos(a)[:, None] * e1 + np.sin(a)[:, None] * e2
        r = env.clearance + 0.5 * float(self.vox.max())
        self._ring = np.concatenate([ring * r, ring * (r / 2)])          # [2 D, 3]
        pts = occupied_points(self.occ, self.lo, self.hi)
        self._tree = cKDTree(pts) if len(pts) else None
        self._oracle = GridOracle(self.lo, self.hi, self.occ, margin=env.view_margin)
        # voxels a feasible centre can lie in: allowed, within reach of the height range, clear enough
        half = 0.5 * float(np.linalg.norm(self.vox))
        flat = np.flatnonzero(self.allowed.ravel())
        nodes = self.node_xyz(flat)
        h = nodes @ env.up
        ok = (h >= env.heights[0] - half) & (h <= env.heights[1] + half)
        ok &= self.clearance(nodes) >= env.clearance - half
        ok[ok] = self.seen_around(nodes[ok])
        self.cells = flat[ok]

    def node_xyz(self, flat: np.ndarray) -> np.ndarray:
        """[n, 3] coordinates of the nodes of flat indices [n]."""
        i, j, k = np.unravel_index(np.asarray(flat, np.int64), (self.R,) * 3)
        return self.lo + np.stack([i, j, k], 1) * self.vox

    def seen_around(self, points: np.ndarray) -> np.ndarray:
        """[n] bool: the ring around each point [n, 3] in its horizontal plane (the clearance and half a voxel out,
        and half that) lies in observed-free, unoccupied voxels."""
        p = np.asarray(points, float).reshape(-1, 3)
        flat = voxel_index(p[:, None, :] + self._ring[None], self.lo, self.hi, self.R)      # [n, 2 D]
        return np.all((flat >= 0) & self.allowed.ravel()[np.maximum(flat, 0)], axis=1)

    def checks(self, cams: Cameras) -> dict[str, np.ndarray]:
        """Each feasibility test, [N] bool per name: 'free' (centre in an observed-free, unoccupied voxel),
        'height', 'pitch', 'clearance' (from occupied nodes), 'seen' (:meth:`seen_around`) and 'view'."""
        env = self.env
        c = cams.centres
        flat = voxel_index(c, self.lo, self.hi, self.R)
        free = (flat >= 0) & self.allowed.ravel()[np.maximum(flat, 0)]
        h = c @ env.up
        p = np.arcsin(np.clip(cams.view_dirs @ env.up, -1, 1))
        eps = 1e-9
        out = {"free": free,
               "height": (h >= env.heights[0] - eps) & (h <= env.heights[1] + eps),
               "pitch": (p >= env.pitches[0] - eps) & (p <= env.pitches[1] + eps),
               "clearance": self.clearance(c) >= env.clearance,
               "seen": self.seen_around(c),
               "view": np.zeros(len(cams), bool)}
        pre = out["free"] & out["height"] & out["pitch"] & out["clearance"] & out["seen"]
        if pre.any():
            out["view"][pre] = self._oracle.min_depth(cams[np.flatnonzero(pre)]) >= env.view_margin
        return out

    def _sample(self, rng: np.random.Generator, m: int) -> Cameras:
        """``m`` candidate poses, feasible or not: the position uniform in a feasible voxel (each equally likely),
        the height uniform in the envelope's range (a range of zero width too: a capture on a tripod), a uniform yaw,
        a pitch uniform in the envelope's range."""
        env = self.env
        cell = self.cells[rng.integers(0, len(self.cells), m)]
        c = self.node_xyz(cell) + rng.uniform(-0.5, 0.5, (m, 3)) * self.vox
        c += env.up[None, :] * (rng.uniform(env.heights[0], env.heights[1], m) - c @ env.up)[:, None]
        yaw = rng.uniform(-np.pi, np.pi, m)
        pitch = rng.uniform(env.pitches[0], env.pitches[1], m)
        return make_cameras(c, yaw, pitch, env)
