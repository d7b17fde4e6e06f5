"""How far apart a capture's matched pairs are, and how many verify, from a run folder's database.

Frames are put in name order (COLMAP's sequential order); for each distance between the two frames of a pair that
was matched, the pairs and those with at least ``--min`` verified inliers (``SfmConfig.min_num_matches``). With
``--far D``, the verified pairs at least D frames apart that loop detection did not list (``loop_pairs.txt``).
Prints one JSON object. docs/investigations/sfm.md#sequential-neighbours.

    python -m research.pair_distances RUN [RUN ...] [--distances 1 2 4 8 16 32 64 128 256] [--far 64]
"""

from __future__ import annotations

import argparse
import json
import sqlite3
from pathlib import Path

PAIR_ID_FACTOR = 2147483647   # COLMAP: pair_id = id1 * 2^31 - 1 + id2, id1 < id2


def by_distance(run: Path, min_inliers: int) -> tuple[dict[int, list[int]], list[dict]]:
    """({distance: [inliers of each matched pair]}, [each pair: names, distance, inliers, configuration])."""
    from research.rundb import database_copy
    with database_copy(run / "sfm" / "database.db") as db:   # a read-only reader leaves the log's files beside it
        con = sqlite3.connect(db)
        try:
            names = dict(con.execute("SELECT image_id, name FROM images"))
            rows = con.execute("SELECT pair_id, rows, config FROM two_view_geometries").fetchall()
        finally:
            con.close()
    order = {i: k for k, i in enumerate(sorted(names, key=names.get))}
    dist: dict[int, list[int]] = {}
    pairs = []
    for pid, n, config in rows:
        b, a = pid % PAIR_ID_FACTOR, pid // PAIR_ID_FACTOR
        d = abs(order[a] - order[b])
        dist.setdefault(d, []).append(n)
        pairs.append({"pair": sorted((names[a], names[b])), "distance": d, "inliers": n, "config": config})
    return dist, pairs


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--distances", type=int, nargs="*", default=[1, 2, 4, 8, 16, 32, 64, 128, 256])
    ap.add_argument("--min", type=int, default=15, help="verified: at least this many inliers")
    ap.add_argument("--far", type=int, default=0, help="list the verified pairs this far apart or more, not loop pairs")
    a = ap.parse_args(argv)
    out = {}
    for run in a.runs:
        dist, pairs = by_distance(run, a.min)
        rec = {str(d): {"pairs": len(dist.get(d, [])), "verified": sum(n >= a.min for n in dist.get(d, []))}
               for d in a.distances}
        if a.far:
            loops = run / "sfm" / "loop_pairs.txt"
            listed = {tuple(sorted(ln.split())) for ln in loops.read_text().splitlines()} if loops.is_file() else set()
            rec["far_not_loop"] = [p for p in pairs if p["distance"] >= a.far and p["inliers"] >= a.min
                                   and tuple(p["pair"]) not in listed]
        out[str(run)] = rec
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
