"""How dear a direct solve of a global bundle adjustment would be, for prefixes of a finished model
(issue 36, part 5: choose each global adjustment's solver from the model's shape; docs/sfm.md,
"Which solver for a global adjustment past 1,000 photos").

A direct solve factors the reduced camera system: one block row per photo, a block wherever two
photos see a common point. Its cost is the fill of that factor under a fill-reducing ordering
(here SuperLU's minimum degree on the photo-level pattern, a stand-in for Ceres' own ordering):
``nnz_L_per_photo`` and ``flops`` (sum of squared column counts of L, scalar; a block solve is
about 6**3 times that). A walk down a hall sees each point from nearby photos only (a band), a
room circled again and again from photos all along the walk (fill that grows with the pool).

    python3 -m research.ba_fill MODEL [N ...]     # MODEL: a COLMAP sparse model folder; N: prefixes
"""
from __future__ import annotations

import json
import sys

import numpy as np


def fill_of_tracks(tracks: list, n: int) -> dict:
    """Fill of the reduced camera system of ``n`` photos whose points are seen by ``tracks`` (each a
    sequence of photo indices in [0, n), tracks of fewer than 2 distinct photos ignored).

    Returns ``{"n", "pattern_per_photo", "nnz_L_per_photo", "flops"}``: nonzeros per photo of the
    system's pattern (diagonal included) and of its Cholesky factor, and the factor's scalar flops."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu
    rows, cols = [np.arange(n)], [np.arange(n)]
    for t in tracks:
        a = np.unique(np.asarray(t, dtype=np.int64))
        if len(a) >= 2:
            r, c = np.meshgrid(a, a)
            rows.append(r.ravel())
            cols.append(c.ravel())
    r, c = np.concatenate(rows), np.concatenate(cols)
    S = sp.csc_matrix((np.ones(len(r)), (r, c)), shape=(n, n))
    S.data[:] = 1.0
    pattern = S.nnz
    S = sp.csc_matrix(S + sp.identity(n) * (S.sum(axis=1).max() + 1))   # diagonally dominant: no pivoting
    L = splu(S, permc_spec="MMD_AT_PLUS_A", options=dict(SymmetricMode=True)).L.tocsc()
    col = np.diff(L.indptr).astype(float)
    return {"n": n, "pattern_per_photo": round(pattern / n, 1), "nnz_L_per_photo": round(L.nnz / n, 1),
            "flops": float((col ** 2).sum())}


def model_fill(model: str, prefixes: list[int]) -> list[dict]:
    """:func:`fill_of_tracks` of the first N registered photos of ``model`` in name order (the capture's
    order for a video), for each N of ``prefixes`` (all of them when empty)."""
    import pycolmap
    rec = pycolmap.Reconstruction(model)
    order = sorted(rec.reg_image_ids(), key=lambda i: rec.image(i).name)
    tracks = [[e.image_id for e in p.track.elements] for p in rec.points3D.values()]
    out = []
    for n in prefixes or [len(order)]:
        pos = {im: k for k, im in enumerate(order[:n])}
        out.append(fill_of_tracks([[pos[i] for i in t if i in pos] for t in tracks], len(pos)))
    return out


if __name__ == "__main__":
    for row in model_fill(sys.argv[1], [int(a) for a in sys.argv[2:]]):
        print(json.dumps({"model": sys.argv[1], **row}), flush=True)
