"""The command line: instant help, score and select on transforms.json, clear errors."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from curate.select.config import EnergyConfig
from curate.select.energy import compute_energy
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
    from curate.sfm.model import reconstruction_from_cameras
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




# ---------------------------------------------------------------------- errors a newcomer meets
def _err(capsys, *argv) -> str:
    from curate import cli
    assert cli.main(list(argv)) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err.strip()


def test_a_mistyped_flag_names_the_commands_help_and_the_nearest_flag(capsys):
    assert _err(capsys, "run", "photos", "--budjet", "10", "--out", "o") == (
        "curate run: error: unrecognized argument --budjet; did you mean --budget? (see curate run --help)")
    # reported before what follows from it (here: --out missing), for any command
    err = _err(capsys, "select", "x.json", "--methd", "path")
    assert err.startswith("curate select: error: unrecognized argument --methd; did you mean --method?")
    assert err.endswith("(see curate select --help)")
    err = _err(capsys, "run", "--itres", "3", "--budjet", "4", "--out", "o")
    assert "--itres (did you mean --iters" in err and "--budjet (did you mean --budget?)" in err
    assert _err(capsys, "report", "RUN", "--colour").endswith(
        "unrecognized argument --colour (see curate report --help)")
    assert "unexpected argument extra" in _err(capsys, "run", "photos", "extra", "--out", "o")
    # an abbreviation argparse accepts is not a typo; an ambiguous one is argparse's message
    assert "ambiguous option: --bud" in _err(capsys, "run", "--bud", "3", "--out", "o")
    err = _err(capsys, "run", "--method", "pth", "--out", "o")
    assert "invalid choice: 'pth'" in err and "did you mean path?" in err and "(see curate run --help)" in err


def test_a_mistyped_command_suggests_the_nearest_and_names_curates_help(capsys):
    assert _err(capsys, "rnu") == "curate: error: unknown command 'rnu'; did you mean run? (see curate --help)"
    assert _err(capsys, "slect", "x").startswith("curate: error: unknown command 'slect'; did you mean select?")
    err = _err(capsys, "frobnicate")
    assert "unknown command 'frobnicate'" in err and "run, sfm, select" in err
    assert "give a command" in _err(capsys)


@pytest.mark.parametrize("budget, msg", [("500", "budget 500 is more than all 30 cameras of {p}"),
                                         ("30", "budget 30 is all 30 cameras of {p}: nothing to choose"),
                                         ("100%", "budget 100% is all 30 cameras of {p}")])
def test_select_on_a_pose_file_speaks_of_its_cameras_not_of_a_hold_out(pool_json, tmp_path, capsys, budget, msg):
    path, _ = pool_json
    err = _err(capsys, "select", str(path), "--budget", budget, "--res", "8", "--out", str(tmp_path / "sel"))
    assert msg.format(p=path) in err and "hold-out" not in err
    assert not (tmp_path / "sel").exists()


def test_select_says_what_it_expected(tmp_path, capsys):
    missing = tmp_path / "runs" / "nonexistent"
    assert _err(capsys, "select", str(missing), "--budget", "4").endswith(
        f"{missing}: no such run folder or pose file")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("x")
    err = _err(capsys, "select", str(tmp_path / "mine"), "--budget", "4")
    assert "neither a run folder (no run.json) nor a pose file" in err and "--out" not in err


def _posed_run(tmp_path, stages_done: str):
    """A run folder of the sample walk's first 8 photos with run.json and, when asked, its SfM stage."""
    from pathlib import Path
    from curate.config import RunConfig
    from curate.core import runfolder
    from curate.pipeline import save_run_config
    from curate.core.transforms_json import read_transforms
    src = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    import shutil
    cams, files = read_transforms(src / "transforms.json")
    (tmp_path / "poses" / "images").mkdir(parents=True)
    for f in files[:8]:   # the photos beside their poses: a pose file names nothing outside its folder
        shutil.copyfile(f, tmp_path / "poses" / "images" / Path(f).name)
    tj = write_transforms(tmp_path / "poses" / "transforms.json", cams[list(range(8))],
                          [f"images/{Path(f).name}" for f in files[:8]])
    run = runfolder.claim(tmp_path / "my run")
    save_run_config(RunConfig(), run, None, tj)
    if stages_done == "sfm":
        from curate.sfm.pose_import import import_poses
        from curate.sfm.config import SfmConfig
        import_poses(SfmConfig(progress=False), tj, run)
    return run, tj


def test_a_stage_command_on_a_half_finished_run_names_the_curate_command_to_run(tmp_path, capsys):
    run, tj = _posed_run(tmp_path, "")
    for cmd in ("occupancy", "select", "evaluate", "export", "report"):
        err = _err(capsys, cmd, str(run))
        assert f"SfM has not finished there; run `curate sfm --poses {tj} --out '{run}'` first" in err, err
        assert f"`curate run --poses {tj} --out '{run}'` to finish the whole run" in err
        assert "run_sfm" not in err and "import_poses" not in err
    assert not (run / "occupancy").exists()


def test_the_next_missing_stage_is_named(tmp_path, capsys):
    run, _ = _posed_run(tmp_path, "sfm")
    assert f"the occupancy stage has not finished there; run `curate occupancy '{run}'` first" in _err(
        capsys, "select", str(run))
    # the library's reader speaks of curate's commands too
    from curate.sfm.io import load_sfm
    with pytest.raises(FileNotFoundError, match="run `curate sfm PHOTOS --out .*` or `curate run PHOTOS"):
        load_sfm(tmp_path / "elsewhere")


def test_export_says_linked_or_copied(tmp_path, capsys):
    from curate import cli
    run, tj = _posed_run(tmp_path, "")
    out = tmp_path / "run2"
    args = ["run", "--poses", str(tj), "--out", str(out), "--budget", "3", "--no-evaluate", "--res", "8",
            "--method", "stride"]   # no pool field to train
    assert cli.main(args) == 0, capsys.readouterr().err
    assert "export     3 images (hard-linked)" in capsys.readouterr().out
    assert cli.main(["export", str(out), "--mode", "copy"]) == 0
    line = capsys.readouterr().out
    assert "3 images (copied)" in line and "copys" not in line
    assert cli.main(["export", str(out), "--mode", "link"]) == 0
    assert "3 images (linked)" in capsys.readouterr().out


def test_select_on_a_folder_of_curate_sfm_says_what_to_run(tmp_path):
    """Issue 49: `curate select RUN` on a folder made by `curate sfm` said only "--out is required for a pose
    file"; it now says what the folder holds and the two commands that go on from it."""
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    run_dir = tmp_path / "r"
    run("sfm", "--poses", str(sample / "transforms.json"), str(sample / "images"), "--out", str(run_dir),
        "--triangulate", "off")
    p = run("select", str(run_dir), "--budget", "10", check=False)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1
    assert "cameras of `curate sfm`" in p.stderr and f"curate select {run_dir} --out DIR" in p.stderr
    assert f"curate run PHOTOS --out {run_dir}" in p.stderr
