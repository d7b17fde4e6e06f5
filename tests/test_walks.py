"""Hand-held walks through the synthetic rooms (the long-capture benchmark and the harness's walk scenes)."""

from __future__ import annotations

import numpy as np
import pytest

from curate.simulate.walks import WALK_KINDS, hand_held_walk, motion_blur


@pytest.mark.parametrize("kind", WALK_KINDS)
def test_walks_stay_in_the_free_room_turn_smoothly_and_repeat(kind):
    from curate.simulate.synthetic import LAYOUTS, make_scene
    for layout in LAYOUTS:
        scene = make_scene(layout, 0)
        cams, omega = hand_held_walk(600, kind, seed=3, room=scene.interior)
        assert len(cams) == 600 and np.isfinite(cams.c2w).all()
        assert not scene.occupied(cams.centres).any(), f"{kind} in {layout}: a camera inside a solid"
        R = cams.rotations
        assert np.allclose(R @ np.transpose(R, (0, 2, 1)), np.eye(3), atol=1e-9)
        step = np.linalg.norm(np.diff(cams.centres, axis=0), axis=1)
        jumps = (step > 0.2).sum()               # a walker moves a few cm a frame; two sessions jump once
        assert jumps == (1 if kind == "two_sessions" else 0)
        assert omega.max() < 0.5                 # under 5 rad/s at 10 frames a second: no teleporting gaze
    again, _ = hand_held_walk(600, kind, seed=3, room=scene.interior)
    assert np.array_equal(again.c2w, cams.c2w)


def test_walk_rejects_unknown_kind_and_too_few_frames():
    with pytest.raises(ValueError, match="kind"):
        hand_held_walk(10, "jog")
    with pytest.raises(ValueError, match="2 frames"):
        hand_held_walk(1)


def test_motion_blur_blurs_along_x_in_proportion_to_the_turn():
    rgb = np.zeros((8, 64, 3), np.uint8)
    rgb[:, 32] = 255
    assert motion_blur(rgb, 0.001, 500.0, 0.5) is rgb              # under 2 px: untouched
    b = motion_blur(rgb, 0.04, 500.0, 0.5)                          # 10 px
    row = b[4, :, 0].astype(int)
    assert (row > 0).sum() == 10 and row.max() < 255 and np.array_equal(b[0], b[7])
