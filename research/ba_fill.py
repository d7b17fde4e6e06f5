"""How dear a direct solve of a global bundle adjustment would be, for prefixes of a finished model
(issue 36, part 5: choose each global adjustment's solver from the model's shape;
docs/investigations/sfm.md#global-ba-solver).

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

from curate.sfm.mapping import fill_per_photo


fill_of_tracks = fill_per_photo   # the product's measure (curate.sfm.mapping), by its research name


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
