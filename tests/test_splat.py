"""``--trainer gsplat`` (issue 59, item 4): 3D Gaussian splatting as the evaluation's trainer, and the field on the
device torch sees. gsplat needs CUDA, which CI has not: the plumbing is tested here on the CPU with a stand-in for
gsplat's rasterizer (a differentiable splat of each Gaussian's colour), the refusal where it cannot run is tested as
a user meets it, and research/gpu_check.py runs the real thing where a GPU is lent."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at


def _fake_gsplat(monkeypatch) -> list:
    """Install a stand-in ``gsplat`` package: ``rasterization`` renders each pixel as the opacity-weighted mean of
    the Gaussians' base colours (differentiable in colour and opacity), ``DefaultStrategy`` densifies nothing.
    Returns the list of (width, height, sh_degree) it was asked to render."""
    import torch
    calls = []

    def rasterization(means, quats, scales, opacities, colors, viewmats, Ks, width, height, sh_degree=3,
                      packed=False):
        assert viewmats.shape == (1, 4, 4) and Ks.shape == (1, 3, 3) and colors.ndim == 3 and colors.shape[2] == 3
        calls.append((width, height, sh_degree))
        w = opacities / opacities.sum()
        rgb = (w[:, None] * (0.5 + 0.28209479177387814 * colors[:, 0, :])).sum(0)
        img = rgb.expand(1, height, width, 3)
        return img, torch.ones(1, height, width, 1), {"means2d": means[:, :2]}

    class DefaultStrategy:
        def __init__(self, verbose=False):
            pass

        def check_sanity(self, params, opts):
            assert set(params) == set(opts)

        def initialize_state(self, scene_scale=1.0):
            return {}

        def step_pre_backward(self, *a, **k):
            pass

        def step_post_backward(self, *a, **k):
            pass

    g = types.ModuleType("gsplat")
    g.rasterization = rasterization
    s = types.ModuleType("gsplat.strategy")
    s.DefaultStrategy = DefaultStrategy
    g.strategy = s
    monkeypatch.setitem(sys.modules, "gsplat", g)
    monkeypatch.setitem(sys.modules, "gsplat.strategy", s)
    return calls


def _cams(n=4, w=12, h=8) -> Cameras:
    ang = np.linspace(0, np.pi / 2, n)
    centres = np.stack([3 * np.cos(ang), 3 * np.sin(ang), np.full(n, 0.5)], 1)
    return Cameras(look_at(centres, np.zeros((n, 3))), 10.0, 10.0, w / 2, h / 2, w, h,
                   names=tuple(f"{i}.png" for i in range(n)))


def test_splats_train_on_the_subsets_photos_at_their_size_and_render_each_view(monkeypatch):
    from curate.field.config import SplatConfig
    from curate.field.splat import render_view, train_splats
    calls = _fake_gsplat(monkeypatch)
    cams = _cams()
    target = np.array([0.8, 0.3, 0.1], np.float32)
    imgs = [np.broadcast_to(target, (8, 12, 3)).copy() for _ in range(len(cams))]
    pts = np.random.default_rng(0).normal(0, 0.3, (50, 3))
    steps = []
    model, st = train_splats(SplatConfig(steps=30, sh_degree=1), cams, imgs, pts, None,
                             (np.full(3, -1.0), np.full(3, 1.0)), seed=0, device="cpu", callback=steps.append)
    assert st.iters == 30 and steps == list(range(1, 31)) and st.n_gaussians == 50
    assert {(w, h) for w, h, _ in calls} == {(12, 8)} and max(d for *_, d in calls) == 0   # degree 1 after 1,000 steps
    out = render_view(model, cams, 2)
    assert out.shape == (8, 12, 3) and np.isfinite(out).all() and out.min() >= 0 and out.max() <= 1
    start = 0.5 * np.ones(3)                                  # grey points: the loss must have moved the colour
    assert np.abs(out[0, 0] - target).sum() < np.abs(start - target).sum()


def test_without_points_the_splats_start_in_the_scene_box():
    from curate.field.splat import initial_points
    xyz, rgb = initial_points(None, None, (np.zeros(3), np.ones(3)), 500, seed=3)
    assert xyz.shape == (500, 3) and xyz.min() >= 0 and xyz.max() <= 1 and rgb.shape == (500, 3)
    pts = np.arange(30, dtype=float).reshape(10, 3)
    xyz, rgb = initial_points(pts, np.full((10, 3), 255), (np.zeros(3), np.ones(3)), 500, seed=3)
    assert np.array_equal(xyz, pts.astype(np.float32)) and np.allclose(rgb, 1.0)


def test_the_unit_key_names_the_trainer_and_not_the_device():
    from dataclasses import replace
    from curate.evaluate.config import EvalConfig
    ev = EvalConfig()
    assert ev.training() == replace(ev, field=replace(ev.field, device="cuda")).training()   # same field anywhere
    gs = EvalConfig(trainer="gsplat")
    assert gs.training() != ev.training() and gs.training()["trainer"] == "gsplat"
    assert gs.train_side() == 1600 and ev.train_side() == 160 and gs.train_steps() == 7000
    with pytest.raises(ValueError, match="--trainer"):
        EvalConfig(trainer="nerfacto")


def test_the_device_is_chosen_once_for_every_training(monkeypatch):
    import torch
    from curate.evaluate.config import EvalConfig
    from curate.evaluate.units import resolved
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolved(EvalConfig()).field.device == "cpu"
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert resolved(EvalConfig()).field.device == "cuda"


@pytest.mark.parametrize("cuda,has_gsplat,words", [(False, True, "needs a CUDA GPU"),
                                                    (True, False, "pip install 'curate[gsplat]'")])
def test_trainer_gsplat_where_it_cannot_run_is_one_line_before_any_work(tmp_path, monkeypatch, capsys, cuda,
                                                                       has_gsplat, words):
    import importlib.util

    import torch
    from curate import cli
    monkeypatch.setattr(torch.cuda, "is_available", lambda: cuda)
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: (object() if has_gsplat else None) if name == "gsplat" else real(name, *a))
    from pathlib import Path
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    out = tmp_path / "run"
    rc = cli.main(["run", str(sample / "images"), "--poses", str(sample / "transforms.json"), "--out", str(out),
                   "--trainer", "gsplat"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and words in err[0]
    assert not (out / "sfm").exists()                          # nothing was computed
    from curate.evaluate.config import EvalConfig
    from curate.evaluate.units import resolved
    with pytest.raises(ValueError) as e:
        resolved(EvalConfig(trainer="gsplat"))
    assert words in str(e.value)


def test_an_evaluation_unit_trains_splats_at_the_capture_resolution_and_scores_each_held_out_photo(tmp_path,
                                                                                                monkeypatch):
    """The evaluation's worker with ``--trainer gsplat``: the subset trained, each held-out photo rendered at the
    size the unit was given, scored and written (metrics.json, renders), as for the field."""
    import json

    from PIL import Image
    from curate.core.runfolder import claim
    from curate.evaluate.config import EvalConfig
    from curate.evaluate.units import Unit, train_unit
    from curate.field.config import SplatConfig
    _fake_gsplat(monkeypatch)
    run = claim(tmp_path / "run")
    (run / "sfm").mkdir()
    np.save(run / "sfm" / "points.npy", np.random.default_rng(1).normal(0, 0.3, (40, 3)).astype(np.float32))
    cams = _cams(6, 24, 16)
    paths = []
    for i in range(6):
        p = tmp_path / f"{i}.png"
        Image.new("RGB", (24, 16), (200, 80, 30)).save(p)
        paths.append(str(p))
    ev = EvalConfig(trainer="gsplat", splat=SplatConfig(steps=20, max_side=24))
    m = train_unit(str(run), Unit("f00_selection", "selection", None, [1, 2, 4, 5], 0), ev, cams, paths, [0, 3],
                   (np.full(3, -1.0), np.full(3, 1.0)), "k")
    assert m["n_train"] == 4 and m["iters"] == 20 and [v["name"] for v in m["per_view"]] == ["0.png", "3.png"]
    assert all(np.isfinite(v["psnr"]) for v in m["per_view"])
    saved = json.loads((run / "evaluate" / "f00_selection" / "metrics.json").read_text())
    assert saved["psnr"] == m["psnr"]
    with Image.open(run / "evaluate" / "f00_selection" / "renders" / "0.png") as im:
        assert im.size == (24, 16)
