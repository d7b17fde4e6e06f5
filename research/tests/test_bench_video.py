"""The video benchmark makes the walk it measures: rendered small, upscaled, cached; and it times
the passes of the video ingest it names."""

from __future__ import annotations

import json

import numpy as np
import pytest


@pytest.mark.slow
def test_the_walk_is_rendered_upscaled_cached_and_measured(tmp_path, capsys):
    import av

    from research.bench.bench_video import main, render_small, upscale
    small = render_small(tmp_path, 8, 30, 64, 36, jobs=1)
    big = upscale(small, tmp_path / "big.mp4", 256, 144, 30)
    with av.open(str(small)) as c:
        lo = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
    with av.open(str(big)) as c:
        s = c.streams.video[0]
        assert (s.width, s.height, float(s.average_rate)) == (256, 144, 30.0)
        hi = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
    assert len(lo) == len(hi) == 8 and lo[0].shape == (36, 64, 3)
    assert np.abs(lo[1].astype(int) - lo[0].astype(int)).mean() > 1          # the camera moves
    down = [np.asarray(av.VideoFrame.from_ndarray(h, format="rgb24").reformat(64, 36, interpolation="AREA")
                       .to_ndarray(format="rgb24"), int) for h in hi]
    assert all(np.abs(d - a.astype(int)).mean() < 8 for d, a in zip(down, lo))  # the same walk, bigger
    assert render_small(tmp_path, 8, 30, 64, 36, jobs=1) == small               # cached
    assert main(["--seconds", str(8 / 30), "--render-size", "64x36", "--size", "256x144", "--work", str(tmp_path),
                 "--jobs", "1"]) == 0
    last = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    kinds = {r["what"]: r for r in last["videos"]}
    assert kinds["analysis"]["decoded"] == kinds["extract"]["decoded"] == 8
    assert kinds["analysis"]["candidates_sha"] == kinds["extract"]["candidates_sha"]
    assert all(r["cpu_s"] >= 0 and r["wall_s"] > 0 for r in last["videos"])
