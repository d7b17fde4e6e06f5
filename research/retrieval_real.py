"""Retrieval matching against exhaustive matching on real photo sets: photos registered, matching time, poses.

    python -m research.bench.bench_sfm --data ../shared/data/{templering,fox,skull} --runs R \\
        --set matcher=retrieval retrieval_num_images=10
    python -m research.retrieval_real --data ../shared/data --exhaustive E --retrieval R templering fox skull

``E/<set>`` and ``R/<set>`` are run folders whose SfM used exhaustive and retrieval matching (the sets are
under the 150 photos past which ``--matcher auto`` picks retrieval, so it is forced, with fewer similar
photos per photo than the default to be as sparse as the default is on a few hundred photos). One JSON line
per set: each run's matcher, photos registered, image pairs with a geometry, matching seconds, pose error
against the ground truth where the set has one, and the retrieval model's poses against the exhaustive
model's (after a similarity alignment).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from curate.sfm.io import load_sfm
from research.align import pose_errors
from research.datasets import load_ground_truth

KEYS = ("n_matched", "rotation_deg_median", "rotation_deg_max", "centre_rel_median", "centre_rel_max")


def _run(run: Path, gt) -> dict:
    st = json.loads((run / "sfm" / "stage.json").read_text())
    s = st["stats"]
    k = (st.get("config") or {}).get("retrieval_num_images") if s["matcher"] == "retrieval" else None
    out = {"matcher": s["matcher"], **({"retrieval_num_images": k} if k else {}), "n_kept": s["n_kept"],
           "registered": s["n_registered"], "pairs_with_geometry": s.get("n_pairs_matched"),
           "match_s": st["timings"]["match"]}
    if "retrieval_second_round" in s:
        r2 = s["retrieval_second_round"]
        out["second_round"] = {k: r2[k] for k in ("photos", "num_images", "verified", "model_sizes_before",
                                                  "model_sizes_after")}
    if gt is not None:
        e = pose_errors(load_sfm(run).cameras, gt)
        out["vs_truth"] = {k: round(float(e[k]), 3) for k in KEYS}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sets", nargs="+")
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--exhaustive", type=Path, required=True)
    ap.add_argument("--retrieval", type=Path, required=True)
    a = ap.parse_args(argv)
    for name in a.sets:
        gt = load_ground_truth(a.data / name)
        rec = {"set": name, "exhaustive": _run(a.exhaustive / name, gt), "retrieval": _run(a.retrieval / name, gt)}
        e = pose_errors(load_sfm(a.retrieval / name).cameras, load_sfm(a.exhaustive / name).cameras)
        rec["retrieval_vs_exhaustive"] = {k: round(float(e[k]), 3) for k in KEYS}
        print(json.dumps(rec), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
