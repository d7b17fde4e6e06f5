"""The SfM stage as a run-folder stage: photos (or known poses) -> ``RUN/sfm``.

:func:`run` has the shape of every stage (config, run folder, force -> :class:`StageResult`);
the work is :func:`curate.sfm.colmap.run_sfm` (COLMAP) or :func:`curate.sfm.colmap.import_poses`.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig


def _record_stamp(d: Path):
    p = d / "stage.json"
    return (p.stat().st_mtime_ns, p.read_bytes()) if p.is_file() else None


def run(cfg: "RunConfig", run_dir: Path, force: bool = False, photos: str | Path | None = None,
        poses: str | Path | None = None) -> StageResult:
    """SfM on ``photos`` or, with ``poses`` (a COLMAP model or transforms.json), an import.

    The stage ran when its record changed; an unchanged re-run leaves it as it was.
    """
    from curate.sfm.colmap import import_poses, run_sfm
    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    d = run_dir / "sfm"
    before = _record_stamp(d)
    if poses:
        import_poses(cfg.sfm, poses, run_dir, photos=photos, force=force)
    else:
        if photos is None:
            raise ValueError("give a photo folder, or --poses with a COLMAP model or transforms.json")
        run_sfm(cfg.sfm, photos, run_dir, force=force)
    ran = _record_stamp(d) != before
    n = len(json.loads((d / "cameras.json").read_text())["cameras"])
    return StageResult("sfm", d, ran, time.perf_counter() - t0, f"{n} cameras registered")
