"""research.gap_closed: the gap counts only where all frames are significantly above random."""

from research.gap_closed import scene_cells
from research.tests.conftest import harness_unit


def test_gap_closed_only_where_all_frames_beat_random(tmp_path):
    ev = tmp_path / "walk-x" / "evaluate"
    harness_unit(ev, "all", [30, 31, 32, 33], [20.0, 20.1, 19.9, 20.0])
    harness_unit(ev, "q_random_s0_b10_t0", [28, 29, 30, 31], [20.0, 19.9, 20.1, 20.0])   # path: 2 dB below all
    harness_unit(ev, "q_default-abc_b10_t0", [29.5, 30.5, 31.5, 32.5], [20.0, 20.0, 20.0, 20.0])
    rows = {r["part"]: r for r in scene_cells(tmp_path / "walk-x")}
    assert rows["path"]["significant"] and rows["path"]["all_minus_random"] == 2.0
    assert rows["path"]["closed"] == 0.75                       # 1.5 of 2 dB
    assert not rows["off"]["significant"]                       # all = random off the path: no real gap
    assert rows["path"]["views"] == 4 and rows["off"]["views"] == 4
    assert scene_cells(tmp_path / "walk-x", "fvs") == []        # no unit of that method
