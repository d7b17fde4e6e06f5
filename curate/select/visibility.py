"""Which cameras observe which nodes, and the sparse index the selection works on.

Visibility is a replaceable piece: anything with the :class:`Visibility` signature
(``(cameras, nodes [m, 3]) -> bool [m, K]``) can stand in for the frustum test, e.g.
an occlusion-aware test that also asks the occupancy grid whether the segment from
the camera to the node is free.

:class:`FrustumVisibility` (the paper's): a node is observed by a camera when it lies
in front of it (positive depth) and projects inside the image,
``0 <= u < width, 0 <= v < height``. A node exactly at a camera's centre has depth 0
and is therefore *not* observed by that camera (its direction would be undefined). So that
this holds at every scale and offset of the scene, a depth is taken as 0 when it is below
the rounding noise of its own computation or of the scene's coordinates: ``z <= DEPTH_TOL *
max(|x r0| + |y r1| + |z r2| + |r3|, L)``, the magnitudes of its terms and L the extent of the
camera centres (:func:`depth_floor`), about 10^4 times the float64 noise.
The test is evaluated without division, as ``z > 0, 0 <= u' < W z, 0 <= v' < H z``
with ``[u', v', z] = K [R | t] X``, one fixed order of float64 operations per
(node, camera) pair, so chunking never changes a result.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from curate.select.bins import DirectionBins
from curate.core.cameras import Cameras
from curate.core.executors import cpu_count


class Visibility(Protocol):
    def __call__(self, cams: Cameras, nodes: np.ndarray) -> np.ndarray:
        """bool [m, K]: True where node i is observed by camera k."""
        ...


def projection_rows(cams: Cameras) -> np.ndarray:
    """[3, 4, K] rows of each camera's ``K [R | t]`` (world to homogeneous pixels)."""
    R, t = cams.w2c()
    P = np.einsum("nij,njk->nik", cams.K, np.concatenate([R, t[:, :, None]], axis=2))  # [K, 3, 4]
    return np.ascontiguousarray(np.transpose(P, (1, 2, 0)))


def _affine(X, Y, Z, row):
    """((X a + Y b) + Z c) + d, broadcast [m, 1] x [K] -> [m, K], in this exact order."""
    out = X * row[0]
    out += Y * row[1]
    out += Z * row[2]
    out += row[3]
    return out


@dataclass(frozen=True)
class FrustumVisibility:
    """Frustum (no occlusion) visibility, see the module docstring."""

    def __call__(self, cams: Cameras, nodes: np.ndarray) -> np.ndarray:
        P = projection_rows(cams)
        return frustum_mask(P, cams.width.astype(np.float64), cams.height.astype(np.float64), nodes,
                            depth_floor(cams))


DEPTH_TOL = 1e-12
"""A depth at or below this fraction of the magnitude of its terms counts as 0 (see the module docstring)."""


def depth_floor(cams: Cameras) -> float:
    """Depths at or below this count as 0: ``DEPTH_TOL`` times the extent of the camera centres
    (the scene's length scale; 0 for a single camera)."""
    c = np.asarray(cams.centres, np.float64)
    return DEPTH_TOL * float(np.max(np.ptp(c, axis=0))) if len(c) > 1 else 0.0


def frustum_mask(P: np.ndarray, W: np.ndarray, H: np.ndarray, nodes: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """bool [m, K] frustum test for nodes [m, 3] against projections ``P`` [3, 4, K]; ``floor``:
    :func:`depth_floor`."""
    return _frustum_ops(np.asarray(nodes, np.float64), P, W, H, floor)


def _frustum_ops(nodes, P, W, H, floor: float = 0.0):
    """The frustum test's operations, for numpy arrays or torch tensors alike (same order)."""
    X, Y, Z = nodes[:, 0:1], nodes[:, 1:2], nodes[:, 2:3]
    z = _affine(X, Y, Z, P[2])
    vis = z > DEPTH_TOL * _affine(abs(X), abs(Y), abs(Z), abs(P[2]))
    vis &= z > floor
    u = _affine(X, Y, Z, P[0])
    vis &= u >= 0
    vis &= u < W * z
    del u
    v = _affine(X, Y, Z, P[1])
    vis &= v >= 0
    vis &= v < H * z
    return vis


def frustum_visible_reference(cams: Cameras, node) -> list[bool]:
    """Plain-Python frustum test of one node against each camera (reference for tests)."""
    P = projection_rows(cams)
    floor = depth_floor(cams)
    x, y, zc = (float(c) for c in node)
    out = []
    for k in range(len(cams)):
        r = [[float(P[i, j, k]) for j in range(4)] for i in range(3)]
        z = ((x * r[2][0] + y * r[2][1]) + zc * r[2][2]) + r[2][3]
        zmag = ((abs(x * r[2][0]) + abs(y * r[2][1])) + abs(zc * r[2][2])) + abs(r[2][3])
        u = ((x * r[0][0] + y * r[0][1]) + zc * r[0][2]) + r[0][3]
        v = ((x * r[1][0] + y * r[1][1]) + zc * r[1][2]) + r[1][3]
        out.append(z > DEPTH_TOL * zmag and z > floor and 0 <= u < float(cams.width[k]) * z
                   and 0 <= v < float(cams.height[k]) * z)
    return out


@dataclass
class PairIndex:
    """Sparse (node, camera) observation pairs with their direction bins.

    Node-major arrays (pairs sorted by node, then camera):
        indptr: [M + 1] int64, pairs of node p are ``indptr[p]:indptr[p + 1]``.
        cam: [P] camera index of each pair (uint16 when K < 65536, else int32).
        nb: [P] ``node * n_bins + bin``, the flat (node, direction bin) cell of each pair,
            the bin being that of the direction from the node to the camera centre
            (int32 when M * B < 2^31, else int64).
    Camera-major view:
        cam_indptr: [K + 1] int64; cam_pos[cam_indptr[k]:cam_indptr[k + 1]] are the
        positions (into the node-major arrays) of camera k's pairs, in node order.
    """

    n_nodes: int
    n_cams: int
    n_bins: int
    indptr: np.ndarray
    cam: np.ndarray
    nb: np.ndarray
    cam_indptr: np.ndarray
    cam_pos: np.ndarray

    @property
    def n_pairs(self) -> int:
        return int(self.indptr[-1])

    def camera_pairs(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(nodes [n] int64, bins [n] int64) observed by camera ``k``, nodes ascending."""
        nb = self.nb[self.cam_pos[self.cam_indptr[k]:self.cam_indptr[k + 1]]].astype(np.int64)
        return np.divmod(nb, self.n_bins)

    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.indptr, self.cam, self.nb, self.cam_indptr, self.cam_pos))


def _torch_device(device: str | None):
    import torch
    if device in (None, "auto"):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


class _TorchFrustum:
    """The frustum test of :func:`frustum_mask`, with torch, plus each pair's direction bin.

    The same float64 operations in the same order as :func:`frustum_mask`, so the
    results are identical. On CPU, chunks run in a pool of Python threads, each with
    single-threaded torch ops (torch releases the GIL): unlike torch's own OpenMP
    threads, this degrades gracefully when other processes share the cores.
    """

    def __init__(self, cams: Cameras, nodes: np.ndarray, bins: DirectionBins, device: str | None):
        import torch
        self.dev = _torch_device(device)
        to = lambda a: torch.from_numpy(np.ascontiguousarray(a)).to(self.dev)  # noqa: E731
        self.P, self.C, self.nodes = to(projection_rows(cams)), to(cams.centres), to(nodes)
        self.W, self.H = to(cams.width.astype(np.float64)), to(cams.height.astype(np.float64))
        self.bins = bins
        self.floor = depth_floor(cams)

    def __call__(self, start: int, stop: int):
        import torch
        nd = self.nodes[start:stop]
        rows, cols = torch.nonzero(_frustum_ops(nd, self.P, self.W, self.H, self.floor), as_tuple=True)
        d = (self.C[cols] - nd[rows]).cpu().numpy()
        return start, rows.cpu().numpy(), cols.cpu().numpy(), self.bins.assign(d)

    def run(self, chunk_nodes: int, progress: bool):
        """Yield (start, rows, cols, bins) per node chunk, in node order."""
        import torch
        from collections import deque
        from concurrent.futures import ThreadPoolExecutor
        M = self.nodes.shape[0]
        jobs = [(s, min(s + chunk_nodes, M)) for s in range(0, M, chunk_nodes)]
        if progress:
            from tqdm import tqdm
            jobs = tqdm(jobs, desc="visibility", unit="chunk", leave=False, delay=1.0)
        if self.dev.type != "cpu":
            for a, b in jobs:
                yield self(a, b)
            return
        workers, prev = cpu_count(), torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            with ThreadPoolExecutor(workers) as ex:
                pending: deque = deque()
                for a, b in jobs:  # at most 2 chunks per worker in flight: bounded memory
                    pending.append(ex.submit(self, a, b))
                    if len(pending) >= 2 * workers:
                        yield pending.popleft().result()
                while pending:
                    yield pending.popleft().result()
        finally:
            torch.set_num_threads(prev)


def build_pair_index(cams: Cameras, nodes: np.ndarray, bins: DirectionBins,
                     visibility: Visibility | None = None, chunk_pairs: int = 1 << 18,
                     device: str | None = None, progress: bool = False) -> PairIndex:
    """Evaluate visibility of every (node, camera) pair and keep the observed ones.

    Args:
        cams: K cameras.
        nodes: [M, 3] node coordinates.
        bins: direction binning.
        visibility: the visibility test; None is the frustum test, run with torch
            (all CPU threads, or CUDA when available / asked for by ``device``).
        chunk_pairs: pairs evaluated at once (bounds the scratch memory, ~30 B per pair).
        device: torch device for the frustum test ("cpu", "cuda", None = auto).
        progress: show a tqdm bar.
    Memory: about 10 bytes per observed pair (2 camera + 4 cell + 4 camera-major position).
    """
    nodes = np.ascontiguousarray(np.asarray(nodes, np.float64).reshape(-1, 3))
    M, K, B = nodes.shape[0], len(cams), bins.n_bins
    cam_dtype = np.uint16 if K < (1 << 16) else np.int32
    nb_dtype = np.int32 if M * B < (1 << 31) else np.int64
    counts = np.zeros(M, np.int64)
    cam_parts, nb_parts = [], []
    if K > 0 and M > 0:
        if visibility is None or isinstance(visibility, FrustumVisibility):
            chunks = _TorchFrustum(cams, nodes, bins, device).run(max(1, chunk_pairs // K), progress)
        else:
            chunks = _generic_pairs(cams, nodes, bins, visibility, chunk_pairs)
        for s, rows, cols, b in chunks:
            counts[s:s + np.max(rows, initial=-1) + 1] += np.bincount(rows)
            cam_parts.append(cols.astype(cam_dtype))
            nb_parts.append(((rows + s) * B + b).astype(nb_dtype))
    cam = np.concatenate(cam_parts) if cam_parts else np.zeros(0, cam_dtype)
    nb = np.concatenate(nb_parts) if nb_parts else np.zeros(0, nb_dtype)
    del cam_parts, nb_parts
    indptr = np.zeros(M + 1, np.int64)
    np.cumsum(counts, out=indptr[1:])
    cam_indptr = np.zeros(K + 1, np.int64)
    np.cumsum(chunked_bincount(cam, K), out=cam_indptr[1:])
    return PairIndex(M, K, B, indptr, cam, nb, cam_indptr, _camera_major(cam, cam_indptr))


def chunked_bincount(x: np.ndarray, minlength: int, weights=None, chunk: int = 1 << 22) -> np.ndarray:
    """``np.bincount`` over a large small-int array without its [P] int64 copy.

    Args:
        x: [P] non-negative ints (any int dtype).
        minlength: output length.
        weights: None, or a function ``(start, stop) -> [stop - start] float64`` giving the
            weights of ``x[start:stop]`` (so they are never materialised whole).
    Returns:
        [minlength] float64 when weighted, int64 otherwise.
    """
    out = np.zeros(minlength, np.float64 if weights is not None else np.int64)
    for s in range(0, x.size, chunk):
        e = min(s + chunk, x.size)
        out += np.bincount(x[s:e], weights=None if weights is None else weights(s, e), minlength=minlength)
    return out


def _generic_pairs(cams: Cameras, nodes: np.ndarray, bins: DirectionBins, visibility: Visibility,
                   chunk_pairs: int):
    step = max(1, chunk_pairs // len(cams))
    centres = cams.centres
    for s in range(0, nodes.shape[0], step):
        chunk = nodes[s:s + step]
        rows, cols = np.nonzero(np.asarray(visibility(cams, chunk), bool))
        yield s, rows, cols, bins.assign(centres[cols] - chunk[rows])


def _camera_major(cam: np.ndarray, cam_indptr: np.ndarray, chunk: int = 1 << 22) -> np.ndarray:
    """[P] positions of the pairs grouped by camera (stable), by a chunked counting sort
    (no [P] int64 temporary)."""
    P = cam.size
    out = np.empty(P, np.int32 if P < (1 << 31) else np.int64)
    cursor = cam_indptr[:-1].copy()
    for s in range(0, P, chunk):
        c = cam[s:s + chunk].astype(np.int64)
        order = np.argsort(c, kind="stable")
        sc = c[order]
        first = np.flatnonzero(np.r_[True, sc[1:] != sc[:-1]])
        group_len = np.diff(np.r_[first, sc.size])
        rank = np.arange(sc.size) - np.repeat(first, group_len)
        out[cursor[sc] + rank] = order + s
        np.add.at(cursor, sc[first], group_len)
    return out
