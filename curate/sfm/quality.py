"""Per-photo quality before SfM: sharpness and near-duplicates.

* Sharpness: variance of the Laplacian (``skimage.filters.laplace``) of a grey thumbnail
  whose longer side is ``THUMB`` pixels, so values compare across photo sizes. A photo
  is *blurry* when its sharpness is below ``blur_fraction`` times the pool's median.
* Near-duplicates: a 256-bit DCT perceptual hash (pHash: sign of the 16x16 lowest DCT
  frequencies of a 64x64 grey thumbnail against their median). Two photos whose hashes
  differ in at most ``dup_max_distance`` bits are duplicates; of such a pair the sharper
  one is kept.

Defaults (see ``curate.sfm.config.SfmConfig``): duplicates are dropped only when the hashes
are (almost) identical (distance <= 4 of 256 bits; consecutive video frames of a walk
differ by 12 or more): a burst or a camera standing still,
which add nothing to SfM or to NeRF training); blurry photos are *flagged but kept*,
because a "blurry" photo may be the only view of a region and the selection stage
weighs quality against coverage anyway. Both are recorded per photo.
"""

from __future__ import annotations

import logging

import numpy as np

logger = logging.getLogger(__name__)

THUMB = 512  # longer side of the sharpness thumbnail, pixels
HASH_SIDE = 16  # pHash uses HASH_SIDE x HASH_SIDE DCT coefficients -> 256 bits


def _grey(rgb: np.ndarray, longer: int | None = None, size: tuple[int, int] | None = None) -> np.ndarray:
    from PIL import Image
    im = Image.fromarray(np.asarray(rgb, np.uint8)).convert("L")
    if size is None:
        w, h = im.size
        s = longer / max(w, h)
        size = (max(1, round(w * s)), max(1, round(h * s)))
    return np.asarray(im.resize(size, Image.BILINEAR), np.float64) / 255.0


def sharpness(rgb: np.ndarray) -> float:
    """Variance of the Laplacian of a grey thumbnail (longer side ``THUMB``) of ``rgb`` [H, W, 3] uint8."""
    from skimage.filters import laplace
    return float(np.var(laplace(_grey(rgb, longer=THUMB))))


def _dct_matrix(n: int) -> np.ndarray:
    k = np.arange(n)[:, None]
    m = np.cos(np.pi * (2 * np.arange(n)[None, :] + 1) * k / (2 * n))
    m[0] *= 1 / np.sqrt(2)
    return m * np.sqrt(2 / n)


def phash(rgb: np.ndarray) -> np.ndarray:
    """Perceptual hash of ``rgb`` [H, W, 3]: [HASH_SIDE * HASH_SIDE] bool."""
    g = _grey(rgb, size=(4 * HASH_SIDE, 4 * HASH_SIDE))
    d = _dct_matrix(g.shape[0])
    coef = (d @ g @ d.T)[:HASH_SIDE, :HASH_SIDE].ravel()
    bits = coef > np.median(coef[1:])  # the DC term (mean brightness) is compared too, harmlessly
    return bits


def hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamming distances between hash sets ``a`` [N, B] and ``b`` [M, B] (bool): [N, M] int."""
    a = np.asarray(a, np.int32)
    b = np.asarray(b, np.int32)
    return (a @ (1 - b).T + (1 - a) @ b.T).astype(np.int64)


def assess(sharp: np.ndarray, hashes: np.ndarray, blur_fraction: float = 0.3,
           dup_max_distance: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flag blurry photos and near-duplicates.

    Args:
        sharp: [N] sharpness values.
        hashes: [N, B] bool perceptual hashes.
    Returns:
        blurry: [N] bool, sharpness < blur_fraction * median.
        dup_of: [N] int, index of the photo this one duplicates (kept instead), -1 if none.
        dup_dist: [N] int, hash distance to that photo (-1 if none).
    """
    sharp = np.asarray(sharp, np.float64)
    n = len(sharp)
    blurry = sharp < blur_fraction * np.median(sharp) if n else np.zeros(0, bool)
    dup_of = np.full(n, -1, np.int64)
    dup_dist = np.full(n, -1, np.int64)
    if n < 2 or dup_max_distance < 0:
        return blurry, dup_of, dup_dist
    dist = hamming(hashes, hashes)
    np.fill_diagonal(dist, 1 << 30)
    # greedy: visit photos from the sharpest; each keeps its unclaimed near-duplicates out
    kept = np.zeros(n, bool)
    for i in np.argsort(-sharp, kind="stable"):
        if dup_of[i] >= 0:
            continue
        kept[i] = True
        close = np.flatnonzero((dist[i] <= dup_max_distance) & ~kept & (dup_of < 0))
        dup_of[close] = i
        dup_dist[close] = dist[i, close]
    return blurry, dup_of, dup_dist


def files_sharpness(paths, progress: bool = False) -> np.ndarray:
    """[N] :func:`sharpness` of the image files ``paths`` (any format ``curate.sfm.ingest``
    reads, RAW included); NaN for a file that cannot be read (logged)."""
    from tqdm import tqdm
    from curate.core.images import read_image
    out = np.full(len(paths), np.nan)
    for i, p in enumerate(tqdm(paths, desc="sharpness", disable=not progress, leave=False)):
        try:
            out[i] = sharpness(read_image(p)[0])
        except (OSError, ValueError) as e:
            logger.warning("sharpness: cannot read %s (%s)", p, e)
    return out
