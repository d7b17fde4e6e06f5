"""The self-contained HTML report of a run folder (synthetic run folder, no training)."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from curate.core.cameras import Cameras, look_at
from curate.report.run_report import floorplan, top_down_axes, write_html


def make_run(root: Path, evaluated: bool = True) -> Path:
    """A run folder with every file the report reads: 10 cameras on a ring, 3 chosen, 2 held out."""
    run = root / "run"
    n, res = 10, 6
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c = np.stack([2 * np.cos(a), 2 * np.sin(a), np.full(n, 1.0)], 1)
    names = tuple(f"img_{i:02d}.jpg" for i in range(n))
    cams = Cameras(look_at(c, np.zeros((n, 3))), 50, 50, 32, 24, 64, 48, names=names)
    (run / "sfm" / "images").mkdir(parents=True)
    cams.save(run / "sfm" / "cameras.json")
    rng = np.random.default_rng(0)
    for nm in names:
        Image.fromarray(rng.integers(0, 255, (48, 64, 3), np.uint8)).save(run / "sfm" / "images" / nm)
    (run / "sfm" / "images.json").write_text(json.dumps({"photos": [
        {"original": f"/photos/{nm}", "rel": nm, "working": nm, "status": "kept", "registered": True}
        for nm in names]}))
    hold, chosen = [0, 5], [3, 7, 1]
    sel = {"method": "energy", "budget": 3, "holdout_every": 0, "holdout": [], "pool": list(range(n)), "chosen": chosen,
           "chosen_names": [names[i] for i in chosen], "energy": [10.5, 17.25, 20.125], "angular": [0.5, 1.25, 2.125],
           "frequency": [10.0, 16.0, 18.0], "seconds": 0.12, "n_nodes": 40, "up_axis": 2}
    (run / "select").mkdir()
    (run / "select" / "selection.json").write_text(json.dumps(sel))
    flat = rng.choice(res ** 3, 40, replace=False)
    np.savez(run / "select" / "nodes.npz", nodes=rng.uniform(-1, 1, (40, 3)), angular=rng.uniform(0, 0.3, 40),
             frequency=rng.uniform(0.5, 1, 40), flat=flat, res=res, box_min=-np.ones(3), box_max=np.ones(3))
    rep = {"photos": "/photos", "run_dir": str(run), "budget": 3, "n_photos": 12, "n_registered": n,
           "n_candidates": n, "wall_seconds": 123.4,
           "stages": [{"name": "sfm", "seconds": 1.5, "skipped": True, "compute_seconds": 61.5},
                      {"name": "select", "seconds": 0.25, "skipped": False, "compute_seconds": 0.25}],
           "sfm": {"skipped": [{"file": "/photos/notes.txt", "reason": "not an image <txt>"}],
                   "dropped": [{"file": "/photos/dup.jpg", "reason": "near-duplicate"}]},
           "selection": {k: v for k, v in sel.items() if k not in ("holdout", "pool")}}
    if evaluated:
        gt = run / "evaluate" / "gt"
        gt.mkdir(parents=True)
        for i in hold:
            Image.fromarray(rng.integers(0, 255, (24, 32, 3), np.uint8)).save(gt / f"img_{i:02d}.png")
        keys = ["selection", "random_s0", "random_s1", "random_s2", "fvs", "all"]
        for k in keys:
            (run / "evaluate" / k / "renders").mkdir(parents=True)
            for i in hold:
                Image.fromarray(rng.integers(0, 255, (24, 32, 3), np.uint8)).save(
                    run / "evaluate" / k / "renders" / f"img_{i:02d}.png")

        def m(psnr, key, n_train=3):
            return {"psnr": psnr, "ssim": 0.5, "n_train": n_train, "train_seconds": 12.0, "key": key,
                    "per_view": [{"name": names[i], "psnr": psnr + d, "ssim": 0.5} for i, d in zip(hold, (-0.5, 0.5))]}
        rep["methods"] = {
            "selection": m(25.125, "selection"), "fvs": m(23.5, "fvs"), "all": m(26.75, "all", 8),
            "random": {"psnr": 22.375, "psnr_std": 0.625, "ssim": 0.45, "ssim_std": 0.015, "seeds": [0, 1, 2],
                       "n_train": 3, "runs": {str(s): {**m(22 + s / 2, f"random_s{s}"), "seed": s} for s in range(3)},
                       "per_view": [{"name": names[i], "psnr": 22.375, "ssim": 0.45} for i in hold]}}
        rep["paired"] = {"selection-random": {"mean": 2.75, "lo": 1.125, "hi": 4.375, "n": 2},
                         "selection-fvs": {"mean": 1.625, "lo": -0.5, "hi": 3.75, "n": 2}}
        rep["gap_closed"] = 0.6286
        rep["evaluation"] = {"status": "current", "refresh": f"curate evaluate {run}"}
        rep["estimate"] = {"budget": 3, "n_pool": 8, "n_holdout": 2, "holdout_every": 5, "method": "energy"}
        (run / "evaluate" / "summary.json").write_text(json.dumps({"protocol": {"holdout": hold, "holdout_every": 5}}))
    (run / "report.json").write_text(json.dumps(rep))
    return run


def image_sources(page: str) -> list[str]:
    return re.findall(r'<img[^>]*\ssrc="([^"]*)"', page) + re.findall(r'<image[^>]*\shref="([^"]*)"', page)


def test_report_with_evaluation(tmp_path):
    run = make_run(tmp_path)
    out = write_html(run)
    assert out == run / "report.html"
    page = out.read_text()
    for v in ("25.12", "22.38 ± 0.62", "23.50", "26.75", "+2.75", "+1.12 .. +4.38", "+1.62", "63%", "2.1 min",
              "near-duplicate", "not an image &lt;txt&gt;", "img_03.jpg", "this method, 3 of 8", "all 8 photos",
              "<b>ahead of</b> random subsets", "<b>not told apart from</b> farthest-view sampling"):
        assert v in page, v
    body = page[page.index("<body"):]
    # the first screen: the verdict, then the chosen photos, before any table
    assert body.index('class="verdict"') < body.index("The chosen photos") < body.index("<table")
    srcs = image_sources(page)
    # 3 thumbnails + 2 held-out views x (gt + selection, random, fvs, all) + 2 floor plans
    assert len(srcs) == 3 + 2 * 5 + 2
    assert all(s.startswith("data:image/") for s in srcs)
    # namespaces only
    assert "http://" not in re.sub(r"http://www\.w3\.org/[\w/.]+", "", page) and "https://" not in page
    assert page.count("<svg") >= 6  # bars, 2 colour bars, 2 floor plans, camera map, energy curves
    assert "Not available" not in page  # no section failed


def test_report_without_evaluation_and_missing_files(tmp_path):
    run = make_run(tmp_path, evaluated=False)
    (run / "select" / "nodes.npz").unlink()
    page = write_html(run).read_text()
    assert page.count("Not evaluated") == 1 and "nodes.npz missing" in page   # said once, in the verdict
    assert "curate evaluate" in page and "--eval-minutes" in page   # how, and in what time, to evaluate it
    assert "Held-out photos side by side" not in page and "How the selection compares" not in page
    assert all(s.startswith("data:image/") for s in image_sources(page))
    assert "Not available" not in page
    # an almost empty run folder still gives a page
    empty = tmp_path / "empty"
    empty.mkdir()
    page = write_html(empty).read_text()
    assert "Not evaluated" in page and "<h2>" in page


def test_floorplan_averages_vertical_columns():
    res = 3
    flat = np.array([(1 * res + 2) * res + 0, (1 * res + 2) * res + 2])  # ix=1, iy=2, iz=0 and 2
    m = floorplan(np.array([1.0, 3.0]), flat, res, up=2, a=0, b=1)
    assert m.shape == (3, 3) and m[0, 1] == 2.0  # row 0 = largest y, column = x
    assert np.isnan(m).sum() == 8
    # y up (cameras' -y along +y): a x b points along +y
    c2w = np.tile(np.eye(4), (2, 1, 1))
    c2w[:, :3, 1] = [0, -1, 0]
    k, a, b, sign = top_down_axes(c2w)
    assert k == 1 and np.cross(np.eye(3)[a], np.eye(3)[b])[1] == pytest.approx(sign)


def test_simulate_report(tmp_path):
    from curate.simulate.report import write_simulate_html
    cams = Cameras(look_at(np.array([[1.0, 0, 1], [0, 1, 1]]), np.zeros((2, 3))), 50, 50, 32, 24, 64, 48)
    tests = ("hemisphere", "random", "ours")
    rep = {"scene": "kitchen", "scene_seed": 0, "budget": 2, "n_nodes": 99, "wall_seconds": 3.5,
           "table": {m: {**{t: 20.0 + i + j / 4 for j, t in enumerate(tests)}, "average": 20.25 + i}
                     for i, m in enumerate(("ours", "random"))},
           "ssim": {m: {t: 0.5 for t in tests} for m in ("ours", "random")},
           "per_view": {m: {t: {"psnr": [20.0 + i, 21.0 + 2 * i, 19.0], "ssim": [0.5] * 3} for t in tests}
                        for i, m in enumerate(("ours", "random"))},
           "energy_curve": [1.0, 2.0], "cameras": {"ours": cams.to_dict(), "random": cams.to_dict()},
           "test_cameras": {t: cams.to_dict() for t in tests}, "timings": {"render_s": 1.25}}
    (tmp_path / "report.json").write_text(json.dumps(rep))
    page = write_simulate_html(tmp_path).read_text()
    assert "21.25" in page and "kitchen" in page and "ours − random" in page and "Not available" not in page
    assert "https://" not in page and "<img" not in page  # all charts are inline SVG


def test_a_split_capture_and_a_disconnected_export_are_boxed_at_the_top(tmp_path):
    """A user must see, before any figure, that SfM kept only part of the capture and that the
    exported images do not form one connected set."""
    run = make_run(tmp_path)
    page = write_html(run).read_text()
    assert 'class="warnbox"' not in page
    (run / "sfm" / "stage.json").write_text(json.dumps({"stats": {
        "model_sizes": [6, 3], "n_kept": 10, "n_registered": 6,
        "unregistered": ["img_07.jpg", "img_08.jpg", "img_09.jpg"]}}))
    (run / "export").mkdir()
    (run / "export" / "stage.json").write_text(json.dumps({"warning": "the 3 exported images form 2 groups"}))
    rec = json.loads((run / "sfm" / "stage.json").read_text())
    rec["stats"]["videos"] = [{"video": "walk.mp4", "decoded": 3600, "candidates": 412, "static": 700, "stopped": ""}]
    (run / "sfm" / "stage.json").write_text(json.dumps(rec))
    page = write_html(run).read_text()
    body = page[page.index("<body"):]
    assert "video walk.mp4" in body and "3600 frames decoded, 412 kept as candidates" in body
    assert body.count('class="warnbox"') == 2
    assert "split into 2 models (6, 3 photos)" in body and "img_07.jpg..img_09.jpg (3)" in body
    assert body.index("warnbox") < body.index('class="verdict"') < body.index("<dl")   # above the figures


def test_a_folded_video_take_is_boxed_at_the_top(tmp_path):
    """A model whose camera path jumps once and does not come back (a fold keeps every frame): said above
    the figures, with the frames on each side of the jump."""
    run = make_run(tmp_path)
    (run / "sfm" / "stage.json").write_text(json.dumps({"stats": {"path_jumps": {"walk.mp4": [
        {"from": "walk_000012.300.jpg", "to": "walk_000012.400.jpg", "x_around": 44.8}]}}}))
    body = write_html(run).read_text()
    body = body[body.index("<body"):]
    assert body.count('class="warnbox"') == 1
    assert ("video walk.mp4: the camera path jumps from walk_000012.300.jpg to walk_000012.400.jpg (44.8 times the "
            "steps around it)") in body
    assert body.index("warnbox") < body.index("<dl")


def test_steps_their_own_matches_refute_are_boxed_at_the_top(tmp_path):
    """A model with steps between consecutive frames that their own verified matches refute (the blurred walk's
    wrong model): said above the figures, with the worst step and how many were checked."""
    run = make_run(tmp_path)
    bad = [{"from": "walk_000002.200.jpg", "to": "walk_000002.300.jpg", "inliers": 303, "fit": 0.17},
           {"from": "walk_000002.700.jpg", "to": "walk_000002.800.jpg", "inliers": 544, "fit": 0.22}]
    (run / "sfm" / "stage.json").write_text(json.dumps({"stats": {"parts": [
        {"model": "sparse/0", "n_registered": 26, "steps_checked": {"walk.mp4": 22},
         "unexplained_steps": {"walk.mp4": bad}}]}}))
    body = write_html(run).read_text()
    body = body[body.index("<body"):]
    assert body.count('class="warnbox"') == 1
    assert ("video walk.mp4: 2 of 22 steps between consecutive frames are not what the frames&#x27; own matches say "
            "(walk_000002.200.jpg to walk_000002.300.jpg fits 17% of their 303 verified matches and 1 more)") in body
    assert body.index("warnbox") < body.index("<dl")


@pytest.mark.parametrize("gain, says", [
    (2, "curate used COLMAP's incremental mapper: the global model, the less accurate of the two, held 2 photos "
        "more than the incremental one, under the 22 it must gain to replace it"),
    (0, "held no more photos than the incremental one, under the 22"),
    (30, None)])
def test_the_report_says_why_a_larger_global_model_was_not_used(tmp_path, gain, says):
    """Three takes, one of another place: the global model held 2 photos more than the incremental one
    and was not used (it is the less accurate); the SfM section says why, not only which mapper."""
    run = make_run(tmp_path)
    mapper = "incremental" if says else "global"
    (run / "sfm" / "stage.json").write_text(json.dumps({"stats": {"mapper": mapper, "mappers_tried": {
        "incremental": {"model_sizes": [369, 63]},
        "global": {"model_sizes": [369 + gain, 63], "pruned_to": 369 + gain, "gain": gain, "gain_needed": 22}}}}))
    body = html.unescape(write_html(run).read_text())
    assert "the incremental mapper split the capture into models of 369, 63 photos" in body
    if says:
        assert says in body
    else:
        assert "it must gain" not in body and "curate used COLMAP's global mapper" in body


@pytest.mark.parametrize("glob", [False, True])
def test_the_report_says_which_parts_joined_the_largest(tmp_path, glob):
    """A third of office.mp4's frame rate: the incremental mapper split it (81, 50, 4), the 50-frame part shared 16
    frames with the largest and joined it (115); the SfM section says so, with or without the global mapper's try."""
    run = make_run(tmp_path)
    tried = {"incremental": {"model_sizes": [81, 50, 4], "joined_sizes": [115, 4]}}
    if glob:
        tried["global"] = {"model_sizes": [124], "refuted": True, "part_disagreement_deg": [13.21, None]}
    (run / "sfm" / "stage.json").write_text(json.dumps({"stats": {"mapper": "incremental", "mappers_tried": tried}}))
    body = html.unescape(write_html(run).read_text())
    assert ("the incremental mapper split the capture into models of 81, 50, 4 photos; the parts that share frames "
            "with the largest and agree on them joined it (115 photos)") in body
    assert ("the global mapper mapped 124 in one model" in body) is glob and "curate used COLMAP's incremental" in body
    assert ("curate used COLMAP's incremental mapper: the global model disagrees with every incremental part it "
            "could be checked against (13.21 deg)" in body) is glob


def test_a_video_cut_short_is_boxed_at_the_top(tmp_path):
    """A video that stopped decoding before its end: where it stopped, above the figures."""
    run = make_run(tmp_path)
    stopped = "decoding stopped at 10.7 s of 12.5 s: the file is damaged or cut after that point"
    (run / "sfm" / "stage.json").write_text(json.dumps({"stats": {"videos": [
        {"video": "walk.mp4", "decoded": 107, "candidates": 40, "static": 0, "stopped": stopped},
        {"video": "hall.mp4", "decoded": 50, "candidates": 20, "static": 0, "stopped": ""}]}}))
    body = write_html(run).read_text()
    body = body[body.index("<body"):]
    assert body.count('class="warnbox"') == 1 and f"video walk.mp4: {stopped}" in body
    assert body.index("warnbox") < body.index("<dl") and "video hall.mp4</dt><dd>50 frames decoded" in body


@pytest.mark.parametrize("kind, says, not_says", [("walk", "on the office", "skull"),
                                                   ("object", "the skull", "on the office")])
def test_budget_auto_section_states_the_check_for_its_kind(kind, says, not_says):
    """The "How many photos" section says how the law was checked for the capture's kind (the real
    walk it was not fitted on; the real objects, each left out), the chosen point and the note."""
    from types import SimpleNamespace
    from curate.report.run_report import _budget_auto
    auto = {"budget": 12, "pool": 40, "tolerance_db": 0.5, "kind": kind, "predicted_loss_db": 0.45,
            "curve_k": [2, 12, 39], "curve_loss_db": [4.0, 0.45, 0.01], "note": f"auto chose 12 of 40 ({kind})"}
    html = _budget_auto(SimpleNamespace(sel={"budget_auto": auto}, methods={}))
    assert says in html and not_says not in html and "<svg" in html
    assert f"Predicted from the poses alone: <b>12</b> of 40 photos for 0.5 dB ({kind} law)" in html


def test_an_out_of_date_evaluation_is_never_shown_as_this_selections(tmp_path):
    """A report whose evaluation estimates an earlier selection says so and shows none of its figures."""
    run = make_run(tmp_path)
    rep = json.loads((run / "report.json").read_text())
    for k in ("methods", "paired", "gap_closed", "estimate"):
        rep.pop(k)
    rep["evaluation"] = {"status": "out of date", "why": "select was redone since", "refresh": "curate evaluate R",
                         "of": {"exported_budget": 22, "method": "path"}}
    (run / "report.json").write_text(json.dumps(rep))
    page = write_html(run).read_text()
    assert "earlier selection (22 photos, path)" in page and "curate evaluate R" in page
    assert "25.12" not in page and "How the selection compares" not in page


def test_the_camera_map_labels_the_axes_it_plots():
    """The top-down map's axis labels are the world axes it draws (z up: x right, y up; y up: z, x)."""
    from curate.html.charts import camera_map, text_of
    from curate.html.plots import top_down_axes
    c = np.array([[0.0, 0, 1], [1, 0, 1], [0, 1, 1]])
    for up, target in ((2, np.array([0.5, 0.5, 0.0])), (1, np.array([0.5, 2.0, 0.5]))):
        cams = Cameras(look_at(c if up == 2 else c[:, [0, 2, 1]], np.zeros((3, 3)) + target), 50, 50, 32, 24, 64, 48)
        k, a, b, _ = top_down_axes(cams.c2w, up)
        svg = camera_map(cams.centres[:, [a, b]], cams.view_dirs[:, [a, b]], [0], "t", axis_labels=("xyz"[a], "xyz"[b]))
        labels = text_of(svg).split()
        assert "xyz"[a] in labels and "xyz"[b] in labels and "xyz"[k] not in labels


@pytest.mark.parametrize("given, says", [
    ("auto", "how many: <code>--budget auto</code>, 0.5 dB)"),
    ("default: auto (an object capture)",
     "how many: <code>--budget default</code>, auto for an object capture, 0.5 dB)")])
def test_the_first_screen_names_the_budget_the_user_gave(tmp_path, given, says):
    """The default budget on an object capture is auto's advice: the verdict's first line names the budget as the
    user gave it (`--budget default`, and what it meant), not a flag they never typed."""
    from types import SimpleNamespace
    from curate.report.run_report import _verdict
    sel = {"chosen": [0, 1, 2], "method": "energy", "budget_text": given,
           "budget_auto": {"tolerance_db": 0.5, "budget": 3, "pool": 5, "kind": "object"}}
    html = _verdict(SimpleNamespace(rep={"selection": sel, "n_registered": 5}, sel=sel, dir=tmp_path))
    assert says in html


def test_the_method_table_shows_whole_counts_and_no_empty_spread():
    """The folds' mean count of photos is a count when every fold trained as many (28, not 28.0), one decimal
    otherwise; a spread that was not measured (random's SSIM over one draw) is left out, not shown as '± —'."""
    from types import SimpleNamespace
    from curate.report.run_report import _method_table
    run = SimpleNamespace(rep={"estimate": {"budget": 28, "n_pool": 200, "n_holdout": 14, "n_folds": 1}}, paired={},
                          methods={"selection": {"psnr": 20.0, "ssim": 0.5, "n_train": 28.0},
                                   "random": {"psnr": 19.0, "ssim": 0.4, "psnr_std": 0.2, "n_train": 27.5},
                                   "all": {"psnr": 21.0, "ssim": 0.6, "n_train": 186.0, "n_views": 14}})
    html = _method_table(run)
    assert "<td>28</td>" in html and "<td>27.5</td>" in html and "<td>186</td>" in html and "28.0" not in html
    assert "19.00 ± 0.20" in html and "± —" not in html
