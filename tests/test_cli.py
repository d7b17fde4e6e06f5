"""The command line: instant help, score and select on transforms.json, clear errors."""

import json
import subprocess
import sys

import numpy as np
import pytest

from curate.select.energy import EnergyConfig, compute_energy
from curate.core.grid import NodeGrid
from curate.core.transforms_json import write_transforms
from conftest import random_pool, shared_data


def run(*args, check=True):
    p = subprocess.run([sys.executable, "-m", "curate", *args], capture_output=True, text=True, timeout=300)
    if check and p.returncode != 0:
        raise AssertionError(p.stderr)
    return p


@pytest.fixture
def pool_json(tmp_path):
    cams = random_pool(30, seed=5)
    return write_transforms(tmp_path / "transforms.json", cams, [f"img_{i:03d}.png" for i in range(30)]), cams


def test_help_is_instant_and_imports_nothing_heavy():
    code = ("import sys, curate.cli as c; c.build_parser(None); "
            "print(sorted(m for m in ('torch', 'open3d', 'pycolmap', 'skimage') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    assert "score" in run("--help").stdout


@pytest.mark.slow
def test_score_json_matches_library(pool_json):
    path, cams = pool_json
    out = json.loads(run("score", str(path), "--box=-1,-1,-1,1,1,1", "--res", "8", "--gamma", "0.5",
                         "--bins", "4x6", "--json").stdout)
    ref = compute_energy(cams, NodeGrid([-1] * 3, [1] * 3, 8).nodes(), EnergyConfig(0.5, 4, 6))
    assert out["n_cameras"] == 30 and out["n_nodes"] == 512
    for k in ("energy", "angular", "frequency"):
        assert np.isclose(out[k], getattr(ref, k), rtol=1e-9)
    eq = json.loads(run("score", str(path), "--res", "8", "--equal-area", "--json").stdout)
    assert eq["binning"] == "equal-area" and len(eq["box"]) == 6  # box from the cameras
    human = run("score", str(path), "--res", "8").stdout
    assert "energy" in human and "angular" in human and "coverage" in human


@pytest.mark.slow
def test_select_writes_subset(pool_json, tmp_path):
    path, cams = pool_json
    out = tmp_path / "sel"
    res = json.loads(run("select", str(path), "--budget", "20%", "--res", "8", "--out", str(out), "--json").stdout)
    assert len(res["chosen"]) == 6
    sel = json.loads((out / "selection.json").read_text())
    assert sel["chosen"] == res["chosen"] and len(sel["energy"]) == 6
    names = (out / "selected.txt").read_text().split()
    assert names == [f"img_{k:03d}.png" for k in res["chosen"]]
    tj = json.loads((out / "transforms.json").read_text())
    assert len(tj["frames"]) == 6
    # image paths relative to the written transforms.json (not to the current directory)
    want = [str((path.parent / f"img_{k:03d}.png").resolve()) for k in res["chosen"]]
    assert [str((out / f["file_path"]).resolve()) for f in tj["frames"]] == want
    assert sel["pool"] == list(range(30)) and sel["holdout"] == [] and sel["budget"] == 6
    rnd = json.loads(run("select", str(path), "--budget", "6", "--method", "random", "--res", "8",
                         "--out", str(tmp_path / "r"), "--json").stdout)
    assert rnd["energy"] <= res["energy"] + 1e-9


@pytest.mark.slow
def test_select_budget_auto_on_a_pose_file(pool_json, tmp_path):
    path, cams = pool_json
    out = tmp_path / "auto"
    res = json.loads(run("select", str(path), "--budget", "auto", "--res", "8", "--out", str(out), "--json").stdout)
    sel = json.loads((out / "selection.json").read_text())
    auto = sel["budget_auto"]
    assert len(res["chosen"]) == auto["budget"] == sel["budget"] and 2 <= auto["budget"] < 30
    assert auto["predicted_loss_db"] <= 0.5 or "little to spare" in auto["note"]
    loose = json.loads(run("select", str(path), "--budget", "auto", "--budget-tolerance", "5", "--res", "8",
                           "--out", str(tmp_path / "loose"), "--json").stdout)
    assert len(loose["chosen"]) <= len(res["chosen"])


@pytest.mark.parametrize("args, msg", [
    (["score", "/nonexistent/transforms.json"], "no such file"),
    (["score", "{tmp}/bad.json"], "not valid JSON"),
    (["score", "{tmp}/noframes.json"], "frames"),
    (["score", "{tmp}/noframes.json", "--box", "1,2,3"], "six numbers"),
    (["score", "{tmp}/noframes.json", "--bins", "5by10"], "THETAxPHI"),
    (["select", "{tmp}/noframes.json", "--budget", "ten", "--out", "{tmp}/o"], "count"),
    (["select", "{tmp}/noframes.json", "--budget", "auto", "--budget-tolerance", "0", "--out", "{tmp}/o"],
     "tolerance"),
])
@pytest.mark.slow
def test_clear_errors(tmp_path, args, msg):
    (tmp_path / "bad.json").write_text("{not json")
    (tmp_path / "noframes.json").write_text(json.dumps({"frames": []}))
    p = run(*[a.format(tmp=tmp_path) for a in args], check=False)
    assert p.returncode == 2 and msg in p.stderr and "Traceback" not in p.stderr


@pytest.mark.slow
def test_score_fox_capture():
    path = shared_data("fox") / "transforms.json"
    out = json.loads(run("score", str(path), "--res", "16", "--json").stdout)
    assert out["n_cameras"] == 67 and 0 < out["energy"] <= 2 * 16 ** 3
    assert 0 < out["observed_fraction"] <= 1


def test_simulate_rejects_bad_size():
    p = run("simulate", "--size", "10", "--out", "/tmp/never", check=False)
    assert p.returncode == 2 and "WIDTHxHEIGHT" in p.stderr


@pytest.mark.slow
def test_score_accepts_a_colmap_model(tmp_path, pool_json):
    """The same cameras written as a COLMAP model (binary and text) score the same as the transforms.json."""
    from curate.sfm.colmap import reconstruction_from_cameras
    path, cams = pool_json
    rec = reconstruction_from_cameras(cams)
    (tmp_path / "bin").mkdir()
    rec.write(str(tmp_path / "bin"))
    (tmp_path / "txt").mkdir()
    rec.write_text(str(tmp_path / "txt"))
    ref = json.loads(run("score", str(path), "--box=-1,-1,-1,1,1,1", "--res", "8", "--json").stdout)
    for d in ("bin", "txt"):
        out = json.loads(run("score", str(tmp_path / d), "--box=-1,-1,-1,1,1,1", "--res", "8", "--json").stdout)
        assert out["n_cameras"] == 30 and np.isclose(out["energy"], ref["energy"], rtol=1e-9)


@pytest.mark.slow
def test_sfm_command_imports_poses_and_skips_unchanged(tmp_path):
    src = shared_data("fox") / "transforms.json"
    first = run("sfm", "--poses", str(src), "--out", str(tmp_path / "run"), "--triangulate", "off")  # points:
    assert "67 cameras registered" in first.stdout                                # test_pose_import.py
    stage = (tmp_path / "run" / "sfm" / "stage.json").read_text()
    run("sfm", "--poses", str(src), "--out", str(tmp_path / "run"), "--triangulate", "off")
    assert (tmp_path / "run" / "sfm" / "stage.json").read_text() == stage  # unchanged inputs: skipped
    out = json.loads(run("score", str(tmp_path / "run"), "--res", "8", "--json").stdout)
    assert out["n_cameras"] == 67
    p = run("sfm", "--out", str(tmp_path / "r2"), check=False)
    assert p.returncode == 2 and "photo folder" in p.stderr


