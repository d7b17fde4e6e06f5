"""The samples in data_samples/ are the project's own renders (scripts/make_sample_pool.py), and the README's
main job runs on one that behaves like a real capture: crowded where the walker lingered, sparse where they
hurried, a stretch walked back, blurred swings of the camera and a second pass."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from curate.core.transforms_json import read_transforms
from curate.simulate.walks import filmed_walk

SAMPLES = Path(__file__).resolve().parents[1] / "data_samples"


def test_the_filmed_sample_is_the_walk_the_script_renders():
    cams, _ = filmed_walk()
    got, files = read_transforms(SAMPLES / "room_capture" / "transforms.json")
    assert [Path(f).name for f in files] == [Path(n).name for n in cams.names]
    assert np.allclose(got.c2w, cams.c2w, atol=1e-9) and np.allclose(got.fx, cams.fx)
    assert all(Path(f).is_file() for f in files)


def test_the_filmed_walk_lingers_hurries_turns_back_blurs_and_passes_twice():
    from curate.simulate.synthetic import make_scene
    cams, omega = filmed_walk()
    c = cams.centres
    step = np.linalg.norm(np.diff(c[:, :2], axis=0), axis=1)        # [N-1] metres between frames
    assert np.percentile(step, 90) > 4 * np.percentile(step, 10)      # lingering and walking on
    ahead = np.diff(c[:, :2], axis=0)
    turned = np.einsum("ij,ij->i", ahead[1:], ahead[:-1]) < 0         # the walker reversed
    assert turned.sum() >= 2
    blur_px = omega * cams.fx / 12                                    # a 1/60 s shutter, frames 1/5 s apart
    assert 5 <= (blur_px >= 4).sum() <= 60                            # blurred stretches, not most frames
    assert len(set(np.round(c[:, 2], 1))) >= 2 and c[:, 2].min() < 1.3 < c[:, 2].max()   # a lower second pass
    assert not make_scene("livingroom", seed=0).occupied(c).any()
