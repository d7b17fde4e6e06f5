"""`curate batch`: three folders (two posed pools cut from the sample pool, one of broken files)
with the local executor and with a local Ray instance; failure isolation, resume, helpers."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from curate.batch.runner import find_poses, plan, read_list

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "room_walk"
FAST = ["--iters", "10", "--eval-size", "48", "--random-seeds", "2", "--res", "16", "--budget", "8", "--folds", "2",
        "--refine-iters", "40", "--refine-size", "32"]


def make_pool(dst: Path, frames: range) -> Path:
    """A posed pool folder: links to some sample photos and their own transforms.json."""
    tj = json.loads((SAMPLE / "transforms.json").read_text())
    (dst / "images").mkdir(parents=True)
    keep = []
    for k in frames:
        fr = tj["frames"][k]
        src = SAMPLE / fr["file_path"]
        (dst / "images" / src.name).symlink_to(src)
        keep.append(fr)
    (dst / "transforms.json").write_text(json.dumps({**tj, "frames": keep}))
    return dst


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    base = tmp_path_factory.mktemp("pools")
    a = make_pool(base / "pool_a", range(0, 160, 4))  # 40 photos each
    b = make_pool(base / "pool_b", range(2, 160, 4))
    bad = base / "broken"
    bad.mkdir()
    for i in range(3):
        (bad / f"img_{i}.jpg").write_bytes(os.urandom(3000))
    (bad / "notes.png").write_text("not an image")
    return [a, b, bad]


def _batch(folders, out: Path, *extra: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "curate", "batch", *map(str, folders), "--out", str(out), *FAST,
                           *extra], env=env, capture_output=True, text=True, timeout=900)


def _check(out: Path, res: subprocess.CompletedProcess) -> dict:
    assert res.returncode == 1, res.stdout + res.stderr  # one folder failed
    summ = json.loads((out / "summary.json").read_text())
    rows = {r["name"]: r for r in summ["rows"]}
    assert list(rows) == ["pool_a", "pool_b", "broken"]
    assert summ["n_ok"] == 2 and summ["n_failed"] == 1
    bad = rows["broken"]
    assert bad["status"] == "failed" and bad["failed_stage"] == "sfm" and "usable photos" in bad["reason"]
    assert bad["photos"] == 4
    for name in ("pool_a", "pool_b"):
        r = rows[name]
        assert r["status"] == "ok" and r["reason"] == "" and r["poses"] == "transforms.json"
        assert r["photos"] == 40 and r["registered"] == 40 and r["chosen"] == 8 == len(r["chosen_names"])
        assert all(isinstance(r["psnr"][m], float) for m in ("selection", "random", "fvs", "all"))
        assert r["wall_seconds"] > 0 and r["report"] == f"{name}/report.html"
        assert (out / r["report"]).is_file() and (out / name / "export" / "transforms.json").is_file()
        log = (out / name / "run.log").read_text()
        assert "occupancy" in log and "select" in log and "evaluate" in log
    page = (out / "summary.html").read_text()
    assert 'href="pool_a/report.html"' in page and "failed" in page and "<script" not in page
    assert "broken: FAILED" in (out / "batch.log").read_text()
    return rows


def _same(r1: dict, r2: dict) -> None:
    for name in r1:
        assert r1[name]["status"] == r2[name]["status"]
        assert r1[name]["chosen_names"] == r2[name]["chosen_names"], name
        for m in ("selection", "random", "fvs", "all"):
            a, b = r1[name]["psnr"][m], r2[name]["psnr"][m]
            assert (a is None and b is None) or abs(a - b) < 1e-3, (name, m, a, b)


@pytest.fixture(scope="module")
def local_run(folders, tmp_path_factory):
    out = tmp_path_factory.mktemp("batch") / "runs_local"
    t0 = time.time()
    res = _batch(folders, out, "--executor", "local", "--jobs", "2")
    return out, res, time.time() - t0


@pytest.mark.slow
def test_batch_local_isolates_failure_and_resumes(folders, local_run):
    out, res, _ = local_run
    rows = _check(out, res)
    stamp = (out / "pool_a" / "report.json").stat().st_mtime_ns
    t0 = time.time()
    again = _batch(folders, out, "--executor", "local", "--jobs", "2")
    rows2 = _check(out, again)
    _same(rows, rows2)
    assert rows2["pool_a"]["resumed"] and rows2["pool_b"]["resumed"] and not rows2["broken"]["resumed"]
    assert (out / "pool_a" / "report.json").stat().st_mtime_ns == stamp  # finished folders were not touched
    assert time.time() - t0 < 60


@pytest.mark.slow
def test_batch_ray_agrees_with_local(folders, local_run, tmp_path):
    pytest.importorskip("ray", reason="ray is not installed (pip install -e '.[ray]'; scripts/setup.sh does)")
    out_l, res_l, _ = local_run
    rows_l = _check(out_l, res_l)
    out = tmp_path / "runs_ray"
    res = _batch(folders, out, "--executor", "ray")
    rows = _check(out, res)
    _same(rows_l, rows)
    # the trainings ran as Ray tasks, in parallel: every unit of every fold has its record
    for name in ("pool_a", "pool_b"):
        summ = json.loads((out / name / "evaluate" / "summary.json").read_text())
        want = sorted(u for f in summ["protocol"]["folds"] for u in f["units"])
        units = sorted(p.parent.name for p in (out / name / "evaluate").glob("*/stage.json"))
        assert units == want and len(summ["protocol"]["folds"]) == 2 and "f00_random_s1" in units


@pytest.mark.slow
def test_ray_missing_is_a_clear_error(tmp_path, folders):
    code = ("import sys; sys.modules['ray'] = None; from curate.cli import main; "
            f"sys.exit(main(['batch', {str(folders[0])!r}, '--out', {str(tmp_path / 'r')!r}, '--budget', '5', "
            "'--executor', 'ray']))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert res.returncode == 2 and "needs the ray package" in res.stderr, res.stderr


def test_plan_names_poses_and_list(tmp_path):
    for sub in ("x/scene", "y/scene", "colmap_cap/sparse/0", "colmap_cap/images", "plain"):
        (tmp_path / sub).mkdir(parents=True)
    (tmp_path / "x" / "scene" / "transforms.json").write_text("{}")
    (tmp_path / "colmap_cap" / "sparse" / "0" / "cameras.txt").write_text("# a COLMAP model\n")
    lst = tmp_path / "list.txt"
    lst.write_text("# captures\nx/scene\ny/scene\n\ncolmap_cap\nplain\nplain  # twice\n")
    folders = read_list(lst)
    assert len(folders) == 5
    items = plan(folders, tmp_path / "runs")
    names = [it.name for it in items]
    assert len(items) == 4 and len(set(names)) == 4  # duplicates dropped, clashing names made unique
    assert names == ["x-scene", "y-scene", "colmap_cap", "plain"]   # clashing names: with their parent's
    assert [it.source for it in items] == ["transforms.json", "sfm", "colmap", "sfm"]
    assert find_poses(tmp_path / "colmap_cap") == (str(tmp_path / "colmap_cap" / "images"),
                                                   str(tmp_path / "colmap_cap" / "sparse" / "0"), "colmap")
    assert all(Path(it.run_dir).parent == (tmp_path / "runs").resolve() for it in items)


def test_batch_names_folders_as_a_person_recognises_them(tmp_path):
    """Issue 50: two folders named `images` became `images-37daac` and `images-419dd3`."""
    for sub in ("kitchen/images", "garden/images", "a/photos/images", "b/photos/images", "walk.mp4"):
        (tmp_path / sub).parent.mkdir(parents=True, exist_ok=True)
        if sub.endswith(".mp4"):
            (tmp_path / sub).write_bytes(b"")
        else:
            (tmp_path / sub).mkdir()
    items = plan([tmp_path / s for s in ("kitchen/images", "garden/images", "a/photos/images", "b/photos/images",
                                         "walk.mp4")], tmp_path / "runs")
    names = [it.name for it in items]
    assert names[:2] == ["kitchen", "garden"] and names[4] == "walk"
    assert names[2].startswith("photos-") and names[3].startswith("photos-") and names[2] != names[3]


@pytest.mark.slow
def test_batch_budget_auto_chooses_per_folder(folders, tmp_path):
    """`curate batch --budget auto --budget-tolerance 1`: every folder chooses its own count from
    its own pool (recorded in its selection and in the summary row), the failed folder stays a row."""
    out = tmp_path / "runs_auto"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    res = subprocess.run([sys.executable, "-m", "curate", "batch", *map(str, folders), "--out", str(out),
                          "--budget", "auto", "--budget-tolerance", "1", "--no-evaluate", "--res", "16",
                          "--iters", "10", "--executor", "local", "--jobs", "1"],
                         env=env, capture_output=True, text=True, timeout=900)
    assert res.returncode == 1, res.stdout + res.stderr      # the broken folder fails, the others go on
    rows = {r["name"]: r for r in json.loads((out / "summary.json").read_text())["rows"]}
    assert rows["broken"]["status"] == "failed"
    for name in ("pool_a", "pool_b"):
        sel = json.loads((out / name / "select" / "selection.json").read_text())
        auto = sel["budget_auto"]
        assert sel["budget_text"] == "auto" and auto["tolerance_db"] == 1.0
        assert auto["pool"] == len(sel["pool"]) > 30             # its own pool (40 less the held-out views)
        assert 2 <= auto["budget"] < auto["pool"] and rows[name]["chosen"] == auto["budget"] == len(sel["chosen"])


def test_a_summary_without_evaluation_shows_no_psnr_columns(tmp_path):
    """Issue 50: with --no-evaluate the summary kept five empty PSNR columns."""
    from curate.batch.summary import write_summary_html
    row = {"name": "kitchen", "folder": "/x/kitchen/images", "poses": "sfm", "status": "ok", "photos": 40,
           "registered": 40, "chosen": 8, "psnr": {"selection": None, "random": None, "fvs": None, "all": None},
           "selection_minus_random": None, "wall_seconds": 12.0, "report": "kitchen/report.html", "reason": ""}
    summ = {"rows": [row], "n_folders": 1, "n_ok": 1, "n_failed": 0, "executor": "local", "wall_seconds": 12.0,
            "config": {"budget": "8"}}
    page = write_summary_html(tmp_path, summ).read_text()
    assert "PSNR" not in page and "Not evaluated" in page and 'href="kitchen/report.html"' in page
    row["psnr"] = {"selection": 24.1, "random": 23.0, "fvs": 23.5, "all": 25.0}
    page = write_summary_html(tmp_path, summ).read_text()
    assert "PSNR selection" in page and "24.10" in page


def test_the_progress_line_names_each_running_folders_stage(tmp_path):
    """Issue 50: for ten minutes the only progress was 'folders 0/2'."""
    from curate.batch.runner import stage_in_progress
    from curate.config import RunConfig
    quick, evaluated = RunConfig(run_evaluation=False), RunConfig()
    run = tmp_path / "kitchen"
    assert stage_in_progress(run, quick) == "starting"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({"config": {"run_evaluation": False}}))
    assert stage_in_progress(run, quick) == "sfm"
    for st, nxt in (("sfm", "occupancy"), ("occupancy", "select"), ("select", "export"), ("export", "report")):
        (run / st).mkdir()
        (run / st / "stage.json").write_text("{}")
        assert stage_in_progress(run, quick) == nxt
    assert stage_in_progress(run, evaluated) == "evaluate"


def test_the_progress_line_ticks_while_ray_tasks_block_their_threads():
    """Issue 50: with --executor ray the folders' threads block on their tasks, so the progress line's
    stages are refreshed by a ticker of their own (as the local executor's wait does), and stop with it."""
    import time as _t
    from curate.batch.runner import ticking
    got = []
    with ticking(lambda kind, it, row: got.append(kind), period=0.02):
        _t.sleep(0.2)
    n = len(got)
    assert n >= 3 and set(got) == {"tick"}
    _t.sleep(0.1)
    assert len(got) == n                       # none after the block
