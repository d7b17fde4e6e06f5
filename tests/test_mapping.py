"""curate.sfm.mapping: the fill of a direct solve, and the solver it picks for a global adjustment past
1,000 photos (issue 36, part 5; docs/investigations/sfm.md#global-ba-solver)."""
import numpy as np
import pytest

from curate.sfm import mapping
from curate.sfm.mapping import ALWAYS_DIRECT, SolverChoice, fill_per_photo


def _chain(n):                      # a walk down a hall: each point seen by 4 consecutive photos
    return [list(range(i, min(i + 4, n))) for i in range(n)]


def _room(n, per=100):              # a room circled every `per` photos: a point seen again on each round
    rounds = n // per
    return [[k + r * per + j for r in range(rounds) for j in (0, 1)] for k in range(per - 1)] + _chain(n)


def _grid(rows, cols, reach=3):     # a grid flight: a point seen by photos within `reach` along and across
    idx = np.arange(rows * cols).reshape(rows, cols)
    return [idx[r:r + 2, c:c + reach].ravel().tolist() for r in range(rows) for c in range(cols)]


def test_a_chain_has_a_fill_per_photo_that_does_not_grow():
    small, big = fill_per_photo(_chain(200), 200), fill_per_photo(_chain(2000), 2000)
    assert small["pattern_per_photo"] <= 7 and big["nnz_L_per_photo"] <= 1.2 * small["nnz_L_per_photo"]
    assert big["flops"] <= 12 * small["flops"]             # linear in the photos, not faster


def test_a_room_circled_again_and_a_grid_fill_more_as_they_grow():
    chain = fill_per_photo(_chain(3000), 3000)
    for small, big in ((fill_per_photo(_room(300), 300), fill_per_photo(_room(3000), 3000)),
                       (fill_per_photo(_grid(10, 30), 300), fill_per_photo(_grid(30, 100), 3000))):
        assert big["nnz_L_per_photo"] > 3 * chain["nnz_L_per_photo"]
        assert big["nnz_L_per_photo"] > 1.5 * small["nnz_L_per_photo"]


def test_degenerate_tracks_give_a_diagonal_and_nothing_is_nan():
    assert fill_per_photo([[], [3], [5, 5]], 10) == {"n": 10, "pattern_per_photo": 1.0, "nnz_L_per_photo": 1.0,
                                                     "flops": 10.0}
    assert fill_per_photo([], 0) == {"n": 0, "pattern_per_photo": 0.0, "nnz_L_per_photo": 0.0, "flops": 0.0}
    one = fill_per_photo([[0, 1]], 2)
    assert all(np.isfinite(v) for v in one.values())
    every = fill_per_photo([list(range(50))], 50)            # every photo sees every point: a dense factor
    assert every["nnz_L_per_photo"] == pytest.approx(25.5)


class _Model:                       # what SolverChoice reads of a pycolmap Reconstruction
    def __init__(self, n):
        self.n = n

    def num_reg_images(self):
        return self.n


@pytest.mark.parametrize("photos, fill, max_fill, solver", [
    (900, 50.0, 270.0, None),            # within Ceres' limit: its own direct solve, nothing measured
    (1500, 150.0, 270.0, "direct"),      # a chain past it: direct
    (1500, 400.0, 270.0, "iterative"),   # a room seen round and round: Ceres' iterative solve
    (1500, 150.0, 0.0, None),            # max_fill 0: Ceres' choice everywhere
])
def test_the_solver_of_a_global_adjustment_follows_the_fill(monkeypatch, photos, fill, max_fill, solver):
    import pycolmap
    seen = []
    monkeypatch.setattr(mapping, "reconstruction_fill", lambda rec: seen.append(rec.n) or {"nnz_L_per_photo": fill})
    choice, ba = SolverChoice(max_fill, 1000), pycolmap.BundleAdjustmentOptions()
    entry = choice.apply(_Model(photos), ba)
    limit = ba.ceres.max_num_images_direct_sparse_cpu_solver
    if solver is None:
        assert entry is None and choice.record == [] and seen == [] and limit == 1000
    else:
        assert entry == choice.record[0] and entry["solver"] == solver and entry["photos"] == photos
        assert entry["fill_per_photo"] == fill and seen == [photos]
        assert limit == (ALWAYS_DIRECT if solver == "direct" else 1000)
    assert mapping.ceres_direct_limit() == 1000             # COLMAP's own limit, which curate leaves below it
