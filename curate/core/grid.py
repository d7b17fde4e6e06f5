"""The grid of nodes over which the energy is summed.

A :class:`NodeGrid` holds ``R^3`` nodes (``R = res``, default 32) spanning an
axis-aligned box, nodes on the box's faces included: along each axis the node
coordinates are ``numpy.linspace(box_min, box_max, R)``. Flat node index
``(ix * R + iy) * R + iz`` (x slowest). An optional boolean mask ``[R, R, R]`` keeps
only some nodes (occupied space and its surface, say); skipped nodes cost nothing
anywhere downstream, since only active nodes are ever handed to visibility.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from curate.core.cameras import Cameras


@dataclass(frozen=True)
class NodeGrid:
    """Regular node grid over an axis-aligned box.

    Attributes:
        box_min: [3] lower corner.
        box_max: [3] upper corner (each coordinate >= box_min's).
        res: nodes per axis (R).
        mask: optional [R, R, R] bool, True for nodes to keep; None keeps all.
    """

    box_min: np.ndarray
    box_max: np.ndarray
    res: int = 32
    mask: np.ndarray | None = field(default=None)

    def __post_init__(self) -> None:
        lo = np.asarray(self.box_min, np.float64).reshape(3)
        hi = np.asarray(self.box_max, np.float64).reshape(3)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError("box corners must be finite")
        if np.any(hi < lo):
            raise ValueError(f"box_max {hi} is below box_min {lo}")
        if int(self.res) < 1:
            raise ValueError("res must be >= 1")
        object.__setattr__(self, "box_min", lo)
        object.__setattr__(self, "box_max", hi)
        object.__setattr__(self, "res", int(self.res))
        if self.mask is not None:
            m = np.asarray(self.mask, bool)
            if m.shape != (self.res,) * 3:
                raise ValueError(f"mask must have shape {(self.res,) * 3}, got {m.shape}")
            object.__setattr__(self, "mask", m)

    @property
    def axes(self) -> list[np.ndarray]:
        """Three [R] arrays of node coordinates along x, y, z."""
        return [np.linspace(self.box_min[a], self.box_max[a], self.res) for a in range(3)]

    def all_nodes(self) -> np.ndarray:
        """[R^3, 3] every node, flat index ``(ix * R + iy) * R + iz``."""
        gx, gy, gz = np.meshgrid(*self.axes, indexing="ij")
        return np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)

    def active_indices(self) -> np.ndarray:
        """[M] flat indices of the kept nodes (all of them without a mask)."""
        if self.mask is None:
            return np.arange(self.res ** 3)
        return np.flatnonzero(self.mask.ravel())

    def nodes(self) -> np.ndarray:
        """[M, 3] coordinates of the kept nodes."""
        return self.all_nodes()[self.active_indices()]

    def with_mask(self, mask: np.ndarray | None) -> "NodeGrid":
        return NodeGrid(self.box_min, self.box_max, self.res, mask)

    def scatter(self, values: np.ndarray, fill: float = np.nan) -> np.ndarray:
        """Active-node values [M] -> a dense [R, R, R] volume, ``fill`` at skipped nodes."""
        out = np.full(self.res ** 3, fill, dtype=np.float64)
        out[self.active_indices()] = values
        return out.reshape((self.res,) * 3)


def focus_point(cams: Cameras) -> np.ndarray | None:
    """[3] least-squares point nearest to every camera's optical axis, or None when the
    axes are (nearly) parallel. The point an orbit-style capture looks at."""
    if len(cams) < 2:
        return None
    d = cams.view_dirs
    c = cams.centres
    proj = np.eye(3)[None] - d[:, :, None] * d[:, None, :]  # [N, 3, 3] projectors orthogonal to each axis
    A = proj.sum(0)
    b = np.einsum("nij,nj->i", proj, c)
    w = np.linalg.eigvalsh(A)
    if w[0] < 1e-3 * max(w[-1], 1e-300):
        return None
    return np.linalg.solve(A, b)


def box_from_cameras(cams: Cameras, margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """A scene box from the cameras alone (used when no box and no points are given).

    The bounding box of the camera centres, grown to include the point the cameras
    look at (their optical axes' least-squares focus, when it lies within one box
    diagonal of the centres: an orbit around an object), then padded by ``margin`` of
    its largest side, and widened so that no side is below 10% of the largest (all
    cameras at one height would otherwise give a flat box).

    Returns:
        (box_min [3], box_max [3]).
    """
    if len(cams) == 0:
        raise ValueError("cannot derive a box from zero cameras")
    c = cams.centres
    lo, hi = c.min(0), c.max(0)
    diag = float(np.linalg.norm(hi - lo))
    f = focus_point(cams)
    if f is not None and np.all(np.abs(f - 0.5 * (lo + hi)) <= diag):
        lo, hi = np.minimum(lo, f), np.maximum(hi, f)
    side = hi - lo
    big = float(side.max())
    if big == 0.0:  # one camera or all at one point: a unit box around it
        big = 1.0
    grow = np.maximum(side, 0.1 * big) - side
    lo, hi = lo - 0.5 * grow, hi + 0.5 * grow
    pad = margin * big
    return lo - pad, hi + pad
