"""The long-capture benchmark renders the walk it measures: videos of the walk's first N frames."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.slow
def test_walk_videos_hold_the_walks_first_frames(tmp_path):
    import av

    from research.bench.bench_capture import _truth_cameras, render_videos
    paths = render_videos(tmp_path, [3, 5], "kitchen", "loop", 0, 1)
    frames = {}
    for n, p in paths.items():
        with av.open(str(p)) as c:
            frames[n] = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
        assert len(frames[n]) == n and frames[n][0].shape == (480, 640, 3)
    # the shorter video is the start of the longer one (the same walk), up to H.264's loss
    assert all(np.abs(a.astype(int) - b.astype(int)).mean() < 3 for a, b in zip(frames[3], frames[5]))
    truth = _truth_cameras(paths[5], tmp_path)
    assert len(truth) == 5 and truth.names[4] == "frame_00004"
    assert render_videos(tmp_path, [3, 5], "kitchen", "loop", 0, 1) == paths   # cached
