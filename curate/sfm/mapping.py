"""COLMAP's incremental mapper run step by step, each global bundle adjustment's solver chosen from the
model's shape (the measurements: docs/investigations/sfm.md#global-ba-solver).

``pycolmap.incremental_mapping`` builds its global adjustments' options in C++ with Ceres' solver left
at COLMAP's choice: a sparse direct solve (Cholesky of the reduced camera system) up to 1,000 photos in
the model, Ceres' iterative Schur solver past that. Which is faster past 1,000 photos depends on the
capture: on a walk down a long hall (a chain of photos, each sharing points with its neighbours only)
the iterative solver converges slowly and the direct solve is 1.2-10 times faster; on a room circled
again and again the direct solve's factor fills in and the iterative one wins. :func:`fill_per_photo`
measures that fill (the factor's nonzeros per photo under a minimum-degree ordering); past 1,000 photos
each global adjustment solves directly while it stays under ``SfmConfig.direct_ba_max_fill``.

:func:`incremental_mapping` runs the same steps in the same order as COLMAP's ``IncrementalPipeline``
(``controllers/incremental_pipeline.cc``): the initial pair by the pipeline's own
``initialize_reconstruction``; each next image registered, triangulated and refined locally by pycolmap's
``IncrementalMapper``; a global refinement when the model has grown by the pipeline's ratios; models,
retries and the two relaxations of the initial pair's thresholds as COLMAP has them. What is written
here is only that loop, the choice, and one step left out where COLMAP repeats itself
(``repeat_final_refinement``): every step is pycolmap's.

Where no photo more registers, COLMAP refines the whole model and tries once more; its final refinement at the end
then runs again, though nothing registered since, because the counts it compares were last set by the refinement
before (``ReconstructSubModel``: "only run final global BA, if last incremental BA was not global"). Here the
refinement before the last try counts as global, so the final one runs only where a photo registered after it: on
office.mp4 the two last refinements cost 17 and 8 s of a 70 s mapping (docs/investigations/sfm.md#final-refinement).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Callable

import numpy as np
from curate.sfm.native import load as load_pycolmap

log = logging.getLogger(__name__)

_MIN_INITIAL_TRIALS = 30   # COLMAP: a new model that cannot grow after this many trials gives up
ALWAYS_DIRECT = 1 << 30    # Ceres' direct-solve limit that no model reaches


def ceres_direct_limit() -> int:
    """Ceres' own limit in COLMAP: global adjustments of more photos than this are solved iteratively (1,000)."""
    pycolmap = load_pycolmap()
    return int(pycolmap.BundleAdjustmentOptions().ceres.max_num_images_direct_sparse_cpu_solver)


def fill_per_photo(tracks: list, n: int) -> dict:
    """The fill of a direct solve of the reduced camera system of ``n`` photos whose points are seen by
    ``tracks`` (each a sequence of photo indices in [0, n); tracks of fewer than 2 distinct photos add
    nothing): one row per photo, an entry wherever two photos see a common point, factored under a
    minimum-degree ordering (SuperLU's, a stand-in for Ceres' own).

    Returns ``{"n", "pattern_per_photo", "nnz_L_per_photo", "flops"}``: nonzeros per photo of the
    system's pattern (diagonal included) and of its Cholesky factor, and the factor's scalar flops (sum
    of the squared column counts; a block solve is about 6**3 times that). All finite; ``n`` = 0 gives zeros.
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu
    if n <= 0:
        return {"n": 0, "pattern_per_photo": 0.0, "nnz_L_per_photo": 0.0, "flops": 0.0}
    rows, cols = [], []
    for t in tracks:
        a = np.unique(np.asarray(t, dtype=np.int64))
        if len(a) >= 2:
            rows.append(np.full(len(a), len(rows), np.int64))
            cols.append(a)
    if rows:
        A = sp.csr_matrix((np.ones(sum(map(len, cols))), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(len(rows), n))
        S = (A.T @ A).tocsc() + sp.identity(n, format="csc")
    else:
        S = sp.identity(n, format="csc")
    S.data[:] = 1.0
    pattern = S.nnz
    S = sp.csc_matrix(S + sp.identity(n) * (S.sum(axis=1).max() + 1))   # diagonally dominant: no pivoting
    L = splu(S, permc_spec="MMD_AT_PLUS_A", options=dict(SymmetricMode=True)).L.tocsc()
    col = np.diff(L.indptr).astype(float)
    return {"n": n, "pattern_per_photo": round(pattern / n, 1), "nnz_L_per_photo": round(L.nnz / n, 1),
            "flops": float((col ** 2).sum())}


def reconstruction_fill(rec) -> dict:
    """:func:`fill_per_photo` of a pycolmap Reconstruction's registered photos and points."""
    pos = {int(i): k for k, i in enumerate(rec.reg_image_ids())}
    tracks = [[pos[e.image_id] for e in p.track.elements if e.image_id in pos] for p in rec.points3D.values()]
    return fill_per_photo(tracks, len(pos))


class SolverChoice:
    """The solver of each global bundle adjustment: Ceres' own choice (direct up to ``direct_limit`` photos,
    iterative past it), except that past ``direct_limit`` a model whose direct solve fills in less than
    ``max_fill`` nonzeros per photo (:func:`reconstruction_fill`) is solved directly. ``max_fill`` 0 keeps
    Ceres' choice everywhere. ``record``: one dict per global adjustment past ``direct_limit`` (photos,
    fill, solver, seconds)."""

    def __init__(self, max_fill: float, direct_limit: int):
        self.max_fill, self.direct_limit = float(max_fill), int(direct_limit)
        self.record: list[dict] = []

    def apply(self, rec, global_ba) -> dict | None:
        """Set ``global_ba``'s direct-solve limit for an adjustment of ``rec`` now; the record entry or None."""
        n = int(rec.num_reg_images())
        if n <= self.direct_limit or self.max_fill <= 0:
            global_ba.ceres.max_num_images_direct_sparse_cpu_solver = self.direct_limit
            return None
        t = time.perf_counter()
        fill = reconstruction_fill(rec)["nnz_L_per_photo"]
        direct = fill < self.max_fill
        global_ba.ceres.max_num_images_direct_sparse_cpu_solver = ALWAYS_DIRECT if direct else self.direct_limit
        entry = {"photos": n, "fill_per_photo": fill, "solver": "direct" if direct else "iterative",
                 "fill_s": round(time.perf_counter() - t, 2)}
        self.record.append(entry)
        return entry


def incremental_mapping(database: Path, images: Path, out: Path, options, choice: SolverChoice | None = None,
                        on_pair: Callable[[], None] | None = None,
                        on_image: Callable[[], None] | None = None, global_ba=None,
                        repeat_final_refinement: bool = True) -> dict:
    """{index: pycolmap.Reconstruction} mapped from ``database`` as ``pycolmap.incremental_mapping``
    would with ``options`` (pycolmap.IncrementalPipelineOptions), except that each global bundle
    adjustment's solver is set by ``choice`` (None: as ``global_ba`` has it, by default
    ``options.get_global_bundle_adjustment()``: Ceres' choice, as COLMAP) and, with ``repeat_final_refinement``
    False, a model's final global refinement is left out where the refinement before its last try was the last
    change (the module's docstring). Models are written to ``out``/0, ``out``/1, ... as COLMAP writes them.
    ``on_pair`` is called when a model's initial pair is registered, ``on_image`` after each further
    registration."""
    pycolmap = load_pycolmap()

    options.image_path = str(images)
    out.mkdir(parents=True, exist_ok=True)
    manager = pycolmap.ReconstructionManager()
    global_ba = global_ba or options.get_global_bundle_adjustment()
    with pycolmap.Database.open(database) as db:
        pipeline = pycolmap.IncrementalPipeline(options, db, manager)
        _run(pipeline, _Loop(global_ba, choice, on_pair or (lambda: None), on_image or (lambda: None),
                             repeat_final_refinement))
    manager.write(out)
    return {i: manager.get(i) for i in range(manager.size())}


class _Loop:
    def __init__(self, global_ba, choice, on_pair, on_image, repeat_final: bool = True):
        self.global_ba, self.choice, self.on_pair, self.on_image = global_ba, choice, on_pair, on_image
        self.repeat_final = repeat_final

    def global_refinement(self, pipeline, mapper, mapper_options) -> None:
        opts = pipeline.options
        entry = self.choice.apply(mapper.reconstruction, self.global_ba) if self.choice else None
        t = time.perf_counter()
        mapper.iterative_global_refinement(opts.ba_global_max_refinements, opts.ba_global_max_refinement_change,
                                           mapper_options, self.global_ba, opts.get_triangulation())
        mapper.filter_frames(mapper_options)
        if entry is not None:
            entry["seconds"] = round(time.perf_counter() - t, 1)
            log.info("global adjustment of %d photos: %s solve (fill %.0f per photo), %.1f s", entry["photos"],
                     entry["solver"], entry["fill_per_photo"], entry["seconds"])


def _run(pipeline, loop: _Loop) -> None:
    """``IncrementalPipeline::Run``: map, then relax the initial pair's inliers and angle twice while
    photos are left over."""
    pycolmap = load_pycolmap()
    cache = pipeline.database_cache
    n_images = cache.num_images()
    if n_images == 0:
        return
    mapper = pycolmap.IncrementalMapper(cache)
    mapper_options = pipeline.options.get_mapper()
    done = lambda: mapper.num_total_reg_images() == n_images or pipeline.check_reached_max_runtime()  # noqa: E731
    if not _reconstruct(pipeline, mapper, mapper_options, loop):
        return
    for _ in range(2):
        for relax in ("inliers", "angle"):
            if done():
                return
            if relax == "inliers":
                mapper_options.init_min_num_inliers = int(mapper_options.init_min_num_inliers / 2)
            else:
                mapper_options.init_min_tri_angle /= 2
            mapper.reset_initialization_stats()
            if not _reconstruct(pipeline, mapper, mapper_options, loop):
                return


def _reconstruct(pipeline, mapper, mapper_options, loop: _Loop) -> bool:
    """``IncrementalPipeline::Reconstruct``: new models until the photos are used up; False when the
    whole run must stop (COLMAP's STOP)."""
    pycolmap = load_pycolmap()
    S = pycolmap.IncrementalPipelineStatus
    opts, manager, cache = pipeline.options, pipeline.reconstruction_manager, pipeline.database_cache
    for _ in range(opts.init_num_trials):
        if pipeline.check_reached_max_runtime():
            break
        idx = manager.add()
        rec = manager.get(idx)
        status = _sub_model(pipeline, mapper, mapper_options, rec, loop)
        if status == S.INTERRUPTED:
            rec.update_point_3d_errors()
            mapper.end_reconstruction(False)
            pycolmap.align_reconstruction_to_orig_rig_scales(cache.rigs, rec)
        elif status in (S.NO_INITIAL_PAIR, S.BAD_INITIAL_PAIR):
            mapper.end_reconstruction(True)
            manager.delete(idx)
            if status == S.NO_INITIAL_PAIR:   # nothing more to start from until the thresholds relax
                return True
        else:
            total = mapper.num_total_reg_images()
            if (opts.multiple_models and manager.size() > 1 and rec.num_reg_images() < opts.min_model_size) \
                    or rec.num_reg_images() == 0:
                mapper.end_reconstruction(True)
                manager.delete(idx)
            else:
                rec.update_point_3d_errors()
                mapper.end_reconstruction(False)
                pycolmap.align_reconstruction_to_orig_rig_scales(cache.rigs, rec)
            if not opts.multiple_models or manager.size() >= opts.max_num_models or total >= cache.num_images() - 1:
                return False
    return True


def _sub_model(pipeline, mapper, mapper_options, rec, loop: _Loop):
    """``IncrementalPipeline::ReconstructSubModel``: one model grown photo by photo from its initial pair."""
    pycolmap = load_pycolmap()
    S = pycolmap.IncrementalPipelineStatus
    opts = pipeline.options
    mapper.begin_reconstruction(rec)
    if rec.num_reg_frames() == 0:
        status = pipeline.initialize_reconstruction(mapper, mapper_options, rec)
        if status != S.SUCCESS:
            return status
    loop.on_pair()
    if opts.structure_less_registration_only:
        kinds = [True]
    else:
        kinds = [False, True] if opts.structure_less_registration_fallback else [False]
    tri, local_ba = opts.get_triangulation(), opts.get_local_bundle_adjustment()
    ba_frames, ba_points = rec.num_reg_frames(), rec.num_points3D()
    ok = prev_ok = True
    while ok or prev_ok:
        if pipeline.check_reached_max_runtime():
            break
        prev_ok, ok, image_id = ok, False, None
        for structure_less in kinds:
            for trial, image_id in enumerate(mapper.find_next_images(mapper_options, structure_less=structure_less)):
                ok = (mapper.register_next_structure_less_image(mapper_options, image_id) if structure_less
                      else mapper.register_next_image(mapper_options, image_id))
                if ok or (trial >= _MIN_INITIAL_TRIALS and rec.num_reg_images() < opts.min_model_size):
                    break
            if ok:
                break
        if ok:
            image = rec.images[image_id]
            for data_id in image.frame.image_ids:
                mapper.triangulate_image(tri, data_id.id)
            mapper.iterative_local_refinement(opts.ba_local_max_refinements, opts.ba_local_max_refinement_change,
                                              mapper_options, local_ba, tri, image_id)
            if pipeline.check_run_global_refinement(rec, ba_frames, ba_points):
                loop.global_refinement(pipeline, mapper, mapper_options)
                ba_frames, ba_points = rec.num_reg_frames(), rec.num_points3D()
            if opts.extract_colors:
                for data_id in image.frame.image_ids:
                    rec.extract_colors_for_image(data_id.id, opts.image_path)
            loop.on_image()
        if mapper.num_shared_reg_images() >= opts.max_model_overlap:
            break
        if not ok and prev_ok:   # nothing registered: one global refinement, then one more try
            loop.global_refinement(pipeline, mapper, mapper_options)
            if not loop.repeat_final:   # the final refinement only after a photo registers
                ba_frames, ba_points = rec.num_reg_frames(), rec.num_points3D()
    if pipeline.check_reached_max_runtime():
        return S.INTERRUPTED
    if rec.num_reg_frames() > 0 and rec.num_reg_frames() != ba_frames and rec.num_points3D() != ba_points:
        loop.global_refinement(pipeline, mapper, mapper_options)
    return S.SUCCESS
