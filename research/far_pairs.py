"""What a run's far sequential pairs cost and give: the pairs of ``sequential_pairs.txt`` at least ``MIN_OFFSET``
frames apart (in name order) that are not loop pairs, matched alone on one thread as the stage matches them
(:func:`curate.sfm.matching._match_file`, guided), and the run's matches mapped without them (the stage's
incremental mapper). With a truth file of an office case (and the office folder), the largest model with and
without them against the truth. Loop pairs are those loop detection ranks from the run's own visual words
(``visual_words.npz``; ``loop_pairs.txt`` lists only the loop pairs the sequential ones had not matched). Prints JSON.

    python -m research.far_pairs RUN MIN_OFFSET WORK [CASE.truth.json OFFICE]
"""

from __future__ import annotations

import json
import resource
import sqlite3
import sys
import time
from pathlib import Path
from curate.sfm.matching import copy_database


def main(argv=None) -> dict:
    import pycolmap

    from curate.sfm import matching
    from curate.sfm.config import SfmConfig
    from curate.sfm.reconstruction import map_incremental
    args = argv or sys.argv[1:]
    run, min_off, work = Path(args[0]), int(args[1]), Path(args[2])
    truth = (Path(args[3]), Path(args[4])) if len(args) >= 5 else None
    work.mkdir(parents=True, exist_ok=True)
    sfm = run / "sfm"
    seq = [ln.split() for ln in (sfm / "sequential_pairs.txt").read_text().splitlines() if ln.strip()]
    names = sorted({a for p in seq for a in p})
    idx = {n: i for i, n in enumerate(names)}
    loop_file = sfm / "loop_pairs.txt"
    loop = {tuple(sorted(ln.split())) for ln in loop_file.read_text().splitlines() if ln.strip()} \
        if loop_file.is_file() else set()
    cfg = SfmConfig(progress=False)
    if (sfm / "visual_words.npz").is_file():
        from curate.sfm.retrieval import load
        loop |= {tuple(sorted(p)) for p in matching.loop_pairs(cfg, load(sfm / "visual_words.npz"))[1]}
    drop = [p for p in seq if abs(idx[p[0]] - idx[p[1]]) >= min_off and tuple(sorted(p)) not in loop]
    db = work / "cost.db"
    copy_database(sfm / "database.db", db)
    with sqlite3.connect(db) as con:
        con.execute("DELETE FROM matches")
        con.execute("DELETE FROM two_view_geometries")
    lst = work / "drop.txt"
    lst.write_text("".join(f"{a} {b}\n" for a, b in drop))
    t, r0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
    matching._match_file(db, lst, cfg.seed, cfg.min_num_matches, True, 0)
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    out = {"run": str(run), "min_offset": min_off, "pairs": len(drop),
           "match_wall_s": round(time.perf_counter() - t, 1),
           "match_cpu_s": round(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime, 1)}
    db2 = work / "without.db"
    copy_database(sfm / "database.db", db2)
    with pycolmap.Database.open(db2) as d:
        ids = {im.name: im.image_id for im in d.read_all_images()}
        out["verified"] = sum(d.exists_two_view_geometry(ids[a], ids[b]) and
                              len(d.read_two_view_geometry(ids[a], ids[b]).inlier_matches) >= cfg.min_num_matches
                              for a, b in drop)
        for a, b in drop:
            if d.exists_two_view_geometry(ids[a], ids[b]):
                d.delete_two_view_geometry(ids[a], ids[b])
            d.delete_matches(ids[a], ids[b])
    (work / "sparse").mkdir(exist_ok=True)
    t = time.perf_counter()
    models = map_incremental(cfg, db2, sfm / "images", work / "sparse", len(ids), False)
    out["models_without"] = sorted((int(r.num_reg_images()) for r in models.values()), reverse=True)
    out["map_s"] = round(time.perf_counter() - t, 1)
    if truth:
        from research.join_shared import summary, truth_errors
        recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
        tj = json.loads(truth[0].read_text())
        best = max(models.values(), key=lambda r: r.num_reg_images())
        out["truth_without"] = summary(truth_errors(best, recs, tj, truth[1]).values())
        copy_database(sfm / "database.db", work / "with.db")
        (work / "sparse_with").mkdir(exist_ok=True)
        with_ = map_incremental(cfg, work / "with.db", sfm / "images", work / "sparse_with", len(ids), False)
        out["models_with"] = sorted((int(r.num_reg_images()) for r in with_.values()), reverse=True)
        best = max(with_.values(), key=lambda r: r.num_reg_images())
        out["truth_with"] = summary(truth_errors(best, recs, tj, truth[1]).values())
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
