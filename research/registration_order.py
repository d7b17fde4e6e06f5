"""In what order did COLMAP's incremental mapper register a run's frames? Read from ``RUN/sfm/colmap.log`` (its
"Registering image #ID (num_reg_frames=N)" lines, the first mapping of the log) and named by truth index, for a
range of frames. Prints JSON: {truth index: [rank of its registration, frames registered before it]}.

    python -m research.registration_order RUN CASE.truth.json --show 325-351
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path


def main(argv=None) -> dict:
    import pycolmap

    from research.takes import truth_of
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("truth", type=Path)
    ap.add_argument("--show", default="0-100000", help="A-B: truth indices shown")
    a = ap.parse_args(argv)
    sfm = a.run / "sfm"
    recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
    gt = truth_of(recs, json.loads(a.truth.read_text()))
    from research.rundb import database_copy
    with database_copy(sfm / "database.db") as copy, pycolmap.Database.open(copy) as d:
        truth_of_id = {im.image_id: gt.get(im.name) for im in d.read_all_images()}
    first: dict[int, list[int]] = {}
    rank = 0
    for line in (sfm / "colmap.log").read_text(errors="replace").splitlines():
        m = re.search(r"Registering image #(\d+) \(num_reg_frames=(\d+)\)", line)
        if m:
            t = truth_of_id.get(int(m.group(1)))
            if t is not None and t not in first:
                first[t] = [rank, int(m.group(2)) - 1]
            rank += 1
    lo, hi = map(int, a.show.split("-"))
    out = {t: first.get(t) for t in range(lo, hi + 1)}
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
