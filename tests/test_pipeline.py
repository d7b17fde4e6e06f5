"""`curate run` end to end on the project's sample pool, kill-and-resume, and the pipeline's helpers."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from curate.occupancy.stage import surface_band
from curate.pipeline import RunConfig
from curate.core.stage import config_dict, config_from_dict

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "room_walk"
FAST = ["--iters", "50", "--eval-size", "48", "--random-seeds", "2", "--workers", "1", "--res", "16",
        "--budget", "12", "--triangulate", "off", "--folds", "2", "--refine-iters", "60", "--refine-size", "48"]


def _cmd(out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "curate", "run", str(SAMPLE / "images"), "--poses", str(SAMPLE / "transforms.json"),
            "--out", str(out), *FAST, *extra]


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}


def _mtimes(run: Path) -> dict:
    return {str(p.relative_to(run)): p.stat().st_mtime_ns for p in run.rglob("stage.json")}


@pytest.mark.slow
def test_run_killed_during_training_resumes_without_redoing_finished_stages(tmp_path):
    """Kill `curate run` while a subset trains; the re-run keeps every finished stage and completes the report."""
    run = tmp_path / "run"
    photos_before = sorted((p.name, p.stat().st_size) for p in (SAMPLE / "images").iterdir())
    proc = subprocess.Popen(_cmd(run), env=_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True)
    t0 = time.time()
    # wait until the selection's unit has finished and the next training has started
    while not ((run / "evaluate" / "f00_selection" / "stage.json").is_file()
               and (run / "evaluate" / "f00_random_s0").is_dir()):
        assert proc.poll() is None, proc.stdout.read().decode()
        assert time.time() - t0 < 600, "the run never reached the evaluation"
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (run / "report.json").exists()
    assert not (run / "evaluate" / "f00_random_s0" / "stage.json").exists()
    before = _mtimes(run)
    assert {"sfm/stage.json", "occupancy/stage.json", "select/stage.json",
            "evaluate/f00_selection/stage.json"} <= set(before)

    res = subprocess.run(_cmd(run), env=_env(), capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stdout + res.stderr
    after = _mtimes(run)
    for k, v in before.items():  # nothing finished was redone
        assert after[k] == v, k
    for line in ("occupancy  skipped", "select     skipped"):
        assert line in res.stdout
    rep = json.loads((run / "report.json").read_text())
    assert set(rep["methods"]) == {"selection", "random", "fvs", "stride", "all"}
    assert rep["methods"]["random"]["units"] == 2 * 2          # two draws in each of the two folds
    n_hold0 = len(range(0, 160, 14))                                # fold 0 holds out every 14th from 0,
    n_hold = n_hold0 + len(range(7, 160, 14))                       # fold 1 every 14th from 7
    for name, m in rep["methods"].items():
        both = name != "all"                                        # all photos: the first fold only
        assert len(m["per_view"]) == (n_hold if both else n_hold0)  # every held-out view of its folds
        assert all(np.isfinite(v["psnr"]) for v in m["per_view"])
        assert {v["fold"] for v in m["per_view"]} == ({0, 7} if both else {0})
    assert rep["estimate"]["n_holdout"] == n_hold and rep["estimate"]["n_pool"] == 160 - n_hold0
    assert len(rep["selection"]["chosen"]) == 12 and rep["n_candidates"] == 160   # chosen among every photo
    assert rep["estimate"]["budget"] == round(12 * (160 - n_hold0) / 160)
    assert {"lo", "hi", "mean"} <= set(rep["paired"]["selection-random"])
    assert (run / "report.html").is_file()
    # export: the chosen photos, hard links to the originals (the export travels alone)
    names = (run / "export" / "images.txt").read_text().split()
    assert [Path(n).name for n in names] == [Path(n).name for n in rep["selection"]["chosen_names"]]
    links = sorted((run / "export" / "images").iterdir())
    assert len(links) == 12
    for f in links:
        assert not f.is_symlink() and f.read_bytes() == (SAMPLE / "images" / f.name).read_bytes()
    # the user's photos are untouched
    assert sorted((p.name, p.stat().st_size) for p in (SAMPLE / "images").iterdir()) == photos_before

    # a third run with nothing changed redoes nothing; --force on one stage redoes it and what follows
    res = subprocess.run(_cmd(run), env=_env(), capture_output=True, text=True, timeout=600)
    assert res.returncode == 0 and _mtimes(run) == after
    res = subprocess.run([sys.executable, "-m", "curate", "select", str(run), "--budget", "8", "--method", "fvs"],
                         env=_env(), capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    sel = json.loads((run / "select" / "selection.json").read_text())
    assert sel["method"] == "fvs" and len(sel["chosen"]) == 8


def test_run_config_round_trip_and_unknown_option():
    cfg = RunConfig(budget="60")
    assert config_from_dict(RunConfig, config_dict(cfg)) == cfg
    d = config_dict(cfg)
    d["evaluate"]["no_such_option"] = 1
    with pytest.raises(ValueError, match="no_such_option"):
        config_from_dict(RunConfig, d)


def test_surface_band():
    m = np.zeros((9, 9, 9), bool)
    m[2:7, 2:7, 2:7] = True  # a solid cube: its interior is not surface
    band0 = surface_band(m, 0)
    assert band0[2, 4, 4] and not band0[4, 4, 4] and not band0[1, 4, 4]
    band1 = surface_band(m, 1)
    assert band1[1, 4, 4] and band1[3, 4, 4] and not band1[4, 4, 4]
    thin = np.zeros((5, 5, 5), bool)
    thin[2] = True  # a wall one voxel thick is all surface
    assert np.array_equal(surface_band(thin, 0), thin)
    assert not surface_band(np.zeros((4, 4, 4), bool), 1).any()
    full = np.ones((6, 6, 6), bool)   # nothing known: no surface inside, the box's walls when outside is free
    assert not surface_band(full, 0).any()
    walls = surface_band(full, 0, outside_free=True)
    assert walls[0].all() and walls[:, -1].all() and not walls[1:-1, 1:-1, 1:-1].any()


def _metrics(method, seed, psnrs, names):
    return {"method": method, "seed": seed, "n_train": 5, "psnr": float(np.mean(psnrs)), "ssim": 0.5,
            "per_view": [{"name": n, "psnr": p, "ssim": 0.5} for n, p in zip(names, psnrs)],
            "train_seconds": 1.0, "iters": 10}


def test_summarize_pools_the_folds_averages_random_draws_per_view_and_closes_the_gap():
    from curate.evaluate.folds import Fold, summarize
    from curate.evaluate.units import Unit
    folds, res = [], {}
    for o, hold in ((0, [0, 2, 4]), (1, [1, 3, 5])):
        names = [f"v{i}" for i in hold]
        units = [Unit(f"f{o:02d}_{m}", m.split("_")[0], None, [9]) for m in
                 ("selection", "random_s0", "random_s1", "fvs", "all")]
        folds.append(Fold(o, hold, [6, 7, 8, 9], 1, "path", [9], units))
        res.update({f"f{o:02d}_selection": _metrics("selection", None, [20, 22, 24], names),
                    f"f{o:02d}_random_s0": _metrics("random", 0, [19, 20, 21], names),
                    f"f{o:02d}_random_s1": _metrics("random", 1, [17, 20, 23], names),
                    f"f{o:02d}_fvs": _metrics("fvs", None, [20, 21, 22 + o], names),
                    f"f{o:02d}_all": _metrics("all", None, [24, 25, 26], names)})
    methods, paired, gap = summarize(res, folds, 0.95, 0.3)
    assert methods["random"]["psnr"] == pytest.approx(20.0) and methods["random"]["units"] == 4
    assert [v["psnr"] for v in methods["random"]["per_view"]] == [18, 18, 20, 20, 22, 22]   # in camera order
    assert [v["fold"] for v in methods["selection"]["per_view"]] == [0, 1, 0, 1, 0, 1]
    assert paired["selection-random"]["mean"] == pytest.approx(2.0) and paired["selection-random"]["n_folds"] == 2
    assert paired["selection-fvs"]["mean"] == pytest.approx(1.0 - 1 / 6) and paired["selection-fvs"]["n"] == 6
    assert paired["selection-random"]["decision"] in ("ahead", "undecided")
    assert "selection-stride" not in paired                     # no stride units: no comparison
    assert gap == pytest.approx((22 - 20) / (25 - 20))
    for o in (0, 1):
        res[f"f{o:02d}_all"] = _metrics("all", None, [19, 20, 21], [f"v{i}" for i in folds[o].holdout])
    assert summarize(res, folds, 0.95, 0.3)[2] is None          # no room above random: no gap figure


@pytest.mark.slow
def test_run_refuses_a_run_folder_inside_the_photos(tmp_path):
    res = subprocess.run([sys.executable, "-m", "curate", "run", str(SAMPLE / "images"), "--poses",
                          str(SAMPLE / "transforms.json"), "--out", str(SAMPLE / "images" / "run"), "--budget", "5"],
                         env=_env(), capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "inside the photo folder" in res.stderr
    assert not (SAMPLE / "images" / "run").exists()


def test_original_cameras_of_an_import_point_to_the_photos(tmp_path):
    from curate.sfm.pose_import import import_poses
    from curate.sfm.config import SfmConfig
    from curate.sfm.io import load_sfm, original_cameras
    from curate.sfm.io import image_paths
    import_poses(SfmConfig(progress=False, triangulate="off"), SAMPLE / "transforms.json", tmp_path, photos=SAMPLE)
    res = load_sfm(tmp_path)
    oc, paths = original_cameras(res.cameras, res.records)
    assert all(Path(p).is_absolute() and Path(p).is_file() for p in paths)
    assert np.array_equal(oc.fx, res.cameras.fx) and np.array_equal(oc.width, res.cameras.width)
    assert image_paths(tmp_path, list(res.cameras.names), res.records) == paths


@pytest.mark.slow
def test_stage_reruns_keep_the_saved_options_and_only_the_changed_stage_runs(tmp_path):
    """A changed selection option redoes the select stage only; `curate select RUN --budget N` keeps the
    run's saved options (here --gamma and --method) and saves the new budget; `--box` reaches the
    occupancy grid; `curate select RUN --res` is refused (the grid belongs to the occupancy stage)."""
    out = tmp_path / "run"
    base = _cmd(out, "--no-evaluate", "--method", "energy", "--gamma", "0.2")
    subprocess.run(base, check=True, capture_output=True, env=_env(), timeout=600)
    before = _mtimes(out)
    subprocess.run(base + ["--method", "fvs"], check=True, capture_output=True, env=_env(), timeout=600)
    after = _mtimes(out)
    assert after["sfm/stage.json"] == before["sfm/stage.json"]
    assert after["occupancy/stage.json"] == before["occupancy/stage.json"]
    assert after["select/stage.json"] != before["select/stage.json"]
    assert json.loads((out / "select" / "selection.json").read_text())["method"] == "fvs"

    res = subprocess.run([sys.executable, "-m", "curate", "select", str(out), "--budget", "20"], env=_env(),
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    sel = json.loads((out / "select" / "selection.json").read_text())
    rec = json.loads((out / "select" / "stage.json").read_text())["config"]
    assert len(sel["chosen"]) == 20 and sel["method"] == "fvs"
    assert rec["select"]["energy"]["gamma"] == 0.2 and rec["budget"] == "20"
    assert json.loads((out / "run.json").read_text())["config"]["budget"] == "20"

    res = subprocess.run([sys.executable, "-m", "curate", "select", str(out), "--res", "8"], env=_env(),
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 2 and "curate occupancy" in res.stderr

    res = subprocess.run([sys.executable, "-m", "curate", "occupancy", str(out), "--box=1,1,0.2,5,4,2.5"], env=_env(),
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    z = np.load(out / "occupancy" / "occupancy.npz")
    assert np.allclose(z["box_min"], [1, 1, 0.2]) and np.allclose(z["box_max"], [5, 4, 2.5])
    assert not (out / "occupancy" / "split.json").exists()          # the hold-out belongs to the evaluation
    assert "select" in res.stdout and "export" in res.stdout      # the cheap stages after it were redone
    assert json.loads((out / "select" / "stage.json").read_text())["inputs"]["occupancy"] == \
        json.loads((out / "occupancy" / "stage.json").read_text())["key"]


@pytest.mark.slow
def test_no_evaluate_trains_no_field_unless_the_method_needs_one(tmp_path):
    """`--no-evaluate` with view medoids (or FVS) trains no pool field: the selection needs none. The
    energy on a pose import without points (--triangulate off: no sparse points to give its occupancy)
    still gets one."""
    out = tmp_path / "run"
    res = subprocess.run(_cmd(out, "--no-evaluate", "--method", "medoids"), capture_output=True, text=True,
                         env=_env(), timeout=600)
    assert res.returncode == 0, res.stderr
    rec = json.loads((out / "occupancy" / "stage.json").read_text())
    assert not (out / "occupancy" / "field.pt").exists() and rec["train"] is None
    assert "not needed" in rec["field"] and "field trained" not in res.stdout
    assert len(json.loads((out / "select" / "selection.json").read_text())["chosen"]) == 12
    assert (out / "export" / "transforms.json").is_file() and (out / "report.html").is_file()
    res = subprocess.run(_cmd(out, "--no-evaluate", "--method", "energy", "--triangulate", "off"), capture_output=True,
                         text=True, env=_env(), timeout=600)
    assert res.returncode == 0, res.stderr
    assert (out / "occupancy" / "field.pt").is_file()
    assert "energy" in json.loads((out / "occupancy" / "stage.json").read_text())["field"]


def test_part_budget_shares_a_count_and_keeps_a_percentage():
    from curate.pipeline import part_budget
    assert part_budget("60", 300, 400) == "45" and part_budget("60", 100, 400) == "15"
    assert part_budget("4", 10, 400) == "2"          # never fewer than 2
    assert part_budget("15%", 10, 400) == "15%"      # a percentage is of each part's own pool
    assert part_budget("auto", 10, 400) == "auto"    # so is auto


@pytest.mark.parametrize("budget", ["16", "auto"])
def test_on_split_each_curates_every_part_in_its_own_run_folder(tmp_path, monkeypatch, budget):
    """A capture that split in two (faked: the sample walk's first and second halves as two COLMAP
    models): `--on-split each` curates the largest in RUN and the other in RUN/parts/1, a count
    shared by size, `auto` chosen by each part from its own pool; the report lists the part and
    links its report; the user's photos are untouched."""
    import hashlib
    import shutil

    pytest.importorskip("pycolmap")
    from curate import pipeline
    from curate.core.stage import read_stage, write_json_atomic
    from curate.core.transforms_json import read_transforms
    from curate.sfm import stage as sfm_stage
    from curate.sfm.model import reconstruction_from_cameras

    def sha():
        return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted((SAMPLE / "images").iterdir())}

    before = sha()
    cams, files = read_transforms(SAMPLE / "transforms.json")
    real = sfm_stage.reconstruct

    def fake_sfm(ctx):
        if ctx.poses != "SPLIT":
            return real(ctx)
        from dataclasses import replace
        from curate.core.cameras import Cameras
        halves = (np.arange(0, 100), np.arange(100, len(cams)))
        models = tmp_path / "models"
        for k, idx in enumerate(halves):
            sub = cams[idx]
            sub = Cameras(sub.c2w, sub.fx, sub.fy, sub.cx, sub.cy, sub.width, sub.height,
                          names=tuple(Path(files[i]).name for i in idx))
            (models / str(k)).mkdir(parents=True)
            reconstruction_from_cameras(sub).write(models / str(k))
        res = real(replace(ctx, photos=SAMPLE / "images", poses=models / "0"))
        d = ctx.run_dir / "sfm"
        (d / "images").mkdir(exist_ok=True)
        for i in halves[1]:
            shutil.copy(files[i], d / "images" / Path(files[i]).name)
        shutil.copytree(models / "1", d / "sparse" / "1")
        rec = read_stage(d)
        rec["stats"].update({"model_sizes": [100, len(cams) - 100], "n_kept": len(cams), "n_registered": 100,
                             "unregistered": [Path(files[i]).name for i in halves[1]],
                             "parts": [{"model": "sparse/0", "n_registered": 100},
                                       {"model": "sparse/1", "n_registered": len(cams) - 100}]})
        write_json_atomic(d / "stage.json", rec)
        return res

    monkeypatch.setattr(sfm_stage, "reconstruct", fake_sfm)
    from curate.config import RunConfig
    from curate.select.config import SelectConfig
    from curate.sfm.config import SfmConfig
    cfg = RunConfig(budget=budget, run_evaluation=False,
                    sfm=SfmConfig(on_split="each", progress=False, triangulate="off"),
                    select=SelectConfig(method="medoids"))
    out = tmp_path / "run"
    pipeline.run(cfg, None, out, poses="SPLIT")
    n1 = len(cams) - 100
    main_sel = json.loads((out / "select" / "selection.json").read_text())
    part_sel = json.loads((out / "parts" / "1" / "select" / "selection.json").read_text())
    if budget == "16":
        assert (len(main_sel["chosen"]) == round(16 * 100 / len(cams))
                and len(part_sel["chosen"]) == round(16 * n1 / len(cams)))
    else:
        for sel, n_part in ((main_sel, 100), (part_sel, n1)):     # each from its own part, not the capture
            auto = sel["budget_auto"]
            assert sel["budget_text"] == "auto" and auto["pool"] == len(sel["pool"])
            assert auto["pool"] == n_part and 2 <= auto["budget"] == len(sel["chosen"]) < auto["pool"]   # every photo
    assert (out / "parts" / "1" / "export" / "transforms.json").is_file()
    rep = json.loads((out / "report.json").read_text())
    assert [p["part"] for p in rep["parts"]] == ["1"] and rep["parts"][0]["n_registered"] == n1
    html = (out / "report.html").read_text()
    assert 'href="parts/1/report.html"' in html and "--on-split each" in html
    assert (out / "parts" / "1" / "report.html").is_file()
    assert sha() == before


@pytest.mark.slow
def test_budget_auto_chooses_from_the_pool_and_says_why(tmp_path):
    """`--budget auto` on the sample walk: the select stage chooses the count from the pool (2 to
    pool - 1), records the predicted curve and why, the report draws it; a tighter
    `--budget-tolerance` reruns only the selection and never chooses fewer photos."""
    out = tmp_path / "run"
    res = subprocess.run(_cmd(out, "--no-evaluate", "--budget", "auto"), capture_output=True, text=True,
                         env=_env(), timeout=600)
    assert res.returncode == 0, res.stderr
    sel = json.loads((out / "select" / "selection.json").read_text())
    auto = sel["budget_auto"]
    assert sel["budget_text"] == "auto" and len(sel["chosen"]) == auto["budget"] == sel["budget"]
    assert 2 <= auto["budget"] < len(sel["pool"]) == auto["pool"]
    assert auto["predicted_loss_db"] <= auto["tolerance_db"] == 0.5 and auto["kind"] == "walk"
    assert sel["method"] == "path" and "-> path" in sel["note"]        # the walk rule: frames in capture order
    assert "by even spacing along the capture path" in (out / "report.html").read_text()
    assert "budget auto" in res.stdout and f"{auto['budget']} of {len(sel['pool'])}" in res.stdout
    html = (out / "report.html").read_text()
    assert "How many photos" in html and f"Predicted from the poses alone: <b>{auto['budget']}" in html
    before = _mtimes(out)
    res = subprocess.run(_cmd(out, "--no-evaluate", "--budget", "auto", "--budget-tolerance", "0.2"),
                         capture_output=True, text=True, env=_env(), timeout=600)
    assert res.returncode == 0, res.stderr
    after = _mtimes(out)
    assert after["occupancy/stage.json"] == before["occupancy/stage.json"]
    assert after["select/stage.json"] != before["select/stage.json"]
    tight = json.loads((out / "select" / "selection.json").read_text())["budget_auto"]
    assert tight["tolerance_db"] == 0.2 and tight["budget"] >= auto["budget"]
    assert tight["predicted_loss_db"] <= 0.2
