"""Where does SfM vary from run to run? (issue 58, item 1)

Takes a run folder whose SfM stage finished (``RUN/sfm/database.db``, ``RUN/sfm/images``) and repeats each
step on copies of its database, with the run's own code:

* ``tree``: the capture's visual words trained again (:func:`curate.sfm.retrieval.build`): a hash of the
  photos' vectors each time (``--colmap-tree``: COLMAP's own vocabulary tree, ``pycolmap.VisualIndex``, the
  file's hash);
* ``match``: the matches and their verification removed and made again (the stage's own :func:`match`,
  the run's matcher): a hash of every pair's verified inliers, and the pairs that differ;
* ``map``: the mapping of :func:`curate.sfm.reconstruction.map_capture` (the configuration's mapper), each
  time: the registered frames (a hash), the models, seconds, and the largest pose difference to the first;
* ``sfm``: matching and mapping again from the run's features (ingest and extraction give the same bytes on every
  run): what two runs of ``curate sfm`` on the same capture differ by.

    python3 -m research.determinism /tmp/w/flip/runs/base1/office_t-1_0 --steps match map --repeat 3 \\
        --threads -1 1
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sqlite3
import tempfile
import time
from pathlib import Path

import numpy as np
from curate.sfm.matching import copy_database


def geometry_hash(db: Path) -> tuple[str, dict]:
    """(a hash of every pair's verified inlier matches and configuration, {pair_id: its own hash})."""
    con = sqlite3.connect(str(db))
    try:
        rows = con.execute("SELECT pair_id, rows, config, data FROM two_view_geometries ORDER BY pair_id").fetchall()
    finally:
        con.close()
    per = {int(p): hashlib.sha1(bytes(d or b"") + f"{r}:{c}".encode()).hexdigest()[:10] for p, r, c, d in rows}
    return hashlib.sha1(json.dumps(per, sort_keys=True).encode()).hexdigest()[:12], per


def colmap_tree(db: Path, path: Path, seed: int, threads: int, max_descriptors: int = 100_000) -> Path:
    """COLMAP's vocabulary tree (``pycolmap.VisualIndex``, faiss k-means) on the same sample of descriptors as
    curate's words: what curate built before (the sample is seeded; faiss's training is not)."""
    import pycolmap

    from curate.sfm.features import read_descriptors, tree_sample
    _, desc = read_descriptors(db)
    sample = tree_sample(iter(desc), len(desc), max_descriptors, np.random.default_rng(seed))
    words = int(np.clip(2 ** np.floor(np.log2(max(len(sample) // 40, 1))), 256, 65536))
    index = pycolmap.VisualIndex.create(128, 64)
    bo = pycolmap.VisualIndex.BuildOptions()
    bo.num_visual_words, bo.num_iterations, bo.num_rounds, bo.num_threads = words, 25, 1, threads
    index.build(bo, pycolmap.FeatureDescriptorsFloat(pycolmap.FeatureExtractorType.SIFT, sample))
    index.write(path)
    return path


def kept_records(sfm: Path) -> list:
    """The kept photos of ``sfm``/images.json as :class:`curate.core.images.PhotoRecord` (their takes)."""
    from curate.core.images import PhotoRecord
    out = []
    for r in json.loads((sfm / "images.json").read_text())["photos"]:
        if r["status"] == "kept":
            pr = PhotoRecord(original=r["original"], rel=r["rel"], working=r["working"])
            pr.extra.update(r.get("extra") or {})
            out.append(pr)
    return out


def strip_matches(db: Path) -> None:
    con = sqlite3.connect(str(db))
    try:
        con.execute("DELETE FROM matches")
        con.execute("DELETE FROM two_view_geometries")
        con.commit()
        con.execute("VACUUM")
    finally:
        con.close()


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--steps", nargs="+", default=["match", "map"], choices=["tree", "match", "map", "sfm"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, nargs="+", default=[-1])
    ap.add_argument("--mapper", default=None, help="SfmConfig.mapper for the map step (default: the config's)")
    ap.add_argument("--colmap-tree", action="store_true", help="tree: COLMAP's vocabulary tree, not curate's words")
    ap.add_argument("--dump", type=Path, default=None, help="write each run's registered poses here (JSON)")
    a = ap.parse_args(argv)

    import pycolmap

    from curate.sfm.config import SfmConfig
    from curate.sfm.matching import match
    from curate.sfm.model import cameras_from_reconstruction
    from curate.sfm.prep import takes_of
    from curate.sfm.reconstruction import map_capture
    from research.flip import pose_spread

    sfm = a.run / "sfm"
    st = json.loads((sfm / "stage.json").read_text())
    matcher = st["stats"]["matcher"]
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        db0 = copy_database(sfm / "database.db", tmp / "run.db")   # opening the run's own would rewrite it
        n = len(pycolmap.Database.open(db0).read_all_images())
        for threads in a.threads:
            kw = {"mapper": a.mapper} if a.mapper else {}
            if "guided_matching" in st["stats"]:          # as the stage resolved it
                kw["guided_matching"] = "on" if st["stats"]["guided_matching"] else "off"
            cfg = SfmConfig(progress=False, num_threads=threads, **kw)
            if "tree" in a.steps:
                hashes = []
                for k in range(a.repeat):
                    t = time.perf_counter()
                    if a.colmap_tree:
                        h = hashlib.sha1(colmap_tree(db0, tmp / f"tree{k}.bin", cfg.seed, threads).read_bytes())
                    else:
                        from curate.sfm.retrieval import build
                        h = hashlib.sha1(build(db0, cfg.seed, cfg.vocab_tree_descriptors).vectors.toarray().tobytes())
                    hashes.append((h.hexdigest()[:12], round(time.perf_counter() - t, 1)))
                out.append({"step": "tree", "colmap": a.colmap_tree, "threads": threads, "runs": hashes})
                print(json.dumps(out[-1]), flush=True)
            if "match" in a.steps:
                ref_hash, ref = geometry_hash(db0)
                runs = []
                for k in range(a.repeat):
                    db = tmp / f"match{k}.db"
                    copy_database(db0, db)
                    strip_matches(db)
                    kept = kept_records(sfm)
                    t = time.perf_counter()
                    match(cfg, db, matcher, takes_of(kept), {})
                    h, per = geometry_hash(db)
                    diff = sorted(p for p in set(per) | set(ref) if per.get(p) != ref.get(p))
                    runs.append({"hash": h, "same_as_run": h == ref_hash, "pairs": len(per),
                                 "pairs_differing_from_run": len(diff), "seconds": round(time.perf_counter() - t, 1)})
                    print(json.dumps({"step": "match", "threads": threads, **runs[-1]}), flush=True)
                out.append({"step": "match", "threads": threads, "runs": runs})
            for step in [x for x in ("map", "sfm") if x in a.steps]:
                runs = []
                for k in range(a.repeat):
                    db = tmp / f"map{k}.db"
                    copy_database(db0, db)
                    stats: dict = {}
                    pycolmap.set_random_seed(cfg.seed)
                    t = time.perf_counter()
                    if step == "sfm":
                        strip_matches(db)
                        for f in ("visual_words.npz", "vocab_tree.bin"):
                            (tmp / f).unlink(missing_ok=True)
                        match(cfg, db, matcher, takes_of(kept_records(sfm)), stats)
                    tm = time.perf_counter() - t
                    models = map_capture(cfg, db, sfm / "images", tmp / f"map{k}", n, stats)
                    sec = round(time.perf_counter() - t, 1)
                    best = max(models.values(), key=lambda r: r.num_reg_images())
                    cams = cameras_from_reconstruction(best, warn=False)[0]
                    names = sorted(cams.names)
                    h = hashlib.sha1("\n".join(names).encode()).hexdigest()[:12]
                    runs.append({"registered": len(names), "hash": h,
                                 "models": sorted((int(r.num_reg_images()) for r in models.values()), reverse=True),
                                 "mapper": stats.get("mapper"), "seconds": sec, "match_seconds": round(tm, 1),
                                 "c2w": {nm: np.round(cams.c2w[i, :3, :4], 6).tolist()
                                         for i, nm in enumerate(cams.names)}})
                    shutil.rmtree(tmp / f"map{k}", ignore_errors=True)
                    print(json.dumps({"step": step, "threads": threads, **{x: runs[-1][x] for x in
                                      ("registered", "hash", "models", "mapper", "seconds", "match_seconds")}}),
                          flush=True)
                if a.dump:
                    a.dump.mkdir(parents=True, exist_ok=True)
                    (a.dump / f"{step}_t{threads}.json").write_text(json.dumps(runs))
                spread = pose_spread(runs) if len(runs) > 1 else None
                out.append({"step": step, "threads": threads, "distinct": len({r["hash"] for r in runs}),
                            "spread": spread, "seconds": [r["seconds"] for r in runs]})
                print(json.dumps(out[-1]), flush=True)
    return out


if __name__ == "__main__":
    main()
