"""Names of the selection methods (no heavy imports: the CLI reads them for ``--help``).

"energy" is the paper's greedy on its energy, unchanged; "medoids" is k-medoids of the pool's
views in a centre + look-at distance (:mod:`curate.select.medoids`); "path" spaces frames
evenly along the capture path in that distance (:mod:`curate.select.path`); "fvs" is farthest-view
sampling; "stride" takes every n-th camera in name order (every n-th frame of a video);
"random" is a baseline. Variants that were measured and not adopted (pool coverage, medoid
cost powers, a sharpness prior, an energy share) live in ``research/``. "auto" picks by the kind of capture
(:func:`curate.select.select.capture_kind`): ``WALK_METHOD`` for a walk-through (viewing axes that
meet nowhere, or near-parallel ones), ``OBJECT_METHOD`` for an object capture (cameras around
a point, looking at it).
"""

METHODS = ("auto", "energy", "random", "fvs", "stride", "medoids", "path")
"""Every selection method :func:`curate.select.select.select` knows."""

DEFAULT_METHOD = "auto"
"""The method ``curate`` uses unless told otherwise (chosen by the harness, README)."""

WALK_METHOD = "path"
""""auto" on a walk-through: frames evenly spaced along the capture path (view medoids when the
photos are not in capture order; docs/selection-evidence.md, "A walk rule chosen on 21 walks")."""

OBJECT_METHOD = "energy"
""""auto" on an object capture: the paper's energy, unchanged (README, 'Which selection
method, and why': over all seven every-7th hold-out folds it beat farthest-view sampling,
the earlier choice, in 5 of 6 cells of three object sets and two budgets)."""

METHOD_HELP = ("selection method (default %(default)s; energy: the paper's, unchanged; "
               "see the README's 'Which selection method, and why')")

PATH_WEIGHTS = True
"""Default of ``MedoidsConfig.path_weights`` (README, 'Which selection method, and why')."""

PATH_HELP = ("view medoids: weigh each frame by the stretch of the capture path it stands for, "
             "so the subset covers the walk by distance, not by frame count (frames in name order; "
             "default %(default)s)")
