"""Baseline selections: random, farthest-view sampling, hemisphere.

Each returns the chosen pool indices in order, excluding ``initial`` (taken as
already chosen), like :func:`curate.select.greedy.greedy_select`.
"""

from __future__ import annotations

import numpy as np

from curate.core.cameras import Cameras, look_at
from curate.core.grid import focus_point


def random_subset(n_pool: int, budget: int, seed: int = 0, initial=()) -> list[int]:
    """``budget`` distinct pool indices drawn uniformly (seeded), none of ``initial``."""
    avail = np.setdiff1d(np.arange(n_pool), np.asarray(list(initial), np.int64))
    rng = np.random.default_rng(seed)
    return [int(k) for k in rng.permutation(avail)[:max(0, int(budget))]]


def stride_subset(n_pool: int, budget: int, initial=()) -> list[int]:
    """``budget`` pool indices evenly spaced in index order (every (n / budget)-th of the n
    indices not in ``initial``, centred): what people do with a video, since curate keeps
    cameras sorted by name and numbered frames sort in capture order."""
    avail = np.setdiff1d(np.arange(n_pool), np.asarray(list(initial), np.int64))
    b = min(max(0, int(budget)), len(avail))
    return [int(k) for k in avail[((np.arange(b) + 0.5) * len(avail) / max(b, 1)).astype(np.int64)]]


def farthest_view(cams: Cameras, budget: int, initial=(), rot_weight: float = 0.0) -> list[int]:
    """Farthest-view sampling (as in NeRF Director): repeatedly add the camera farthest
    from every camera chosen so far.

    Distance between cameras i, j: ``|c_i - c_j| + rot_weight * D * angle(d_i, d_j) / pi``,
    with c the centres, d the viewing directions and D the diagonal of the centres'
    bounding box (1 when all centres coincide; so ``rot_weight = 1`` makes opposite views as far apart as the two
    most distant centres). Default 0: centres only. Without ``initial`` the first pick is
    the camera nearest the centroid of all centres. Ties go to the lowest index.
    """
    n = len(cams)
    budget = min(max(0, int(budget)), n - len(set(initial)))
    if budget <= 0:
        return []
    c = cams.centres
    d = cams.view_dirs
    diag = float(np.linalg.norm(c.max(0) - c.min(0))) if n else 0.0
    diag = diag if diag > 0 else 1.0  # all centres at one point: angles alone separate views

    def dist_to(k: int) -> np.ndarray:
        out = np.linalg.norm(c - c[k], axis=1)
        if rot_weight > 0:
            out = out + rot_weight * diag / np.pi * np.arccos(np.clip(d @ d[k], -1.0, 1.0))
        return out

    return farthest_point(n, budget, dist_to, int(np.argmin(np.linalg.norm(c - c.mean(0), axis=1))), initial)


def farthest_point(n: int, budget: int, dist_to, first: int, initial=()) -> list[int]:
    """Greedy k-center order over ``n`` items: repeatedly the item farthest from every item
    taken so far (``initial`` included). ``dist_to(k)``: [n] distances from item k to every
    item. Without ``initial`` the first pick is ``first``. Ties go to the lowest index."""
    budget = min(max(0, int(budget)), n - len(set(initial)))
    taken = np.zeros(n, bool)
    mind = np.full(n, np.inf)
    for k in initial:
        taken[k] = True
        mind = np.minimum(mind, dist_to(k))
    chosen: list[int] = []
    if budget > 0 and not np.any(taken):
        chosen.append(first)
        taken[first] = True
        mind = dist_to(first)
    while len(chosen) < budget:
        k = int(np.argmax(np.where(taken, -np.inf, mind)))
        chosen.append(k)
        taken[k] = True
        mind = np.minimum(mind, dist_to(k))
    return chosen


def fibonacci_hemisphere(n: int, up=(0.0, 0.0, 1.0), min_elevation: float = 0.0) -> np.ndarray:
    """[n, 3] unit directions spread evenly over the hemisphere around ``up``, from
    ``min_elevation`` (radians above the horizon) to the pole."""
    up = np.asarray(up, np.float64)
    up = up / np.linalg.norm(up)
    i = np.arange(n) + 0.5
    zlo = np.sin(min_elevation)
    z = zlo + (1.0 - zlo) * i / max(n, 1)
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    local = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    # Rotate +z onto up.
    a = np.array([1.0, 0, 0]) if abs(up[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(up, a)
    x /= np.linalg.norm(x)
    y = np.cross(up, x)
    return local @ np.stack([x, y, up])


def hemisphere_cameras(center, radius: float, n: int, fx: float, width: int, height: int,
                       up=(0.0, 0.0, 1.0), min_elevation: float = np.radians(10.0)) -> Cameras:
    """n cameras on a hemisphere of ``radius`` around ``center``, each looking at it
    (the usual object-centric NeRF capture); square pixels, centred principal point."""
    dirs = fibonacci_hemisphere(n, up, min_elevation)
    centres = np.asarray(center, np.float64) + radius * dirs
    return Cameras(look_at(centres, center, up), fx, fx, width / 2.0, height / 2.0, width, height)


def hemisphere_subset(cams: Cameras, budget: int, center=None, up=(0.0, 0.0, 1.0), initial=()) -> list[int]:
    """Pool cameras closest in direction to an even hemisphere of viewpoints around ``center``.

    ``center`` defaults to the point the pool's optical axes converge to (else the
    centroid of the centres). For each of ``budget`` Fibonacci-hemisphere directions, in
    order, the unused camera whose direction from the centre is closest is taken.
    """
    n = len(cams)
    taken = np.zeros(n, bool)
    taken[list(initial)] = True
    budget = min(max(0, int(budget)), int((~taken).sum()))
    if budget == 0:
        return []
    if center is None:
        center = focus_point(cams)
        if center is None:
            center = cams.centres.mean(0)
    v = cams.centres - np.asarray(center, np.float64)
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    v = np.where(norm > 0, v / np.where(norm > 0, norm, 1.0), 0.0)
    chosen = []
    for t in fibonacci_hemisphere(budget, up):
        k = int(np.argmax(np.where(taken, -np.inf, v @ t)))
        chosen.append(k)
        taken[k] = True
    return chosen
