"""COLMAP's incremental mapper with the global bundle adjustment's options in our hands (measured, not
adopted: checked equal to COLMAP's pipeline on the fox; on the 3,000-frame walk a direct solve of every
global adjustment took 2,297 CPU s of mapping against 1,464 with COLMAP's iterative solver past 1,000
photos, 2026-11-27, docs/sfm.md "Mapping past 1,000 photos"). research.mapping_profile times its steps.

``pycolmap.incremental_mapping`` builds the options of its global bundle adjustments inside C++, with
Ceres' solver choice left at COLMAP's defaults: past ``max_num_images_direct_sparse_cpu_solver``
(1,000) photos in the model the normal equations are no longer factored (sparse Schur complement,
Cholesky) but solved iteratively (``ITERATIVE_SCHUR``), which on a long walk needs many conjugate
gradient steps per iteration (a hypothesis for the mapping's growth past 1,000 photos; refuted: the
iterative solve is the faster one there). :func:`incremental_mapping`
runs the same steps in the same order as COLMAP's ``IncrementalPipeline`` (``controllers/
incremental_pipeline.cc``: the initial pair by the pipeline's own ``initialize_reconstruction``;
each next image registered, triangulated and refined locally by pycolmap's ``IncrementalMapper``; a
global refinement when the model has grown by the pipeline's ratios; models, retries and the two
relaxations of the initial pair's thresholds as COLMAP has them), and takes the global adjustment's
options as an argument. What is written here is only that loop: every step is pycolmap's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

_MIN_INITIAL_TRIALS = 30   # COLMAP: a new model that cannot grow after this many trials gives up


def incremental_mapping(database: Path, images: Path, out: Path, options, global_ba,
                        on_pair: Callable[[], None] | None = None,
                        on_image: Callable[[], None] | None = None) -> dict:
    """{index: pycolmap.Reconstruction} mapped from ``database`` as ``pycolmap.incremental_mapping``
    would with ``options`` (pycolmap.IncrementalPipelineOptions), except that every global bundle
    adjustment after the initial pair uses ``global_ba`` (pycolmap.BundleAdjustmentOptions, e.g.
    ``options.get_global_bundle_adjustment()`` with another solver threshold). Models are written to
    ``out``/0, ``out``/1, ... as COLMAP writes them. ``on_pair`` is called when a model's initial pair
    is registered, ``on_image`` after each further registration."""
    import pycolmap

    options.image_path = str(images)
    out.mkdir(parents=True, exist_ok=True)
    manager = pycolmap.ReconstructionManager()
    with pycolmap.Database.open(database) as db:
        pipeline = pycolmap.IncrementalPipeline(options, db, manager)
        _run(pipeline, global_ba, on_pair or (lambda: None), on_image or (lambda: None))
    manager.write(out)
    return {i: manager.get(i) for i in range(manager.size())}


def _run(pipeline, global_ba, on_pair, on_image) -> None:
    """``IncrementalPipeline::Run``: map, then relax the initial pair's inliers and angle twice while
    photos are left over."""
    import pycolmap
    cache = pipeline.database_cache
    n_images = cache.num_images()
    if n_images == 0:
        return
    mapper = pycolmap.IncrementalMapper(cache)
    mapper_options = pipeline.options.get_mapper()
    done = lambda: mapper.num_total_reg_images() == n_images or pipeline.check_reached_max_runtime()  # noqa: E731
    if not _reconstruct(pipeline, mapper, mapper_options, global_ba, on_pair, on_image):
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
            if not _reconstruct(pipeline, mapper, mapper_options, global_ba, on_pair, on_image):
                return


def _reconstruct(pipeline, mapper, mapper_options, global_ba, on_pair, on_image) -> bool:
    """``IncrementalPipeline::Reconstruct``: new models until the photos are used up; False when the
    whole run must stop (COLMAP's STOP)."""
    import pycolmap
    S = pycolmap.IncrementalPipelineStatus
    opts, manager, cache = pipeline.options, pipeline.reconstruction_manager, pipeline.database_cache
    for _ in range(opts.init_num_trials):
        if pipeline.check_reached_max_runtime():
            break
        idx = manager.add()
        rec = manager.get(idx)
        status = _sub_model(pipeline, mapper, mapper_options, rec, global_ba, on_pair, on_image)
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


def _global_refinement(pipeline, mapper, mapper_options, global_ba) -> None:
    opts = pipeline.options
    mapper.iterative_global_refinement(opts.ba_global_max_refinements, opts.ba_global_max_refinement_change,
                                       mapper_options, global_ba, opts.get_triangulation())
    mapper.filter_frames(mapper_options)


def _sub_model(pipeline, mapper, mapper_options, rec, global_ba, on_pair, on_image):
    """``IncrementalPipeline::ReconstructSubModel``: one model grown photo by photo from its initial pair."""
    import pycolmap
    S = pycolmap.IncrementalPipelineStatus
    opts = pipeline.options
    mapper.begin_reconstruction(rec)
    if rec.num_reg_frames() == 0:
        status = pipeline.initialize_reconstruction(mapper, mapper_options, rec)
        if status != S.SUCCESS:
            return status
    on_pair()
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
                _global_refinement(pipeline, mapper, mapper_options, global_ba)
                ba_frames, ba_points = rec.num_reg_frames(), rec.num_points3D()
            if opts.extract_colors:
                for data_id in image.frame.image_ids:
                    rec.extract_colors_for_image(data_id.id, opts.image_path)
            on_image()
        if mapper.num_shared_reg_images() >= opts.max_model_overlap:
            break
        if not ok and prev_ok:   # nothing registered: one global refinement, then one more try
            _global_refinement(pipeline, mapper, mapper_options, global_ba)
    if pipeline.check_reached_max_runtime():
        return S.INTERRUPTED
    if rec.num_reg_frames() > 0 and rec.num_reg_frames() != ba_frames and rec.num_points3D() != ba_points:
        _global_refinement(pipeline, mapper, mapper_options, global_ba)
    return S.SUCCESS
