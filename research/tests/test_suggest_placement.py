"""Issue 49: ``curate suggest`` never places a camera behind a wall or nearer to a true surface than the clearance
it states, in the synthetic rooms where the truth is known (research.suggest_placement), plain walls included."""

import pytest

from research import suggest_placement as sp


@pytest.mark.slow
@pytest.mark.parametrize("room", sp.ROOMS)
def test_suggestions_stand_in_the_true_free_space_of_a_room_with_plain_walls(room):
    r = sp.cell(room, "corner", "plain", add=6, seed=1)
    assert r["placed"] == 6, r
    assert r["inside"] == 0 and r["near_stated"] == 0, r


@pytest.mark.slow
def test_an_object_capture_in_a_room_gets_suggestions_that_stand_in_it():
    r = sp.cell("kitchen", "orbit", "textured", add=6, seed=1)
    assert r["placed"] == 6 and r["kind"] == "object", r
    assert r["inside"] == 0 and r["near_stated"] == 0, r
    assert r["above_ring"] + r["below_ring"] > 0, r          # heights the ring did not film
