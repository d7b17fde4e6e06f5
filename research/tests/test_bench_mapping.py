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
