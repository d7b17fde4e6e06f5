"""The export stage: the chosen subset in the formats NeRF tools read -> ``RUN/export``
(see :mod:`curate.export.subset`)."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from curate.core.paths import RunPaths

if TYPE_CHECKING:
    from curate.core.graph import RunContext
    from curate.core.runner import Done, Keyed


EXPORTED = {"hardlink": "hard-linked", "link": "linked", "copy": "copied"}
"""How the stage line says each export mode ("10 images (copied)")."""


def key(ctx: "RunContext") -> "Keyed":
    """The stage's key (:attr:`curate.core.graph.Stage.key`): the export's options (beside the selection's key)."""
    from curate.core.runner import Keyed
    return Keyed({"export": ctx.cfg.export})


def export(ctx: "RunContext", keyed: "Keyed") -> "Done":
    """COLMAP model, transforms.json, image list and image links (or copies) of the selection."""
    from curate.core.runner import Done
    from curate.core.stage import read_stage
    from curate.export.subset import export_subset
    from curate.core.run import read_selection
    cfg, run_dir = ctx.cfg, ctx.run_dir
    d = RunPaths(run_dir).export
    sel = read_selection(run_dir)
    export_subset(run_dir, sel["chosen_names"], d, config=cfg.export)
    model = json.loads((d / "export.json").read_text())["model"]
    sfm = read_stage(RunPaths(run_dir).sfm) or {}
    # what stops a trainer is a warning (atop the report); separate groups of images only matter to a tool that
    # registers the subset again, so it is said beside the training commands, not in the warning box
    warn = points_warning(model, sfm)
    groups = connectivity_warning(model)
    from curate.sfm.warn import import_warning
    # the record's warning (shown atop the report) also says when the photos and the poses did not match
    shown = "; ".join(w for w in (import_warning(run_dir), warn) if w) or None
    return Done(f"{len(sel['chosen_names'])} images ("
                f"{'undistorted, PINHOLE' if model.get('undistorted') else EXPORTED[cfg.export.mode]}), "
                f"{model['n_points3D']} points -> {d}",
                {"sparse": "sparse/0", "transforms": "transforms.json", "list": "images.txt", "images": "images/"},
                record={"model": model, "warning": shown, "export_warning": warn, "connectivity": groups},
                warning=warn)


MIN_POINTS = 100
"""The export warns when its ``sparse/0`` holds fewer 3D points than this."""


def points_warning(model: dict, sfm: dict | None = None) -> str | None:
    """A warning when the exported ``sparse/0`` has no or few (< :data:`MIN_POINTS`) 3D points, and why
    (``sfm``: the SfM stage's record); None otherwise."""
    n = int(model.get("n_points3D", 0))
    if n >= MIN_POINTS:
        return None
    st = (sfm or {}).get("stats") or {}
    tri = st.get("triangulation") or {}
    status = tri.get("status")
    if (sfm or {}).get("mode") != "import" or status == "source":
        why = (f"the chosen images share {'none' if n == 0 else 'few'} of the {model.get('n_points3D_source', 0)} "
               "points of RUN/sfm/sparse/0 (a point is kept when two chosen images see it): a larger budget keeps more")
    elif status == "off":
        why = "the poses came without points and --triangulate off skipped them: --triangulate auto computes them"
    elif status == "skipped":
        why = f"the poses came without points and none could be triangulated ({tri.get('reason')})"
    elif status == "failed":
        why = f"triangulating the photos with the known poses failed ({tri.get('reason')})"
    else:
        why = (f"triangulating the photos with the known poses found {tri.get('n_points', 0)} points, "
               f"{model.get('n_points3D_source', 0)} of them in RUN/sfm/sparse/0, and the chosen images share "
               f"{'none' if n == 0 else 'few'} (photos with little texture, or poses that do not fit the photos?)")
    return f"the export has {'no' if n == 0 else f'only {n}'} 3D points: 3DGS needs an initial point cloud; {why}"


def connectivity_warning(model: dict) -> str | None:
    """A warning when the exported images do not form one set connected through shared SfM points
    (their poses are exported whole, but a tool that registers the subset again sees separate
    pieces); None when they do, or when the poses came without points (nothing to judge by)."""
    comps = model.get("components") or []
    if model.get("n_points3D_source", 0) == 0 or len(comps) <= 1:
        return None
    return (f"the {sum(comps)} exported images form {len(comps)} groups that share no SfM points "
            f"(sizes {', '.join(map(str, comps[:8]))}{', ...' if len(comps) > 8 else ''}): their poses are "
            "exported whole, but a tool that registers this subset again (COLMAP) sees separate pieces; a larger "
            "budget links them")
