"""A video's frames registered in the order of the walk: the run's matches mapped again by curate's step-by-step
incremental mapper (`curate.sfm.mapping.incremental_mapping`) with COLMAP's next images reordered
(:func:`mapping_with`) so that a frame with a registered neighbour in its take (within ``--reach`` frames) comes
before one without, against the same loop in COLMAP's order; each model's frames against the truth. Prints JSON.

    python -m research.neighbour_first RUN CASE.truth.json --office ../shared/data/office --work W [--reach 2]
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path
from curate.sfm.matching import copy_database


def neighbour_rank(kept: list, db: Path, reach: int, entry: bool = False):
    """rank(ids, rec): the image ids with a registered frame within ``reach`` of them in their take first, in
    COLMAP's order within each group; with ``entry``, also a frame of a take that has no frame in the model yet
    (so that a second take enters where COLMAP would have it enter)."""
    import pycolmap

    from curate.sfm.continuity import frame_times
    when = frame_times(kept, numbered=True)
    with pycolmap.Database.open(db) as d:
        ids = {im.name: im.image_id for im in d.read_all_images()}
    takes: dict = {}
    for n, (tk, t) in when.items():
        if n in ids:
            takes.setdefault(tk, []).append((t, ids[n]))
    near: dict[int, list[int]] = {}
    take_of: dict[int, list[int]] = {}
    for frames in takes.values():
        order = [i for _, i in sorted(frames)]
        for k, i in enumerate(order):
            near[i] = order[max(k - reach, 0):k] + order[k + 1:k + 1 + reach]
            take_of[i] = order

    def posed(rec, j: int) -> bool:
        return rec.exists_image(j) and rec.image(j).has_pose

    def rank(cands: list, rec) -> list:
        def have(i: int) -> bool:
            if any(posed(rec, j) for j in near.get(i, [])):
                return True
            return entry and i in take_of and not any(posed(rec, j) for j in take_of[i])
        first = [i for i in cands if have(i)]
        return first + [i for i in cands if not have(i)] if first else cands
    return rank


def mapping_with(rank):
    """A context in which :func:`curate.sfm.mapping.incremental_mapping` tries COLMAP's next images in the order
    ``rank(ids, rec)`` gives (None: COLMAP's order): its loop reads pycolmap through ``load_pycolmap``, here a view
    of pycolmap whose IncrementalMapper reorders ``find_next_images``. The reordering is this experiment's, not
    curate's (measured, not adopted: docs/investigations/sfm.md#registration-order)."""
    import contextlib
    from unittest import mock

    import pycolmap

    from curate.sfm import mapping
    if rank is None:
        return contextlib.nullcontext()

    class Mapper(pycolmap.IncrementalMapper):
        def find_next_images(self, options, structure_less=False):
            return rank(list(super().find_next_images(options, structure_less=structure_less)), self.reconstruction)

    class View:
        IncrementalMapper = Mapper

        def __getattr__(self, name):
            return getattr(pycolmap, name)

    return mock.patch.object(mapping, "load_pycolmap", lambda: View())


def main(argv=None) -> dict:
    from curate.sfm.config import SfmConfig
    from curate.sfm.mapping import incremental_mapping
    from curate.sfm.reconstruction import expected_observations, incremental_options
    from research.join_shared import summary, truth_errors
    from research.path_check import kept_records
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("truth", type=Path)
    ap.add_argument("--office", type=Path, required=True)
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--reach", type=int, default=2)
    ap.add_argument("--variants", nargs="+", default=["colmap", "neighbours"],
                    help="colmap: COLMAP's order; neighbours: a frame with a registered neighbour first; entry: that, "
                         "and a frame of a take not yet in the model; ratio, count: COLMAP's image_selection_method "
                         "MAX_VISIBLE_POINTS_RATIO, MAX_VISIBLE_POINTS_NUM")
    a = ap.parse_args(argv)
    sfm = a.run / "sfm"
    kept = kept_records(a.run)
    recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
    tj = json.loads(a.truth.read_text())
    cfg = SfmConfig()
    out: dict = {"run": str(a.run), "reach": a.reach}
    for v in a.variants:
        w = a.work / v
        shutil.rmtree(w, ignore_errors=True)
        w.mkdir(parents=True)
        db = w / "database.db"
        copy_database(sfm / "database.db", db)
        opts = incremental_options(cfg, len(kept), expected_observations(db, cfg.min_num_matches))
        if v in ("ratio", "count"):   # COLMAP's other next-image choices, in COLMAP's order otherwise
            import pycolmap
            opts.mapper.image_selection_method = (pycolmap.ImageSelectionMethod.MAX_VISIBLE_POINTS_RATIO if v == "ratio"
                                                  else pycolmap.ImageSelectionMethod.MAX_VISIBLE_POINTS_NUM)
        rank = neighbour_rank(kept, db, a.reach, entry=v == "entry") if v in ("neighbours", "entry") else None
        t = time.process_time()
        with mapping_with(rank):
            models = incremental_mapping(db, sfm / "images", w / "sparse", opts)
        cpu = time.process_time() - t
        rows = []
        for r in sorted(models.values(), key=lambda r: -r.num_reg_images()):
            e = truth_errors(r, recs, tj, a.office)
            rows.append({"frames": int(r.num_reg_images()), "truth": summary(e.values()),
                         "over5": sorted(n for n, x in e.items() if x > 5)})
        out[v] = {"cpu_s": round(cpu, 1), "models": rows}
        print(json.dumps({v: out[v]}), flush=True)
    return out


if __name__ == "__main__":
    main()
