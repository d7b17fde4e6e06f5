"""Feasible poses around an object capture: the orbit's missing heights and sides.

An object capture (:func:`curate.select.methods.capture_kind`: cameras around a point, looking at it) sees little of
the room it stands in, and its cameras stand where the object's own rays carve little free space: the walk's rule
(stand where the capture saw empty space) leaves nowhere to stand. What such a capture lacks is views of the object
from the heights and sides it did not film. So a pose around an object is drawn on the capture's own view sphere
(:func:`capture_orbit`): its centre at a distance from the object's centre (the point nearest every viewing axis)
within the range the capture's cameras kept, at any azimuth, at an elevation from the capture's lowest (or level
with the object, if that is lower) up to :data:`ELEVATION_MAX_DEG`, looking at the object's centre with no roll. It
is feasible when its centre keeps the capture's clearance from occupied nodes and nothing occupied lies in its view
nearer than the capture's view margin (the table under the object, a wall behind the user where its points say so).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from curate.core.cameras import Cameras, look_at
from curate.suggest.candidates import Envelope, PoseSet, horizontal_basis, occupied_points
from curate.suggest.freespace import voxel_index

ELEVATION_MAX_DEG = 75.0
"""The highest elevation (degrees above the object's centre) of a suggested view: nearly top-down."""


@dataclass(frozen=True)
class Orbit:
    """The view sphere of an object capture. Lengths in the capture's units, angles in radians."""

    centre: np.ndarray
    """[3] the object's centre: the point nearest every viewing axis."""
    radii: tuple[float, float]
    """Range of distances from the centre (percentiles 5-95 of the capture's)."""
    elevations: tuple[float, float]
    """Range of elevations a suggestion may take."""
    captured: tuple[float, float]
    """Range of the capture's own elevations (percentiles 5-95)."""

    def to_dict(self) -> dict:
        return {"centre": self.centre.tolist(), "radii": list(self.radii),
                "elevation_deg": np.degrees(self.elevations).tolist(), "captured_elevation_deg":
                np.degrees(self.captured).tolist()}


def capture_orbit(cams: Cameras, up: np.ndarray) -> Orbit | None:
    """The view sphere of ``cams`` (module docstring); None when their axes meet nowhere."""
    from curate.core.grid import focus_point
    p = focus_point(cams)
    if p is None:
        return None
    v = cams.centres - p
    r = np.linalg.norm(v, axis=1)
    ok = r > 1e-9
    if not ok.any():
        return None
    elev = np.arcsin(np.clip((v[ok] @ up) / r[ok], -1, 1))
    cap = (float(np.percentile(elev, 5)), float(np.percentile(elev, 95)))
    lo = min(cap[0], 0.0)
    hi = max(cap[1], np.radians(ELEVATION_MAX_DEG))
    return Orbit(p, (float(np.percentile(r[ok], 5)), float(np.percentile(r[ok], 95))), (lo, hi), cap)


def _open_oracle(box_min, box_max, occ, margin):
    """:class:`curate.simulate.progressive.GridOracle` with the space outside the grid taken as empty: an object
    capture's grid spans the object and what is near it, and its cameras stand outside it (the walk's grid spans
    the room, where outside is behind the walls)."""
    from curate.simulate.progressive import GridOracle

    class Open(GridOracle):
        def occupied(self, points) -> np.ndarray:
            p = np.asarray(points, float).reshape(-1, 3)
            inside = np.all((p >= self.lo) & (p <= self.hi), axis=1)
            return inside & super().occupied(p)

    return Open(box_min, box_max, occ, margin)


class OrbitFeasibility(PoseSet):
    """Which poses around an object are feasible, and uniform draws of them on the view sphere (module
    docstring)."""

    kind = "object"

    def __init__(self, occ: np.ndarray, box_min, box_max, env: Envelope, orbit: Orbit, probe: int = 2000):
        from scipy.spatial import cKDTree
        self.occ = np.asarray(occ, bool)
        self.R = self.occ.shape[0]
        self.lo, self.hi = np.asarray(box_min, float), np.asarray(box_max, float)
        self.env, self.orbit = env, orbit
        pts = occupied_points(self.occ, self.lo, self.hi)
        self._tree = cKDTree(pts) if len(pts) else None
        self._oracle = _open_oracle(self.lo, self.hi, self.occ, margin=env.view_margin)
        # how much of the view sphere is feasible (a fixed draw, for the record and for "nowhere to stand")
        self.cells = np.flatnonzero(self.feasible(self._sample(np.random.default_rng(0), probe)))
        self.probe = probe

    def _sample(self, rng: np.random.Generator, m: int) -> Cameras:
        o, env = self.orbit, self.env
        e1, e2 = horizontal_basis(env.up)
        az = rng.uniform(-np.pi, np.pi, m)
        s = rng.uniform(np.sin(o.elevations[0]), np.sin(o.elevations[1]), m)      # uniform over the sphere's area
        ce = np.sqrt(1 - s * s)
        r = rng.uniform(o.radii[0], o.radii[1], m)
        d = ce[:, None] * (np.cos(az)[:, None] * e1 + np.sin(az)[:, None] * e2) + s[:, None] * env.up
        c = o.centre + r[:, None] * d
        fx, fy, cx, cy, w, h = env.intrinsics
        return Cameras(look_at(c, np.broadcast_to(o.centre, c.shape), up=env.up), fx, fy, cx, cy, w, h)

    def checks(self, cams: Cameras) -> dict[str, np.ndarray]:
        """Each feasibility test, [N] bool per name: 'free' (centre not in an occupied voxel), 'clearance' and
        'view'."""
        c = cams.centres
        flat = voxel_index(c, self.lo, self.hi, self.R)
        out = {"free": (flat < 0) | ~self.occ.ravel()[np.maximum(flat, 0)],
               "clearance": self.clearance(c) >= self.env.clearance,
               "view": np.zeros(len(cams), bool)}
        pre = out["free"] & out["clearance"]
        if pre.any():
            out["view"][pre] = self._oracle.min_depth(cams[np.flatnonzero(pre)]) >= self.env.view_margin
        return out
