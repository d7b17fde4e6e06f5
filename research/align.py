"""Similarity alignment of camera sets and pose errors against a reference.

Used by tests and benchmarks to compare an SfM result (arbitrary frame and scale)
with ground-truth poses.
"""

from __future__ import annotations

from pathlib import PurePosixPath
from typing import Callable

import numpy as np

from curate.core.cameras import Cameras, rotation_angle_deg


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity ``dst ~ s * R @ src + t`` (Umeyama 1991).

    Args:
        src, dst: [N, 3] corresponding points, N >= 3 (not all collinear).
    Returns:
        s: scale, R: [3, 3] rotation (det +1), t: [3] translation.
    """
    src = np.asarray(src, np.float64)
    dst = np.asarray(dst, np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 3:
        raise ValueError(f"umeyama: need two [N>=3, 3] arrays, got {src.shape} and {dst.shape}")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1
    R = U @ S @ Vt
    var_s = (xs ** 2).sum() / len(src)
    s = float(np.trace(np.diag(D) @ S) / var_s) if with_scale and var_s > 0 else 1.0
    t = mu_d - s * R @ mu_s
    return s, R, t


def basename_key(name: str) -> str:
    """Default matching key: the file name without folders and without its extension (the last
    suffix only: video frames named by time, ``walk_000012.300.jpg``, keep their milliseconds)."""
    return PurePosixPath(name.replace("\\", "/")).stem


def match_names(est: Cameras, ref: Cameras, key: Callable[[str], str] = basename_key) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i_est [M], i_ref [M])`` of the cameras present in both, by ``key(name)``."""
    ref_idx = {key(n): j for j, n in enumerate(ref.names)}
    pairs = [(i, ref_idx[key(n)]) for i, n in enumerate(est.names) if key(n) in ref_idx]
    if not pairs:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    a = np.array(pairs, np.int64)
    return a[:, 0], a[:, 1]


def pose_errors(est: Cameras, ref: Cameras, key: Callable[[str], str] = basename_key) -> dict:
    """Errors of ``est`` against ``ref`` after the best similarity of camera centres.

    Cameras are paired by ``key(name)``. The similarity is fitted on all pairs, then
    refitted on those within 3x the median centre residual (robust to a few lost
    cameras). The centre error is relative to the *extent* of the reference: the
    diagonal of the bounding box of the paired reference centres.

    Returns:
        dict: ``n_matched``, ``rotation_deg_median``, ``rotation_deg_max``,
        ``centre_rel_median``, ``centre_rel_max``, ``extent``, ``scale`` and the per-camera
        arrays ``rotation_deg`` [M], ``centre_rel`` [M] and ``names`` (lists).
    """
    ie, ir = match_names(est, ref, key)
    if len(ie) < 3:
        raise ValueError(f"pose_errors: only {len(ie)} cameras in common")
    ce, cr = est.centres[ie], ref.centres[ir]
    s, R, t = umeyama(ce, cr)
    res = np.linalg.norm(s * ce @ R.T + t - cr, axis=1)
    inl = res <= 3 * np.median(res) + 1e-12
    if inl.sum() >= 3 and not inl.all():
        s, R, t = umeyama(ce[inl], cr[inl])
    extent = float(np.linalg.norm(cr.max(0) - cr.min(0)))
    cerr = np.linalg.norm(s * ce @ R.T + t - cr, axis=1) / max(extent, 1e-12)
    Ra = R @ est.rotations[ie]                      # [M, 3, 3] estimated c2w rotations in the ref frame
    rdeg = rotation_angle_deg(np.einsum("nji,njk->nik", ref.rotations[ir], Ra))
    return {"n_matched": int(len(ie)), "rotation_deg_median": float(np.median(rdeg)),
            "rotation_deg_max": float(rdeg.max()), "centre_rel_median": float(np.median(cerr)),
            "centre_rel_max": float(cerr.max()), "extent": extent, "scale": float(s),
            "rotation_deg": rdeg.tolist(), "centre_rel": cerr.tolist(), "names": [est.names[i] for i in ie]}
