"""The fox's SfM at the working sizes the tests could use: wall time, photos registered and distance from its
published poses, one JSON line per size (docs/results.md#test-time: the tests' fox runs at 320 px).

    python -m research.fox_sizes --fox ../shared/data/fox --sizes 480 320 --work /tmp/w
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def measure(fox: Path, size: int, out: Path) -> dict:
    from curate.core.transforms_json import read_transforms
    from curate.sfm.colmap import run_sfm
    from curate.sfm.config import SfmConfig
    from curate.sfm.io import load_sfm
    from research.align import pose_errors
    ref, _ = read_transforms(fox / "transforms.json")
    t0 = time.time()
    run_sfm(SfmConfig(max_image_size=size, progress=False), fox / "images", out)
    wall = time.time() - t0
    st = json.loads((out / "sfm" / "stage.json").read_text())
    cams = load_sfm(out).cameras
    e = pose_errors(cams, ref)
    return {"size": size, "wall": round(wall, 1), "timings": st.get("timings"), "registered": len(cams),
            "rot_median_deg": e["rotation_deg_median"], "rot_max_deg": e.get("rotation_deg_max"),
            "centre_rel_median": e["centre_rel_median"]}


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fox", type=Path, required=True, help="the fox set: images/ and transforms.json")
    ap.add_argument("--sizes", type=int, nargs="+", default=[480, 320])
    ap.add_argument("--work", type=Path, required=True, help="a folder for one run folder per size")
    a = ap.parse_args(argv)
    rows = []
    for size in a.sizes:
        rows.append(measure(a.fox, size, a.work / f"fox_{size}"))
        print(json.dumps(rows[-1]), flush=True)
    return rows


if __name__ == "__main__":
    main()
