"""The selection's record, ``RUN/select/selection.json``, one schema written by :func:`selection_record` for a run
folder (:mod:`curate.select.stage`) and for ``curate select POSES --out DIR`` alike: ``method`` (what ran),
``budget`` (the resolved count), ``budget_text`` (as given; ``default`` with what it meant for this capture,
"default: 15% (a walk-through)"), ``pool`` (the candidates: every registered camera) and ``holdout`` (empty: kept
for older readers), ``holdout_every`` (0), ``chosen`` (camera indices in the order chosen), ``chosen_names``,
per-step ``energy`` / ``angular`` / ``frequency``, ``seconds``, ``n_nodes``, ``up_axis``, ``note``, ``box`` /
``res`` of the node grid, ``coverage`` (:func:`coverage`), and with ``--budget auto`` ``budget_auto``
(:class:`curate.select.auto_budget.BudgetChoice`: the predicted loss curve and why). ``nodes.npz``: ``nodes``
[M,3], per-node ``angular`` and ``frequency`` of the chosen set, ``flat`` [M] grid indices, ``res``, ``box_min``,
``box_max``. Camera indices are into ``RUN/sfm/cameras.json``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from curate.core.cameras import Cameras
    from curate.core.grid import NodeGrid
    from curate.select.select import Selection


def up_axis(cams: "Cameras") -> int:
    """World axis closest to the cameras' mean up direction (-y of OpenCV cameras)."""
    up = -cams.c2w[:, :3, 1].mean(0)
    return int(np.argmax(np.abs(up)))


def coverage(index, chosen) -> dict:
    """How much of what the whole capture sees the chosen cameras see: over the scene's surface
    nodes seen by at least one camera of the pool (``index``: its pair index), the fraction seen by
    at least one (``seen``) and at least two (``seen_twice``) of ``chosen`` (pool indices).
    {"seen", "seen_twice", "n_nodes_seen"}; fractions are 0 when the pool sees no node."""
    cams = np.asarray(index.cam, np.int64)                                   # [P]
    node_of = np.repeat(np.arange(index.n_nodes), np.diff(index.indptr))     # [P]
    pick = np.zeros(index.n_cams, bool)
    pick[np.asarray(list(chosen), np.int64)] = True
    by_pool = np.bincount(node_of, minlength=index.n_nodes)                  # [M] cameras seeing each node
    by_chosen = np.bincount(node_of[pick[cams]], minlength=index.n_nodes)    # [M] chosen cameras seeing it
    n = int((by_pool > 0).sum())
    frac = (lambda m: float(m.sum() / n) if n else 0.0)
    return {"seen": frac(by_chosen >= 1), "seen_twice": frac(by_chosen >= 2), "n_nodes_seen": n}


def selection_record(sel: "Selection", cams: "Cameras", pool: list[int], holdout: list[int], holdout_every: int,
                     budget_text: str, grid: "NodeGrid") -> dict:
    """The ``selection.json`` record of ``sel`` (chosen indices into ``pool``) over all cameras ``cams``."""
    chosen = [int(pool[k]) for k in sel.chosen]
    return {**sel.to_dict(), "chosen": chosen, "initial": [], "chosen_names": [cams.names[i] for i in chosen],
            "budget": len(chosen), "budget_text": budget_text, "holdout_every": holdout_every,
            "holdout": list(holdout), "pool": list(pool), "n_nodes": len(grid.active_indices()),
            "up_axis": up_axis(cams), "res": int(grid.res), "box": grid.box_min.tolist() + grid.box_max.tolist()}
