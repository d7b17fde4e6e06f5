"""Where the incremental mapper's time goes: seconds in each of pycolmap's mapper steps over the first
registrations of a finished run's matches, one JSON line (docs/investigations/sfm.md#mapping-past-1000).

    python3 -m research.mapping_profile RUN POOL REGISTRATIONS [FIELD=VALUE ...]

POOL: the first POOL photos (name order) of RUN's matches form the pool; the mapping stops after
REGISTRATIONS photos. The mapping is curate.sfm.mapping (COLMAP's pipeline as a loop of pycolmap's
steps) under curate's options for a pool of that size (SfmConfig FIELD=VALUE overrides), each step of
``pycolmap.IncrementalMapper`` timed.
"""
from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path
from curate.sfm.matching import copy_database

STEPS = ("find_next_images", "register_next_image", "triangulate_image", "iterative_local_refinement",
         "iterative_global_refinement", "filter_frames")


class _Enough(Exception):
    pass


def main(argv: list[str]) -> dict:
    import pycolmap

    import curate.sfm.reconstruction as C
    import curate.sfm.mapping as M
    from curate.sfm.config import SfmConfig
    from research.sfm_mappers import sfm_config_overrides
    run, pool, stop = Path(argv[0]), int(argv[1]), int(argv[2])
    cfg = SfmConfig(progress=False, **sfm_config_overrides(argv[3:]))
    sfm = run / "sfm"
    seconds = dict.fromkeys(STEPS, 0.0)

    class Timed(pycolmap.IncrementalMapper):
        pass

    def timed(step):
        plain = getattr(pycolmap.IncrementalMapper, step)

        def f(self, *a, **k):
            t = time.perf_counter()
            try:
                return plain(self, *a, **k)
            finally:
                seconds[step] += time.perf_counter() - t
        return f

    for step in STEPS:
        setattr(Timed, step, timed(step))
    registered = [0]

    def on_image():
        registered[0] += 1
        if registered[0] >= stop:
            raise _Enough

    tmp = Path(tempfile.mkdtemp())
    plain_mapper = pycolmap.IncrementalMapper
    try:
        db = tmp / "d.db"
        copy_database(sfm / "database.db", db)
        opts = C.incremental_options(cfg, pool)
        opts.image_names = sorted(p.name for p in (sfm / "images").iterdir())[:pool]
        pycolmap.IncrementalMapper = Timed
        pycolmap.set_random_seed(0)
        t0 = time.perf_counter()
        try:
            M.incremental_mapping(db, sfm / "images", tmp / "m", opts, on_image=on_image)
        except _Enough:
            pass
        wall = time.perf_counter() - t0
    finally:
        pycolmap.IncrementalMapper = plain_mapper
        shutil.rmtree(tmp)
    return {"run": str(run), "overrides": argv[3:], "pool": pool, "registered": registered[0], "wall_s": round(wall, 1),
            "seconds": {k: round(v, 1) for k, v in seconds.items()}}


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:])), flush=True)
