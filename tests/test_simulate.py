"""The synthetic comparison's plumbing: placements, distinct test sets, the table."""

import json
from dataclasses import replace

import numpy as np
import pytest

from curate.simulate.progressive import ProgressiveConfig
from curate.simulate.experiment import SimulateConfig, TEST_SETS, run_simulation


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


@pytest.mark.slow
def test_field_variant_end_to_end(tmp_path):
    """Algorithm 1 with occupancy from the field being trained: runs, keeps cameras out of solids,
    records the occupancy source and the loop's timings."""
    from curate.core.cameras import Cameras
    from curate.field.model import FieldConfig
    from curate.simulate.progressive import FieldOccupancyConfig
    from curate.simulate.synthetic import make_scene
    tiny = FieldConfig(res_schedule=(24, 32), upsample_at=(100,), n_inner=32, n_outer=8, batch_rays=1024,
                       val_every=0, occ_update_start=15, occ_update_every=15, tv_block=12)
    cfg = SimulateConfig(scene="kitchen", budget=6, n_test=3, node_res=10, methods=("ours", "random"),
                         occupancy="field", train_between=30, loop_field=tiny,
                         field_occupancy=FieldOccupancyConfig(warmup=3, min_iters=60, res=16),
                         placement=ProgressiveConfig(n_candidates=40, n_free_first=3))
    cfg = replace(cfg, placement=replace(cfg.placement, camera=replace(cfg.placement.camera, width=48, height=36)))
    rep = run_simulation(cfg, tmp_path, train_fn=nearest_view_train)
    assert rep["occupancy"] == "field" and "field" in rep["occupancy_note"]
    assert json.loads((tmp_path / "report.json").read_text())["occupancy"] == "field"
    fl = rep["field_loop"]
    assert fl["train_between"] == 30 and fl["field_iters"] == 30 * 5  # trained after cameras 2..6
    # the field's occupancy is used from camera 3 (60 iterations) on
    assert fl["occupancy_updates"] == 4 and fl["train_s_per_camera"] > 0 and fl["propose_s_per_camera"] > 0
    assert len(fl["occupied_fraction"]) == 6 and fl["occupied_fraction"][-1] != fl["occupied_fraction"][0]
    scene = make_scene("kitchen", 0)
    ours = Cameras.from_dict(rep["cameras"]["ours"]).centres
    assert len(ours) == 6 and not scene.occupied(ours).any()
    flo, fhi = scene.free_box
    assert np.all((ours[:3] >= flo) & (ours[:3] <= fhi))
    assert set(rep["table"]) == {"ours", "random"}


def test_occupancy_setting_is_checked():
    import pytest
    with pytest.raises(ValueError, match="occupancy"):
        SimulateConfig(occupancy="lidar")
