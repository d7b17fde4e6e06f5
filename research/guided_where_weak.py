"""Guided matching on every pair against guided matching only where a pair's unguided matches are few.

``curate sfm`` of one capture twice (or more with ``--repeat``): ``--guided-matching on`` (every pair guided, what
auto did for a sequence of frames before ``SfmConfig.guided_only_below_inliers``) and auto (the photos' median of
SIFT features decides: :func:`curate.sfm.matching.weak_first`). Prints one JSON object: each run's stage times,
CPU seconds, registered frames, pairs guided, and the poses of each auto run against the first every-pair run
(and against a rendered capture's truth with ``--truth``). docs/investigations/sfm.md#guided-where-weak.

    python -m research.guided_where_weak PHOTOS --work W [--truth FRAMES --kind object] [--repeat 2]
        [--below 300 100]   # auto's guided_only_below_inliers, one run each (default: the config's)
        [--above 1500]      # auto's guided_selective_above_features in its runs (default: the config's)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def child(photos: str, run: str, steps: str, below: str, above: str, extra: list[str]) -> int:
    """research.bench.bench_mapping's ``curate sfm`` child with auto's ``guided_only_below_inliers`` set to
    ``below`` and its ``guided_selective_above_features`` to ``above`` ("" leaves the config's)."""
    from dataclasses import replace

    import curate.sfm.colmap as C
    from research.bench.bench_mapping import sfm_child
    if below or above:
        weak_first = C.weak_first
        set_ = {**({"guided_only_below_inliers": int(below)} if below else {}),
                **({"guided_selective_above_features": int(above)} if above else {})}
        C.weak_first = lambda cfg, db: weak_first(replace(cfg, **set_), db)
    return sfm_child(photos, run, steps, extra)


def one(work: Path, name: str, photos: Path, extra: list[str], below: str = "", above: str = "") -> dict:
    """One ``curate sfm`` in its own process (:func:`child`): its record."""
    import shutil

    from research.bench.bench_mapping import _timed
    run, steps = work / "runs" / name, work / f"{name}.steps.json"
    if run.exists():
        shutil.rmtree(run)
    run.parent.mkdir(parents=True, exist_ok=True)
    proc = _timed([sys.executable, "-m", "research.guided_where_weak", "--child", str(photos), str(run), str(steps),
                   below, above, *extra], work / f"{name}.log")
    rec = {"name": name, "options": extra, "process": proc}
    if proc["rc"] == 0:
        st = json.loads((run / "sfm" / "stage.json").read_text())
        s = st["stats"]
        rec.update({"timings": st.get("timings"), "n_kept": s["n_kept"], "n_registered": s.get("n_registered"),
                    "model_sizes": s.get("model_sizes"), "n_pairs_verified": s.get("n_pairs_verified"),
                    "guided_only_below_inliers": s.get("guided_only_below_inliers"),
                    "pairs_guided": sum(v.get("guided_pairs", 0) for k, v in s.items()
                                        if k in ("pairs", "loop_detection", "cross_take") and isinstance(v, dict)),
                    "pairs_matched": sum(v.get("new_pairs", 0) for k, v in s.items()
                                         if k in ("pairs", "loop_detection", "cross_take") and isinstance(v, dict)),
                    "steps": json.loads(steps.read_text())["steps"]})
    return rec


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--child"]:
        return child(*argv[1:6], argv[6:])
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("photos", type=Path)
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--truth", type=Path, help="a rendered capture's frame folder (truth.npy)")
    ap.add_argument("--kind", default="object", help="the rendered capture's kind (research.bench.bench_mapping)")
    ap.add_argument("--repeat", type=int, default=1, help="runs of each setting")
    ap.add_argument("--only", choices=["every", "weak"], help="run one setting only")
    ap.add_argument("--below", nargs="*", default=[""], help="auto's guided_only_below_inliers (one run each)")
    ap.add_argument("--above", default="", help="auto's guided_selective_above_features in its runs")
    a = ap.parse_args(argv)
    from curate.sfm.io import load_sfm
    from research.bench.bench_mapping import pose_record, truth_cameras
    truth = truth_cameras(a.truth, a.kind) if a.truth else None
    out: dict = {"photos": str(a.photos), "every": [], "weak": []}
    runs = [("every", "", ["--guided-matching", "on"])] + [("weak", b, []) for b in a.below]
    for k in range(a.repeat):
        for label, below, extra in runs:
            if a.only and label != a.only:
                continue
            name = f"{label}{below}_{k}" if label == "weak" and below else f"{label}{k}"
            rec = one(a.work, name, a.photos, extra, below, a.above if label == "weak" else "")
            if rec["process"]["rc"] == 0:
                cams = load_sfm(a.work / "runs" / name).cameras
                if truth is not None:
                    rec["against_truth"] = pose_record(cams, truth)
                first = a.work / "runs" / "every0"
                if name != "every0" and (first / "sfm" / "cameras.json").is_file():
                    rec["against_every0"] = pose_record(cams, load_sfm(first).cameras)
            out[label].append(rec)
            print(json.dumps({label: rec}), file=sys.stderr, flush=True)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
