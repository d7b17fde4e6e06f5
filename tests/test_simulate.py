"""The synthetic comparison's plumbing: placements, distinct test sets, the table."""

import json
from dataclasses import replace

import numpy as np

from curate.progressive import ProgressiveConfig
from curate.simulate import SimulateConfig, TEST_SETS, run_simulation


def nearest_view_train(cams, images, tests, out, seed):
    """Stand-in for a NeRF: 'renders' a test view as the training photo taken nearest to it."""
    res = {}
    for name, (tc, ti) in tests.items():
        ps = []
        for k in range(len(tc)):
            j = int(np.argmin(np.linalg.norm(cams.centres - tc.centres[k], axis=1)))
            mse = np.mean((images[j].astype(float) - ti[k].astype(float)) ** 2) / 255.0 ** 2
            ps.append(-10 * np.log10(max(mse, 1e-10)))
        res[name] = {"psnr": ps, "ssim": [0.0] * len(ps)}
    return res


def test_simulation_table(tmp_path):
    cfg = SimulateConfig(scene="kitchen", budget=6, n_test=4, node_res=10, fvs_pool=60,
                         placement=ProgressiveConfig(n_candidates=60, n_free_first=3))
    cfg = replace(cfg, placement=replace(cfg.placement, camera=replace(cfg.placement.camera, width=40, height=30)))
    rep = run_simulation(cfg, tmp_path, train_fn=nearest_view_train)
    assert set(rep["table"]) == {"ours", "random", "hemisphere", "fvs"}
    for m, row in rep["table"].items():
        assert set(row) == set(TEST_SETS) | {"average"} and all(np.isfinite(v) for v in row.values())
    # Test sets are distinct from every training set.
    centres = lambda d: np.array([np.array(c["c2w"])[:3, 3] for c in d["cameras"]])  # noqa: E731
    train_c = np.concatenate([centres(d) for d in rep["cameras"].values()])
    assert len(train_c) == 4 * 6
    for t in rep["test_cameras"].values():
        test_c = centres(t)
        assert len(test_c) == 4
        assert np.min(np.linalg.norm(train_c[:, None] - test_c[None], axis=2)) > 1e-6
    assert len(rep["energy_curve"]) == 6 and rep["propose_seconds_per_camera"] > 0
    assert json.loads((tmp_path / "report.json").read_text())["budget"] == 6
