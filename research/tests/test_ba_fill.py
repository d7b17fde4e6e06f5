"""research.ba_fill: the fill of a direct solve tells a chain of photos from a room seen again and again."""
import numpy as np

from research.ba_fill import fill_of_tracks


def _chain(n):                      # a walk down a hall: each point seen by 4 consecutive photos
    return [list(range(i, min(i + 4, n))) for i in range(n)]


def _room(n, per=100):              # a room circled every `per` photos: a point seen again on each round
    rounds = n // per
    return [[k + r * per + j for r in range(rounds) for j in (0, 1)] for k in range(per - 1)] + _chain(n)


def test_a_chain_has_a_fill_per_photo_that_does_not_grow():
    small, big = fill_of_tracks(_chain(200), 200), fill_of_tracks(_chain(2000), 2000)
    assert small["pattern_per_photo"] <= 7 and big["nnz_L_per_photo"] <= 1.2 * small["nnz_L_per_photo"]
    assert big["flops"] <= 12 * small["flops"]             # linear in the photos, not faster


def test_a_room_circled_again_fills_more_as_it_grows():
    small, big = fill_of_tracks(_room(300), 300), fill_of_tracks(_room(3000), 3000)
    chain = fill_of_tracks(_chain(3000), 3000)
    assert big["nnz_L_per_photo"] > 3 * chain["nnz_L_per_photo"]
    assert big["nnz_L_per_photo"] > 2 * small["nnz_L_per_photo"]


def test_degenerate_tracks_give_a_diagonal():
    r = fill_of_tracks([[], [3], [5, 5]], 10)
    assert r == {"n": 10, "pattern_per_photo": 1.0, "nnz_L_per_photo": 1.0, "flops": 10.0}
    assert np.isfinite(fill_of_tracks([[0, 1]], 2)["flops"])
