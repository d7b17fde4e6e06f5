"""The export's COLMAP model: a model cut down to a subset of its images (with the points they still
triangulate, optionally renamed and rescaled to the originals), and how connected the subset stays.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from curate.sfm.native import load as load_pycolmap

logger = logging.getLogger(__name__)


def write_subset_model(sparse_dir: str | Path, keep_names: list[str], out_dir: str | Path,
                       rename: dict[str, str] | None = None, sizes: dict[str, tuple[int, int]] | None = None,
                       min_track: int = 2, min_shared: int = 15) -> dict:
    """Write a COLMAP binary model holding only the images ``keep_names`` of the model in ``sparse_dir``.

    Same world frame and poses as the source. Each kept image keeps all its keypoints;
    a 3D point is kept when at least ``min_track`` kept images observe it (default 2: a
    point seen by one image only is not triangulated by that subset), with only those
    observations in its track; reprojection errors are recomputed.

    Args:
        sparse_dir: source model folder (binary or text), e.g. ``RUN/sfm/sparse/0``, or a ``pycolmap.Reconstruction``.
        keep_names: image names of the source model to keep (unknown names: ``ValueError``).
        out_dir: folder written (created): ``cameras.bin images.bin points3D.bin`` (+ rigs/frames).
        rename: optional source name -> name written in the new model (e.g. the original photo's).
        sizes: optional source name -> (width, height) of the images the new model describes
            (the originals): the camera is rescaled per axis (focal length and principal point;
            a single-focal model takes the mean scale) and the keypoints with it.
        min_track: fewest kept observations for a 3D point to be kept.
        min_shared: two kept images are connected when they observe at least this many kept
            points in common (COLMAP's fewest verified matches of a pair, 15 by default).

    Returns:
        {"n_images", "n_cameras", "n_points3D", "n_points3D_source", "n_images_with_points" (kept images
        observing at least one kept point), "components"}: ``components``,
        the sizes of the groups of kept images connected through shared points (largest first;
        one group: the subset is one connected set that 3DGS / NeRF tools can register as a whole).
    """
    pycolmap = load_pycolmap()

    src = pycolmap.Reconstruction(str(sparse_dir)) if isinstance(sparse_dir, (str, Path)) else sparse_dir
    rename, sizes = rename or {}, sizes or {}
    by_name = {src.image(i).name: i for i in src.reg_image_ids()}
    missing = [n for n in keep_names if n not in by_name]
    if missing:
        raise ValueError(f"{len(missing)} image(s) not in the model {sparse_dir}: {missing[:5]}")
    rec = pycolmap.Reconstruction()
    cam_ids: dict = {}
    keep_ids = set()
    for n in dict.fromkeys(keep_names):
        iid = by_name[n]
        im = src.image(iid)
        cam = src.camera(im.camera_id)
        w, h = sizes.get(n, (cam.width, cam.height))
        sx, sy = w / cam.width, h / cam.height
        key = (im.camera_id, int(w), int(h))
        if key not in cam_ids:
            new = pycolmap.Camera(camera_id=len(cam_ids) + 1, model=cam.model_name, width=cam.width,
                                  height=cam.height, params=list(cam.params))
            if (w, h) != (cam.width, cam.height):
                new.rescale(int(w), int(h))
            cam_ids[key] = new.camera_id
            rec.add_camera_with_trivial_rig(new)
        xy = np.array([p.xy for p in im.points2D], np.float64).reshape(-1, 2) * [sx, sy]
        out_im = pycolmap.Image(name=rename.get(n, n), keypoints=xy, camera_id=cam_ids[key], image_id=iid)
        rec.add_image_with_trivial_frame(out_im, im.cam_from_world())
        keep_ids.add(iid)
    shared: dict[tuple[int, int], int] = {}
    seeing: set[int] = set()
    for p in src.points3D.values():
        els = [e for e in p.track.elements if e.image_id in keep_ids]
        ids = sorted({e.image_id for e in els})
        if len(ids) >= min_track:
            rec.add_point3D(p.xyz, pycolmap.Track(els), p.color)
            seeing.update(ids)
            for a in range(len(ids)):
                for b in range(a + 1, len(ids)):
                    shared[(ids[a], ids[b])] = shared.get((ids[a], ids[b]), 0) + 1
    components = covisible_groups(sorted(keep_ids), [e for e, n in shared.items() if n >= min_shared])
    rec.update_point_3d_errors()
    from curate.sfm.model import write_model
    out_dir = Path(out_dir)
    write_model(rec, out_dir)
    logger.info("subset model: %d images, %d of %d points -> %s", rec.num_reg_images(), rec.num_points3D(),
                src.num_points3D(), out_dir)
    return {"n_images": rec.num_reg_images(), "n_cameras": rec.num_cameras(), "n_points3D": rec.num_points3D(),
            "n_points3D_source": src.num_points3D(), "n_images_with_points": len(seeing), "components": components}


def covisible_groups(nodes: list[int], edges: list[tuple[int, int]]) -> list[int]:
    """Sizes of the connected components of the graph (``nodes``, ``edges``), largest first."""
    parent = {n: n for n in nodes}

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x
    for a, b in edges:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    sizes: dict[int, int] = {}
    for n in nodes:
        r = find(n)
        sizes[r] = sizes.get(r, 0) + 1
    return sorted(sizes.values(), reverse=True)
