"""The SfM stage as a run-folder stage: photos (or known poses) -> ``RUN/sfm``.

:func:`reconstruct` keys and skips by itself (its key hashes the photo files it finds, or the pose files and the
photos they match: :mod:`curate.core.graph`); the work is :func:`curate.sfm.colmap.sfm_in_claimed` (COLMAP) or
:func:`curate.sfm.pose_import.import_in_claimed`.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

from curate.core.paths import RunPaths
from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.core.graph import RunContext

log = logging.getLogger(__name__)


def reconstruct(ctx: "RunContext") -> StageResult:
    """SfM on ``ctx.photos`` or, with ``ctx.poses`` (a COLMAP model or transforms.json), an import, in the run
    folder its caller claimed (the command, or :func:`curate.pipeline.run`)."""
    from curate.core.run import load_cameras
    from curate.core.stage import read_stage
    from curate.sfm.colmap import sfm_in_claimed
    from curate.sfm.pose_import import import_in_claimed
    from curate.sfm.warn import import_warning, path_warning, split_warning, step_warning
    t0 = time.perf_counter()
    cfg, run_dir, photos, poses = ctx.cfg, ctx.run_dir, ctx.photos, ctx.poses
    if poses:
        _, ran = import_in_claimed(cfg.sfm, poses, run_dir, photos=photos, force=ctx.force)
    else:
        if photos is None:
            raise ValueError("give a photo folder, or --poses with a COLMAP model or transforms.json")
        _, ran = sfm_in_claimed(cfg.sfm, photos, run_dir, force=ctx.force)
    d = RunPaths(run_dir).sfm
    n = len(load_cameras(run_dir))
    st = (read_stage(d) or {}).get("stats") or {}
    warn = split_warning(run_dir, each=cfg.sfm.on_split == "each")
    if warn is not None:
        if cfg.sfm.on_split == "stop":
            raise ValueError(f"{warn} (stopped: --on-split stop; --on-split largest goes on with the largest part, "
                             "--on-split each curates every part)")
        log.warning("sfm: %s", warn)
    for said in (path_warning(st), step_warning(st)):   # imported poses carry neither: curate does not check them
        if said is not None:
            log.warning("sfm: %s", said)
            warn = said if warn is None else f"{warn}; {said}"
    summary = f"{n} cameras registered"
    if poses:
        tri = st.get("triangulation") or {}
        summary += f" (imported, of {st['n_poses']} poses)" if st.get("n_poses", n) != n else " (imported)"
        if tri.get("status") == "done":
            summary += f", {tri['n_points']} points triangulated in {tri['seconds']:.0f}s"
        elif st.get("n_points"):
            summary += f", {st['n_points']} points"
        if st.get("rescaled"):      # poses written for another size of the same photos: said, and scaled
            summary += f"; {st['rescaled']['said']}"
        imp = import_warning(run_dir)
        if imp is not None:
            log.warning("sfm: %s", imp)
            warn = imp if warn is None else f"{warn}; {imp}"
    return StageResult("sfm", d, ran, time.perf_counter() - t0, summary, warning=warn)
