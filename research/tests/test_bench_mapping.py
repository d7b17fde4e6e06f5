"""research.bench.bench_mapping's hall walk: the capture that covers new ground, for SfM's growth past
1,000 photos (docs/sfm.md)."""

import numpy as np

from research.bench.bench_mapping import HALL_WIDTH, capture_cameras, capture_scene, hall_scene, hall_walk


def test_the_hall_walk_stays_in_the_hall_and_never_comes_back():
    cams, omega = hall_walk(600)
    scene = hall_scene(600)
    lo, hi = scene.interior
    c = cams.centres
    assert np.all((c > lo + 0.5) & (c < hi - 0.5))                        # inside, clear of the walls
    assert not scene.occupied(c).any()
    assert np.all(np.diff(c[:, 0]) > 0)                                   # always onward
    assert hi[0] - c[-1, 0] >= 1.9 and c[0, 0] >= 2.0
    ahead = cams.rotations[:, :, 2]                                       # optical axes
    yaw = np.degrees(np.arctan2(ahead[:, 1], ahead[:, 0]))
    assert np.abs(yaw).max() < 90 and np.abs(yaw).max() > 60             # the gaze swings wall to wall
    assert np.all(np.isfinite(omega)) and omega.max() < 0.15                 # under 9 deg a frame
    assert np.allclose(hall_walk(600)[0].c2w, cams.c2w)                   # deterministic
    assert len(capture_cameras("hall", 600)[0]) == 600


def test_the_hall_is_furnished_along_both_walls_and_lit_near_the_camera():
    from research.bench.bench_mapping import _lit_near
    scene = capture_scene("hall", 300)
    lo, hi = scene.interior
    assert abs(hi[1] - HALL_WIDTH) < 1e-9 and hi[0] > 300 * 0.035
    mids = np.array([(np.asarray(s.lo) + (np.asarray(s.hi) if s.kind == "box" else np.asarray(s.lo))) / 2
                     for s in scene.solids[6:]])
    for wall in (0.5, HALL_WIDTH - 0.5):                                  # something every few metres on each side
        near = np.sort(mids[np.abs(mids[:, 1] - wall) < 0.6, 0])
        assert np.diff(near).max() < 3.0
    cams, _ = capture_cameras("hall", 300)
    lit = _lit_near(scene, cams.centres[150])
    assert len(lit.lights) == 3 and lit._rc is scene._rc
    assert np.linalg.norm(lit.lights - cams.centres[150], axis=1).max() < 10


def test_the_walk_there_and_back_sees_each_stretch_from_both_sides():
    from research.bench.bench_mapping import hall_there_and_back
    cams, omega = hall_there_and_back(600)
    scene = capture_scene("hall_back", 600)
    lo, hi = scene.interior
    c = cams.centres
    assert np.all((c > lo + 0.5) & (c < hi - 0.5)) and not scene.occupied(c).any()
    there, back = c[:300], c[300:]
    assert np.all(np.diff(there[:, 0]) > 0) and np.all(np.diff(back[:, 0]) < 0)   # down the hall, then back
    assert there[:, 1].max() < HALL_WIDTH / 2 - 0.1 and back[:, 1].min() > HALL_WIDTH / 2 + 0.1   # other side
    assert abs(back[-1, 0] - there[0, 0]) < 0.1 and abs(back[0, 0] - there[-1, 0]) < 0.1     # the same stretch
    ahead = cams.rotations[:, :, 2]
    assert np.mean(ahead[:300, 0]) > 0.3 and np.mean(ahead[300:, 0]) < -0.3                 # facing the way walked
    assert np.allclose(np.linalg.det(cams.rotations), 1.0) and np.all(np.isfinite(omega))
    assert len(capture_cameras("hall_back", 600)[0]) == 600


def test_the_grid_flight_looks_down_in_strips_that_overlap_side_by_side():
    from research.bench.bench_mapping import GRID_ALTITUDE, GRID_SPACING, grid_flight, grid_plan
    n = 1200
    cams, omega = grid_flight(n)
    scene = capture_scene("grid", n)
    lo, hi = scene.interior
    c = cams.centres
    assert np.all((c > lo + 1.0) & (c < hi - 1.0)) and not scene.occupied(c).any()
    assert np.all(np.abs(c[:, 2] - GRID_ALTITUDE) < 0.2)
    k, ls = grid_plan(n)
    rows = np.round((c[:, 1] - c[0, 1]) / GRID_SPACING, 6)
    strips = sorted(set(r for r in rows if float(r).is_integer()))
    assert len(strips) == k and k >= 8 and abs(ls - (k - 1) * GRID_SPACING) < 3.0       # about square
    ahead = cams.rotations[:, :, 2]
    assert np.all(ahead[:, 2] < -0.99)                                                   # straight down, within 8 deg
    top = -cams.rotations[:, :, 1]                                                       # the image's top
    assert np.all(top[:, 0] > 0.99)                                                      # fixed heading
    step = np.linalg.norm(np.diff(c[:, :2], axis=0), axis=1)
    assert np.all(step < 0.1 + 1e-9) and np.mean(np.abs(step - 0.1) < 1e-9) > 0.97       # 1 m/s at 10 frames a second
    assert step.min() > 0.07                                                             # (a corner cut short)
    # photos of neighbouring strips, abreast of each other, see overlapping ground (65% of 3.5 m)
    half_w = GRID_ALTITUDE * np.tan(np.radians(30))
    assert 2 * half_w - GRID_SPACING > 0.6 * 2 * half_w
    assert np.all(np.isfinite(omega)) and omega.max() < 0.05                             # under 3 deg a frame
    assert np.allclose(grid_flight(n)[0].c2w, cams.c2w)                                  # deterministic
    assert len(capture_cameras("grid", n)[0]) == n
