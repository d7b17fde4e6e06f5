"""The selection methods, in one registry (no heavy imports: the CLI reads it for ``--help``).

Each :class:`Method` has a key (what ``--method`` takes and ``selection.json`` records), a
label for people (the report names the selection by it: :func:`method_label`), a one-line
help (``curate run --help`` lists one line per method: :func:`method_help`) and the function
that runs it, named as ``"module:function"`` and imported only when it runs. Adding a method
is one :class:`Method` in :data:`REGISTRY` and its function, which
:func:`curate.select.select.select` calls as ``fn(cams, grid, budget, cfg, initial, index,
progress) -> Selection`` (``cfg``: the :class:`curate.select.config.SelectConfig`; ``index``:
the pool's pair index over the grid's nodes; a fallback it takes goes into
``Selection.note``).

"energy" is the paper's greedy on its energy, unchanged; "medoids" is k-medoids of the pool's
views in a centre + look-at distance (:mod:`curate.select.medoids`); "path" spaces frames
evenly along the capture path in that distance (:mod:`curate.select.path`); "fvs" is
farthest-view sampling; "stride" takes every n-th camera in name order (every n-th frame of a
video); "random" is a baseline. Variants that were measured and not adopted (pool coverage,
medoid cost powers, a sharpness prior, an energy share) live in ``research/``. "auto" runs no
function of its own: :func:`curate.select.select.resolve_method` replaces it by
:data:`WALK_METHOD` on a walk-through (viewing axes that meet nowhere, or near-parallel ones)
and by :data:`OBJECT_METHOD` on an object capture (cameras around a point, looking at it) of at most
:data:`OBJECT_METHOD_MAX_PHOTOS` photos; a larger object capture is chosen as a walk is.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from curate.core.cameras import Cameras


@dataclass(frozen=True)
class Method:
    """One selection method."""

    key: str
    """What ``--method`` takes and ``selection.json`` records, e.g. "path"."""
    label: str
    """What a person reads in the report, e.g. "even spacing along the capture path"."""
    help: str
    """One line of ``--help`` (after the key)."""
    runner: str | None
    """``"module:function"`` that runs it (imported when it runs); None for "auto", which
    :func:`curate.select.select.resolve_method` replaces by another method first."""

    @property
    def run(self) -> Callable:
        """The function that runs the method (imported now)."""
        if self.runner is None:
            raise ValueError(f"selection method {self.key!r} is resolved to another method before it runs")
        module, _, name = self.runner.partition(":")
        return getattr(import_module(module), name)


DEFAULT_METHOD = "auto"
"""The method ``curate`` uses unless told otherwise (chosen by the harness, README)."""

WALK_METHOD = "path"
""""auto" on a walk-through: frames evenly spaced along the capture path (view medoids when the
photos are not in capture order; docs/investigations/selection.md#walk-rule)."""

OBJECT_METHOD = "energy"
""""auto" on an object capture: the paper's energy, unchanged (README, 'Which selection
method, and why': over all seven every-7th hold-out folds it beat farthest-view sampling,
the earlier choice, in 5 of 6 cells of three object sets and two budgets)."""

OBJECT_METHOD_MAX_PHOTOS = 150
""""auto" on an object capture of more photos than this runs :data:`WALK_METHOD`: on the two object captures
of about 300 photos measured (a real plant, 292 photos, and the rendered photo-textured orbit of a coffee table
in a room, 300), at 14-15% the paper's energy was below random and path spacing ahead of it
(docs/investigations/selection.md#objects); the energy's evidence is three real objects of 47-67 photos. 150
lies between the two, where nothing was measured."""

PATH_WEIGHTS = True
"""Default of ``MedoidsConfig.path_weights`` (docs/investigations/selection.md)."""

_SELECT = "curate.select.select"

REGISTRY: dict[str, Method] = {m.key: m for m in (
    Method("auto", "chosen by the kind of capture",
           f"{WALK_METHOD} on a walk-through, {OBJECT_METHOD} on an object capture of at most "
           f"{OBJECT_METHOD_MAX_PHOTOS} photos (told apart by the poses)", None),
    Method("path", "even spacing along the capture path",
           "frames evenly spaced along the capture path by view change (view medoids when the "
           "photos are not in capture order)", f"{_SELECT}:run_path"),
    Method("medoids", "view medoids",
           "the photos whose views lie closest, on average, to every view of the pool", f"{_SELECT}:run_medoids"),
    Method("energy", "the paper's energy",
           "Kopanas & Drettakis's greedy on their energy, unchanged", f"{_SELECT}:run_energy"),
    Method("fvs", "farthest-view sampling",
           "each next photo the one farthest from those already chosen", f"{_SELECT}:run_fvs"),
    Method("stride", "every n-th frame",
           "every n-th photo in name order (every n-th frame of a video)", f"{_SELECT}:run_stride"),
    Method("random", "random", "a random subset (--seed)", f"{_SELECT}:run_random"),
)}
"""Every selection method, in the order ``--help`` lists them."""

METHODS = tuple(REGISTRY)
"""Every selection method :func:`curate.select.select.select` knows (``--method``'s choices)."""


def get_method(key: str) -> Method:
    """The :class:`Method` of ``key`` (ValueError naming the known ones when there is none)."""
    try:
        return REGISTRY[key]
    except KeyError:
        raise ValueError(f"unknown selection method {key!r} (one of {', '.join(REGISTRY)})") from None


def method_label(key: str) -> str:
    """What a person reads for the method ``key`` (the report's name of a selection), e.g.
    "path" -> "even spacing along the capture path"; an unknown key (a research variant, a
    record of another version) is returned as it is."""
    m = REGISTRY.get(key)
    return m.label if m is not None else key


def method_help() -> str:
    """``--method``'s help: one line per method, the default marked."""
    width = max(map(len, REGISTRY))
    lines = ["how to choose the photos:"]
    for m in REGISTRY.values():
        lines.append(f"{m.key:<{width}}  {m.help}" + (" (default)" if m.key == DEFAULT_METHOD else ""))
    return "\n".join(lines)


OBJECT_MAX_ANGLE_DEG = 20.0
""":func:`capture_kind`: an object capture when the median camera looks within this angle of
the point nearest all viewing axes (measured: object sets 0.6-7.2 deg, walks 55-56 deg)."""


def capture_kind(cams: Cameras) -> tuple[str, float]:
    """("object" | "walk", median angle in degrees) for a pool of cameras.

    The point p nearest every viewing axis (least squares, ``sum_i (I - v_i v_i^T)(p - c_i) = 0``)
    is where an object capture's cameras look; the angle between each camera's viewing
    direction and the direction from its centre to p is then small for almost every camera.
    On a walk-through the axes do not meet: the angles are large. Near-parallel axes
    (a forward-facing capture with little convergence) count as a walk; a forward-facing
    capture whose axes converge on the subject counts as an object capture. Fewer than 3 cameras, or axes all
    parallel, count as a walk.
    """
    import numpy as np
    if len(cams) < 3:
        return "walk", 180.0
    c, v = cams.centres, cams.view_dirs                       # [K, 3], [K, 3]
    P = np.eye(3)[None] - v[:, :, None] * v[:, None, :]        # [K, 3, 3] projectors off each axis
    A, b = P.sum(0), np.einsum("kij,kj->i", P, c)
    if np.linalg.eigvalsh(A / len(c))[0] < 1e-3:               # (near) parallel axes: no meeting point
        return "walk", 180.0
    p = np.linalg.solve(A, b)
    to = p - c
    n = np.linalg.norm(to, axis=1)
    cos = np.sum(to * v, axis=1) / np.maximum(n, 1e-300)
    ang = float(np.median(np.degrees(np.arccos(np.clip(np.where(n > 0, cos, -1.0), -1.0, 1.0)))))
    return ("object" if ang < OBJECT_MAX_ANGLE_DEG else "walk"), ang


def resolve_method(cams: Cameras, method: str, kind: tuple[str, float] | None = None) -> tuple[str, str]:
    """(method that runs, note) for ``method`` on ``cams``: "auto" becomes ``OBJECT_METHOD``
    on an object capture of at most ``OBJECT_METHOD_MAX_PHOTOS`` photos and ``WALK_METHOD`` on a walk
    or a larger object capture (:func:`capture_kind`, or ``kind`` when the caller has it), with a note saying why;
    any other method runs as given, with no note."""
    if method != "auto":
        return method, ""
    kind, ang = kind if kind is not None else capture_kind(cams)
    large = kind == "object" and len(cams) > OBJECT_METHOD_MAX_PHOTOS
    method = OBJECT_METHOD if kind == "object" and not large else WALK_METHOD
    why = ("the cameras look at one point (an object capture; their median angle to it {:.0f} deg)" if kind == "object"
           else "the cameras do not look at one point (a walk-through; their median angle to the nearest common "
                "point {:.0f} deg)").format(ang)
    if large:
        why += f"; {len(cams)} photos, more than {OBJECT_METHOD_MAX_PHOTOS}: spaced as a walk is"
    return method, f"auto: {why} -> {method}"
