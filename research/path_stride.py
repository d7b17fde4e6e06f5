"""Variants of the product's method "path" (:mod:`curate.select.path`): a look-at scale and a
power on each step of the arc length.

``look_scale`` < 1 scales each camera's look-at depth, so a turn of the head counts for less
against a step of the walker; ``power`` in [0, 1] raises each step (in median steps) to that
power before summing: 1 is the product's arc length, 0 counts frames (every n-th frame).
"""

from __future__ import annotations

import numpy as np

from curate.core.cameras import Cameras
from curate.select.medoids import embed, path_steps, view_depths
from curate.select.path import spaced


def arc_length(c: np.ndarray, a: np.ndarray, power: float = 1.0) -> np.ndarray | None:
    """[K] cumulative sum of the capped steps (:func:`curate.select.medoids.path_steps`) of the
    embedded views ``c``, ``a`` [K, 3] raised to ``power``; None when they form no path."""
    step = path_steps(c, a)
    return None if step is None else np.concatenate([[0.0], np.cumsum(step ** power)])


def path_stride(cams: Cameras, budget: int, nodes=None, index=None, initial=(),
                look_scale: float = 1.0, power: float = 1.0) -> list[int] | None:
    """As :func:`curate.select.path.path_select`, with the look-at depths scaled by
    ``look_scale`` and each step raised to ``power``; None when the cameras are not in capture order."""
    c, a = embed(cams, look_scale * view_depths(cams, nodes, index))
    s = arc_length(c, a, power)
    return None if s is None else spaced(s, budget, initial)
