"""Method "auto": the kind of capture decides between the walk rule and the paper's energy;
equal evaluation units train once."""

import json

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.core.grid import NodeGrid
from curate.select.config import SelectConfig
from curate.select.methods import capture_kind
from curate.select.select import select
from conftest import random_pool, shared_data


def orbit(n, seed=0, radius=3.0, noise_deg=3.0, target=(0.2, -0.1, 0.3), scale=1.0):
    """Cameras on a sphere around ``target`` looking at it (with a little aiming noise)."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2])
    c = np.asarray(target) + radius * d / np.linalg.norm(d, axis=1, keepdims=True)
    aim = np.asarray(target) + rng.normal(scale=radius * np.radians(noise_deg), size=(n, 3))
    cams = Cameras(look_at(c, aim), 300.0, 300.0, 160.0, 120.0, 320, 240)
    return cams.transformed(scale)


@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e4])
def test_capture_kind_object_and_walk(scale):
    kind, ang = capture_kind(orbit(40, scale=scale))
    assert kind == "object" and ang < 10
    kind, ang = capture_kind(random_pool(60, seed=2, scale=scale))     # a walk: looking everywhere
    assert kind == "walk" and ang > 30


def test_capture_kind_degenerate():
    c = np.zeros((5, 3)) + [1.0, 2.0, 3.0]
    par = Cameras(look_at(np.random.default_rng(0).normal(size=(8, 3)), np.random.default_rng(0).normal(
        size=(8, 3)) + [0, 0, 100.0]), 300.0, 300.0, 160.0, 120.0, 320, 240)
    same = Cameras(look_at(c, c + np.random.default_rng(1).normal(size=(5, 3))), 300.0, 300.0, 160.0, 120.0, 320, 240)
    for cams in (par, same, orbit(2), Cameras.empty()):
        kind, ang = capture_kind(cams)
        assert kind in ("object", "walk") and np.isfinite(ang)
    assert capture_kind(orbit(2))[0] == "walk"                 # too few cameras to tell
    # forward-facing: all axes (near) parallel, they meet nowhere near the scene
    assert capture_kind(par)[0] == "walk"


def test_auto_runs_the_energy_on_an_object_and_view_medoids_on_walk_photos_in_no_order():
    grid = NodeGrid([-1, -1, -1], [1, 1, 1], 8)
    obj = orbit(40)
    a = select(obj, grid, 8, SelectConfig("auto"))
    assert a.method == "energy" and "object" in a.note
    e = select(obj, grid, 8, SelectConfig("energy"))
    assert a.chosen == e.chosen and a.energy == e.energy
    walk = random_pool(60, seed=2)
    b = select(walk, grid, 8, SelectConfig("auto"))
    assert b.method == "medoids" and "walk" in b.note and b.to_dict()["note"] == b.note
    assert "-> path" in b.note and "not in capture order" in b.note      # the walk rule, and why it fell back
    assert b.chosen == select(walk, grid, 8, SelectConfig("medoids")).chosen
    assert SelectConfig().method == "auto"


def test_auto_spaces_a_large_object_capture_as_a_walk_and_its_folds_do_the_same():
    """Past OBJECT_METHOD_MAX_PHOTOS photos an object capture is chosen as a walk is (the paper's energy was
    below random on both ~300-photo objects measured), the note says why, and a fold of the evaluation, whose
    pool is a fourteenth smaller, runs the method the exported selection ran, not the energy."""
    from curate.evaluate.config import EvalConfig
    from curate.evaluate.folds import plan_fold
    from curate.select.methods import OBJECT_METHOD_MAX_PHOTOS
    grid = NodeGrid([-1, -1, -1], [1, 1, 1], 8)
    small = select(orbit(OBJECT_METHOD_MAX_PHOTOS), grid, 10, SelectConfig("auto"))
    assert small.method == "energy"
    big = orbit(OBJECT_METHOD_MAX_PHOTOS + 5)
    a = select(big, grid, 10, SelectConfig("auto"))
    assert a.method in ("path", "medoids") and "object" in a.note and f"more than {OBJECT_METHOD_MAX_PHOTOS}" in a.note
    assert a.chosen == select(big, grid, 10, SelectConfig(a.method)).chosen
    fold = plan_fold(EvalConfig(), SelectConfig("auto"), big, grid, 10, 0, ordered=False)
    assert len(fold.pool) <= OBJECT_METHOD_MAX_PHOTOS and fold.method == a.method


@pytest.mark.parametrize("scene,kind", [("office", "walk"), ("fox", "object"), ("templering", "object")])
def test_capture_kind_on_real_sets(scene, kind):
    from research.datasets import load_ground_truth
    d = shared_data(scene)
    assert capture_kind(load_ground_truth(d))[0] == kind


def test_equal_units_train_once(tmp_path, monkeypatch):
    """The selection and FVS with the same subset: one training, the other unit a copy under its own name."""
    import curate.evaluate.units as ev
    calls = []

    def fake_entry(args):
        u, key = args[1], args[7]
        calls.append(u.key)
        d = tmp_path / "evaluate" / u.key
        d.mkdir(parents=True)
        m = {"method": u.method, "seed": u.seed, "psnr": 20.0 + len(u.subset), "ssim": 0.5, "per_view": [],
             "n_train": len(u.subset)}
        (d / "metrics.json").write_text(json.dumps(m))
        (d / "stage.json").write_text(json.dumps({"key": key}))
        return m

    monkeypatch.setattr(ev, "_unit_entry", fake_entry)
    monkeypatch.setattr(ev, "save_ground_truth", lambda *a: None)
    units = [ev.Unit("energy", "energy", None, [1, 2, 3]), ev.Unit("fvs", "fvs", None, [1, 2, 3]),
             ev.Unit("random_s0", "random", 0, [4, 5, 6])]
    keys = {"energy": "k1", "fvs": "k1", "random_s0": "k2"}
    cams = random_pool(8)
    res = ev.run_units(tmp_path, units, keys, ev.EvalConfig(workers=1), cams, [""] * 8, [0], None, progress=False)
    assert sorted(calls) == ["energy", "random_s0"]
    assert res["fvs"]["method"] == "fvs" and res["fvs"]["psnr"] == res["energy"]["psnr"]
    assert json.loads((tmp_path / "evaluate" / "fvs" / "stage.json").read_text())["key"] == "k1"
    # a re-run: everything fresh, nothing trained; a new unit equal to a fresh one copies it
    calls.clear()
    units.append(ev.Unit("energy2", "energy", None, [1, 2, 3]))
    keys["energy2"] = "k1"
    res = ev.run_units(tmp_path, units, keys, ev.EvalConfig(workers=1), cams, [""] * 8, [0], None, progress=False)
    assert calls == [] and res["energy2"]["copied_from"] == "energy"


def test_the_default_budget_follows_the_kind_of_capture(tmp_path):
    """``--budget default`` (the default of ``curate run``) keeps 15% of a walk-through and what ``auto``
    advises on an object capture, which needs most of its photos (15% kept 10 of 65 skull photos); the
    selection record says what the default meant."""
    import subprocess
    import sys
    from curate.config import RunConfig
    from curate.core.budget import DEFAULT, by_kind, parse_budget
    from curate.core.transforms_json import write_transforms
    from curate.core.budget import budget_of_pool
    assert RunConfig().budget == DEFAULT and parse_budget("Default") == DEFAULT
    assert by_kind("default", "walk") == "15%" and by_kind("default", "object") == "auto"
    assert by_kind("40", "object") == "40" and by_kind("15%", "object") == "15%"   # a budget given stays
    obj, walk = orbit(60), random_pool(60, seed=2)
    assert budget_of_pool("default", obj) == ("auto", "default: auto (an object capture)")
    assert budget_of_pool("default", walk) == ("15%", "default: 15% (a walk-through)")
    assert budget_of_pool("12", obj) == ("12", "12")
    got = {}
    for name, cams in (("object", obj), ("walk", walk)):
        path = write_transforms(tmp_path / name / "transforms.json", cams, [f"img_{i:03d}.png" for i in range(60)])
        out = tmp_path / f"{name}_out"
        subprocess.run([sys.executable, "-m", "curate", "select", str(path), "--budget", "default", "--res", "8",
                        "--out", str(out), "--json"], check=True, capture_output=True, text=True, timeout=300)
        got[name] = json.loads((out / "selection.json").read_text())
    assert got["walk"]["budget"] == 9 and got["walk"]["budget_text"] == "default: 15% (a walk-through)"
    assert got["object"]["budget_text"] == "default: auto (an object capture)"
    assert got["object"]["budget"] == got["object"]["budget_auto"]["budget"] > 9     # more than 15% of the orbit
