"""Which COLMAP mapper keeps the whole capture: incremental against global (GLOMAP) on the same matches.

Takes a run folder whose SfM stage finished (``RUN/sfm/database.db`` and ``RUN/sfm/images``, as
``curate sfm`` leaves them), maps its matches again with each mapper, and prints one JSON
object: per mapper the models' sizes, the registered fraction, the mapping time and, when a
ground-truth folder is given (``poses.txt`` + ``K.txt``, a transforms.json, or templering's
parameters), the median rotation error and centre error after a similarity alignment.

    python3 -m curate sfm ../shared/data/office/images --out /tmp/office_sfm
    python3 -m research.sfm_mappers /tmp/office_sfm --truth ../shared/data/office
    python3 -m curate sfm ../shared/data/office/office.mp4 --out /tmp/office_video   # frame i = pose i
    python3 -m research.sfm_mappers /tmp/office_video --truth ../shared/data/office
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from curate.sfm.matching import copy_database


def map_with(kind: str, db: Path, images: Path, out: Path, seed: int = 0) -> tuple[dict, float]:
    """{model id: Reconstruction} of ``kind`` ('incremental', 'global', 'hierarchical[:N]' or 'auto': curate's
    :func:`curate.sfm.reconstruction.map_capture`) on the matches of ``db``, and its seconds."""
    import pycolmap
    pycolmap.set_random_seed(seed)
    out.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    if kind in ("incremental", "incremental:colmap_ba"):   # curate's options; ':colmap_ba': COLMAP's BA schedule
        from curate.sfm.reconstruction import incremental_options
        from curate.sfm.config import SfmConfig
        colmap_ba = {"global_ba_above": 10**9, "global_ba_above_observations": 10**12}
        cfg = SfmConfig(seed=seed, **(colmap_ba if kind.endswith("colmap_ba") else {}))
        n = len(pycolmap.Database.open(db).read_all_images())
        models = pycolmap.incremental_mapping(db, images, out, options=incremental_options(cfg, n))
    elif kind == "auto":  # curate's own choice (SfmConfig.mapper = 'auto'), what `curate sfm` keeps
        from curate.sfm.reconstruction import map_capture
        from curate.sfm.config import SfmConfig
        n = len(pycolmap.Database.open(db).read_all_images())
        stats: dict = {}
        models = map_capture(SfmConfig(progress=False, seed=seed), db, images, out, n, stats)
        print(json.dumps({"auto": {k: stats[k] for k in ("mapper", "mappers_tried") if k in stats}}), flush=True)
    elif kind.startswith("hierarchical"):  # 'hierarchical' or 'hierarchical:N' (clusters of at most N photos)
        from curate.sfm.config import SfmConfig
        from research.bench.bench_mapping import map_hierarchical
        models = map_hierarchical(SfmConfig(progress=False, seed=seed), db, images, out,
                                  int(kind.split(":")[1]) if ":" in kind else 500)
    elif kind.startswith("subsample:"):  # the incremental mapper on every K-th photo only (research.large_pool_check)
        models = map_subset(db, images, out, sorted(p.name for p in images.iterdir())[::int(kind.split(":")[1])],
                            seed)
    elif kind.startswith("chunks") or kind.startswith("rounds"):  # research.chunked_mapping: 'chunks[:SIZE:OVERLAP]',
        from curate.sfm.config import SfmConfig                        # 'rounds[:SIZE]'
        from research.chunked_mapping import map_chunks, map_rounds
        cfg, stats = SfmConfig(progress=False, seed=seed), {}
        names = sorted(p.name for p in images.iterdir())
        if kind.startswith("chunks"):
            size, over = (int(v) for v in kind.split(":")[1:3]) if ":" in kind else (400, 100)
            models = map_chunks(cfg, db, images, out, names, stats, size, over)
        else:
            models = map_rounds(cfg, db, images, out, len(names), stats, int(kind.split(":")[1]) if ":" in kind
                                else 250)
        print(json.dumps({kind: stats}), flush=True)
    elif kind == "global":
        opts = pycolmap.GlobalPipelineOptions()
        models = pycolmap.global_mapping(db, images, out, options=opts)
    else:
        raise ValueError(kind)
    return models, time.perf_counter() - t


def video_frames(sfm: Path) -> tuple[list[dict], dict]:
    """(the photo records of ``sfm``/images.json, {working name: frame index} of the photos taken from a
    video): what :func:`truth_for` pairs a video's frames by."""
    recs = json.loads((sfm / "images.json").read_text()).get("photos", []) if (sfm / "images.json").is_file() else []
    return recs, {r["working"]: r["extra"]["frame"] for r in recs if (r.get("extra") or {}).get("video")}


def truth_for(cams, truth, frame_of: dict):
    """(``cams``, the ground truth) paired by name; for the frames of a video (``frame_of``: working
    name -> frame index) frame i of the video is ground-truth camera i, so ``cams`` are renamed to
    the ground truth's names (names such as ``walk_000012.300.jpg`` would pair by their digits)."""
    if not frame_of:
        return cams, truth
    from curate.core.cameras import Cameras
    return Cameras(cams.c2w, cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height,
                   names=tuple(truth.names[frame_of[n]] for n in cams.names)), truth


def sfm_config_overrides(pairs: list[str]) -> dict:
    """{field: value} of SfmConfig from FIELD=VALUE strings, each value of its field's type."""
    import dataclasses

    from curate.sfm.config import SfmConfig
    types = {f.name: str(f.type) for f in dataclasses.fields(SfmConfig)}
    over = {}
    for kv in pairs:
        k, v = kv.split("=", 1)
        t = types[k]
        over[k] = (v.lower() in ("1", "true")) if t == "bool" else int(v) if t == "int" else \
            float(v) if t == "float" else v
    return over


def rematch(db: Path, tmp: Path, overrides: list[str], out: dict, takes: dict | None = None) -> Path:
    """A copy of ``db`` in ``tmp`` matched again by curate's matching step with SfmConfig
    ``overrides`` (FIELD=VALUE); the matcher and seconds go into ``out``. ``takes`` ({take: image
    names}, from images.json) lets the step match across takes, as ``curate sfm`` does."""

    import pycolmap

    from curate.sfm.matching import match
    from curate.sfm.config import SfmConfig
    over = sfm_config_overrides(overrides)
    cfg = SfmConfig(**over)
    new = tmp / "rematched.db"
    copy_database(db, new)
    h = pycolmap.Database.open(new)
    h.clear_matches()
    h.clear_two_view_geometries()
    h.close()
    matcher = out.get("matcher") or "sequential"
    t = time.perf_counter()
    info: dict = {}
    match(cfg, new, matcher, takes, info)
    out["rematch"] = {"overrides": over, "matcher": matcher, "match_seconds": round(time.perf_counter() - t, 1),
                      **info}
    print(json.dumps(out["rematch"]), flush=True)
    return new


def part_rows(glob: dict, parts: dict, truth, frame_of: dict) -> list[dict]:
    """Per model of ``parts`` (largest first): its size, first and last video frame, the largest
    ``glob`` model's orientation disagreement with it (median, 90th percentile, max, degrees) and,
    with ``truth``, the part's own rotation error (median, max) after its own similarity alignment."""
    from curate.sfm.parts import part_disagreements
    from research.align import pose_errors
    rows = []
    for d, pc in part_disagreements(glob, parts):
        fr = sorted(frame_of.get(n, -1) for n in pc.names)
        row = {"photos": len(pc.names), "frames": [fr[0], fr[-1]]}
        if len(d):
            row.update({"disagreement_median": round(float(np.median(d)), 2),
                        "disagreement_p90": round(float(np.percentile(d, 90)), 2),
                        "disagreement_max": round(float(d.max()), 2)})
        if truth is not None and len(pc.names) >= 3:
            e = pose_errors(*truth_for(pc, truth, frame_of))
            row.update({"rotation_deg_median": round(e["rotation_deg_median"], 2),
                        "rotation_deg_max": round(e["rotation_deg_max"], 2)})
        rows.append(row)
    return rows


def map_subset(db: Path, images: Path, out: Path, names: list[str], seed: int = 0) -> dict:
    """{model id: Reconstruction} of COLMAP's incremental mapper with curate's options (seed, initial
    pair, fixed principal point) on the photos ``names`` of ``db`` only."""
    import pycolmap

    from curate.sfm.reconstruction import incremental_options
    from curate.sfm.config import SfmConfig
    opts = incremental_options(SfmConfig(progress=False, seed=seed), len(names))
    opts.image_names = list(names)
    out.mkdir(parents=True, exist_ok=True)
    return pycolmap.incremental_mapping(db, images, out, options=opts)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a run folder whose SfM stage finished")
    ap.add_argument("--truth", type=Path, default=None, help="ground-truth folder (office, fox, templering)")
    ap.add_argument("--mappers", default="incremental,global",
                    help="comma list of incremental (curate's options), incremental:colmap_ba (COLMAP's global "
                         "adjustment schedule), global, auto, hierarchical[:N] (clusters of <= N), subsample:K "
                         "(incremental, every K-th photo), chunks[:SIZE:OVERLAP], rounds[:SIZE] "
                         "(research.chunked_mapping)")
    ap.add_argument("--rematch", nargs="*", default=None, metavar="FIELD=VALUE",
                    help="match again first (on a copy of the database), with these SfmConfig overrides, "
                         "e.g. vocab_tree_descriptors=100000; prints the matching time")
    ap.add_argument("--parts", action="store_true", help="per incremental part: the global model's disagreement "
                    "(median, 90th percentile, max) and the part's own error against the truth")
    ap.add_argument("--dump", type=Path, default=None, help="write each kept frame's pose error to this JSON file")
    a = ap.parse_args(argv)
    from curate.sfm.model import cameras_from_reconstruction
    from research.align import pose_errors
    from research.datasets import load_ground_truth
    sfm = a.run / "sfm"
    db = sfm / "database.db"
    if not db.is_file():
        raise SystemExit(f"{db}: no database (run `curate sfm` first)")
    stats = json.loads((sfm / "stage.json").read_text()).get("stats", {}) if (sfm / "stage.json").is_file() else {}
    # a stage stopped after matching, or poses imported (their stats count registrations, not kept photos)
    n_kept = stats.get("n_kept") or sum(1 for _ in (sfm / "images").iterdir())
    truth = load_ground_truth(a.truth) if a.truth else None
    recs, frame_of = video_frames(sfm)
    out = {"run": str(a.run), "n_kept": n_kept}
    with tempfile.TemporaryDirectory() as tmp:
        if a.rematch is not None:
            takes: dict = {}
            for r in recs:
                if r.get("status") == "kept" and (r.get("extra") or {}).get("take"):
                    takes.setdefault(r["extra"]["take"], []).append(r["working"])
            db = rematch(db, Path(tmp), a.rematch, out, {t: sorted(v) for t, v in takes.items()})
        kept: dict = {}
        for kind in a.mappers.split(","):
            # each mapper on its own copy of the database (mappers write to it)
            dbk = Path(tmp) / f"{kind}.db"
            copy_database(db, dbk)
            models, secs = map_with(kind, dbk, sfm / "images", Path(tmp) / kind)
            sizes = sorted((int(r.num_reg_images()) for r in models.values()), reverse=True)
            row = {"model_sizes": sizes, "registered_fraction": round(sizes[0] / n_kept, 4) if sizes else 0.0,
                   "map_seconds": round(secs, 1)}
            if models and truth is not None:
                best = max(models.values(), key=lambda r: r.num_reg_images())
                cams = cameras_from_reconstruction(best)[0]
                e = pose_errors(*truth_for(cams, truth, frame_of))
                row.update({k: e[k] for k in ("n_matched", "rotation_deg_median", "rotation_deg_max",
                                              "centre_rel_median")})
                rd = np.asarray(e["rotation_deg"])
                row["n_over_5deg"] = int((rd > 5).sum())
                if a.dump is not None:   # per frame: its error, for the frames a check kept (issue 36)
                    a.dump.write_text(json.dumps({"names": e["names"], "rotation_deg": e["rotation_deg"],
                                                  "centre_rel": e["centre_rel"]}))
            out[kind] = row
            kept[kind] = models
            print(json.dumps({kind: row}), flush=True)
        from curate.sfm.parts import part_agreement   # what curate's --mapper auto checks before it
        if "global" in kept and "incremental" in kept:  # prefers the global model
            out["global"]["part_disagreement_deg"] = [d for d, _ in part_agreement(kept["global"],
                                                                                    kept["incremental"])]
            if a.parts:
                out["parts"] = part_rows(kept["global"], kept["incremental"], truth, frame_of)
        for kind in [k for k in kept if k.startswith("subsample:")]:
            if kept.get("global") and kept[kind]:   # the check of a global model by a subsample's model
                out[kind]["global_disagreement_p90_deg"] = [d for d, _ in part_agreement(kept["global"],
                                                                                            kept[kind])]
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
