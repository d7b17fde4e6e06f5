"""The CPU radiance field: analytic rendering, training on a tiny scene, stability, errors, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from curate.core.cameras import Cameras, look_at
from curate.field.model import (SH_C0, FieldConfig, RadianceField, composite_weights, contract, trilinear,
                                trilinear_corners)
from curate.field.metrics import camera_rays, psnr, render_image, ssim
from curate.field.train import train_field

torch.set_num_threads(1)  # see FieldConfig.threads


def _ring(n: int, radius: float = 3.0, size: int = 24, height: float = 0.8) -> Cameras:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c = np.stack([radius * np.cos(a), radius * np.sin(a), height * np.cos(3 * a)], 1)
    f = 1.2 * size
    return Cameras(look_at(c, np.zeros((n, 3))), f, f, size / 2, size / 2, size, size)


def _sphere_images(cams: Cameras, radius: float = 0.8, bg=(1.0, 1.0, 1.0)) -> list[np.ndarray]:
    """Analytic ray casting of an opaque sphere at the origin, coloured by the normal."""
    out = []
    for i in range(len(cams)):
        o, d = (t.numpy().astype(np.float64) for t in camera_rays(cams, i))
        b = np.einsum("ij,ij->i", o, d)
        disc = b * b - (np.einsum("ij,ij->i", o, o) - radius ** 2)
        hit = disc > 0
        t = -b - np.sqrt(np.maximum(disc, 0))
        p = o + t[:, None] * d
        col = np.where(hit[:, None], 0.5 + 0.4 * p / radius, np.asarray(bg)[None])
        out.append(col.reshape(int(cams.height[i]), int(cams.width[i]), 3).astype(np.float32))
    return out


def _tiny_cfg(**kw) -> FieldConfig:
    base = dict(res_schedule=(16, 24), upsample_at=(60,), n_inner=32, n_outer=8, batch_rays=512,
                val_every=0, occ_update_start=50, occ_update_every=50, device="cpu")
    base.update(kw)
    return FieldConfig(**base)


# ---------------------------------------------------------------- analytic rendering
@pytest.mark.parametrize("sigma", [0.3, 2.0, 25.0])
def test_composite_matches_slab(sigma):
    """Constant density slab of thickness d in [a, b] along the ray, colour c, background bg:
    C = c (1 - exp(-sigma d)) + bg exp(-sigma d)."""
    S, L, a, b = 4000, 3.0, 1.0, 1.7
    edges = torch.linspace(0, L, S + 1, dtype=torch.float64)
    mid = 0.5 * (edges[1:] + edges[:-1])
    delta = (edges[1:] - edges[:-1])[None]
    sig = torch.where((mid >= a) & (mid < b), sigma, 0.0)[None].to(torch.float64)
    w = composite_weights(sig, delta)
    c, bg = torch.tensor([0.9, 0.2, 0.4], dtype=torch.float64), torch.tensor([0.1, 0.8, 0.3], dtype=torch.float64)
    col = (w[..., None] * c).sum(1) + (1 - w.sum(1, keepdim=True)) * bg
    trans = math.exp(-sigma * (b - a))
    exp = c * (1 - trans) + bg * trans
    assert torch.allclose(col[0], exp, atol=2e-3)
    assert abs((1 - w.sum()).item() - trans) < 2e-3


@pytest.mark.parametrize("res, channels", [(2, 1), (7, 1), (9, 3), (5, 12)])
def test_trilinear_lookup_is_grid_samples_value_and_gradient(res, channels):
    """Training reads the grids through :func:`trilinear` (an index_add backward); rendering through grid_sample.
    Both give the same values and gradients, at random points, on the nodes and on the faces of the grid."""
    gen = torch.Generator().manual_seed(res * 10 + channels)
    grid = torch.randn(1, channels, res, res, res, generator=gen, dtype=torch.float64)
    nodes = torch.linspace(-1, 1, res, dtype=torch.float64)
    pts = torch.cat([torch.rand(500, 3, generator=gen, dtype=torch.float64) * 2 - 1,
                     nodes[torch.randint(0, res, (60, 3), generator=gen)],            # on nodes, edges and faces
                     torch.tensor([[-1.0, -1, -1], [1, 1, 1], [1, -1, 0.3]], dtype=torch.float64)])
    up = torch.randn(channels, len(pts), generator=gen, dtype=torch.float64)   # an upstream gradient
    values, grads = [], []
    for use_corners in (False, True):
        g = grid.clone().requires_grad_(True)
        if use_corners:
            out = trilinear(g, trilinear_corners(pts, res))
        else:
            out = torch.nn.functional.grid_sample(g, pts.reshape(1, 1, 1, -1, 3), mode="bilinear",
                                                  align_corners=True).reshape(channels, -1)
        (out * up).sum().backward()
        values.append(out.detach())
        grads.append(g.grad)
    assert torch.allclose(values[1], values[0], atol=1e-12)
    assert torch.allclose(grads[1], grads[0], atol=1e-12)
    cn = trilinear_corners(pts, res)
    assert cn.idx.min() >= 0 and cn.idx.max() < res ** 3
    assert torch.allclose(cn.w.sum(0), torch.ones(len(pts), dtype=torch.float64))


@pytest.mark.parametrize("trans_thresh", [0.0, 1e-3])
def test_a_field_trained_is_the_field_rendered(trans_thresh):
    """The colours, depths and opacities of training's forward pass (with gradients) are rendering's (without),
    on a field with random grids, an occupancy mask and samples below the colour threshold."""
    cfg = FieldConfig(res_schedule=(12,), sh_degree=1, n_inner=24, n_outer=12, trans_thresh=trans_thresh,
                      color_thresh=1e-3)
    torch.manual_seed(3)
    f = RadianceField(cfg, [-1, -1, -1], [1, 1, 1])
    with torch.no_grad():
        f.density.copy_(torch.randn_like(f.density) * 3)
        f.color.copy_(torch.randn_like(f.color))
        f.occ &= torch.rand(f.occ.shape) > 0.3
    o = torch.randn(300, 3) * 0.3 + torch.tensor([0.0, 0.0, -2.5])
    d = torch.nn.functional.normalize(torch.randn(300, 3) * 0.3 + torch.tensor([0.0, 0.0, 1.0]), dim=1)
    trained = f.render_rays(o, d)
    with torch.no_grad():
        rendered = f.render_rays(o, d)
    for k in ("rgb", "depth", "acc"):
        assert torch.isfinite(trained[k]).all()
        assert torch.allclose(trained[k].detach(), rendered[k], atol=1e-5), k
    assert trained["n_color"] == rendered["n_color"] > 0
    trained["rgb"].sum().backward()
    assert torch.isfinite(f.density.grad).all() and f.density.grad.abs().sum() > 0
    assert torch.isfinite(f.color.grad).all() and f.color.grad.abs().sum() > 0


def test_field_renders_uniform_medium():
    """End to end through the field: uniform density and colour everywhere; a ray from the box
    centre along +x crosses contracted length ~ (2 - 1/far) - near."""
    cfg = FieldConfig(res_schedule=(17,), sh_degree=0, n_inner=256, n_outer=256, near=0.0)
    f = RadianceField(cfg, [-1, -1, -1], [1, 1, 1])
    sigma, col, bg = 0.7, torch.tensor([0.2, 0.6, 0.9]), torch.tensor([1.0, 0.0, 0.5])
    with torch.no_grad():
        f.density.fill_(math.log(math.expm1(sigma)) - f.bias)  # softplus(raw + bias) = sigma
        f.color.copy_((torch.logit(col) / SH_C0)[None, :, None, None, None].expand_as(f.color))
        out = f.render_rays(torch.zeros(1, 3), torch.tensor([[1.0, 0.0, 0.0]]), bg_override=bg)
    length = 2 - 1 / cfg.far
    trans = math.exp(-sigma * length)
    assert torch.allclose(out["rgb"][0], col * (1 - trans) + bg * trans, atol=5e-3)
    assert abs(out["acc"].item() - (1 - trans)) < 5e-3


def test_contract_bounds():
    x = torch.tensor([[0.5, 0.0, 0.0], [3.0, 0.0, 0.0], [1e9, -1e9, 5.0]])
    c = contract(x)
    assert torch.allclose(c[0], x[0])
    assert torch.all(c.abs() <= 2)


# ---------------------------------------------------------------- training
@pytest.fixture(scope="module")
def sphere_scene():
    cams = _ring(10)
    return cams, _sphere_images(cams)


@pytest.mark.slow
def test_field_trains_on_tiny_scene(sphere_scene):
    cams, imgs = sphere_scene
    cfg = _tiny_cfg()
    field, st = train_field(cfg, cams, imgs, iters=400, seed=0, box=([-1.2] * 3, [1.2] * 3))
    first, last = st.loss[0][2], st.loss[-1][2]
    assert last < 0.5 * first
    p = np.mean([psnr(render_image(field, cams, i), imgs[i]) for i in range(len(cams))])
    assert p > 20.0, p
    assert ssim(render_image(field, cams, 0), imgs[0]) > 0.6
    assert st.rays_per_s > 0 and st.iters == 400


@pytest.mark.slow
def test_determinism(sphere_scene):
    cams, imgs = sphere_scene
    cfg = _tiny_cfg()
    f1, _ = train_field(cfg, cams, imgs, iters=70, seed=3)
    f2, _ = train_field(cfg, cams, imgs, iters=70, seed=3)
    s1, s2 = f1.state_dict(), f2.state_dict()
    assert all(torch.equal(s1[k], s2[k]) for k in s1)
    f3, _ = train_field(cfg, cams, imgs, iters=70, seed=4)
    assert not torch.equal(f3.density, f1.density)


def test_checkpoint_roundtrip(sphere_scene, tmp_path):
    cams, imgs = sphere_scene
    field, _ = train_field(_tiny_cfg(), cams, imgs, run_dir=tmp_path, iters=70, seed=0)
    g = RadianceField.load(tmp_path / "field.pt")
    assert np.allclose(render_image(field, cams, 1), render_image(g, cams, 1), atol=1e-6)


def test_no_nan_with_huge_learning_rate(sphere_scene):
    cams, imgs = sphere_scene
    cfg = _tiny_cfg(lr_density=1e3, lr_color=1e3, lr_bg=1e3)
    field, st = train_field(cfg, cams, imgs, iters=30, seed=0)
    img = render_image(field, cams, 0)
    assert np.all(np.isfinite(img)) and img.min() >= 0 and img.max() <= 1
    assert all(np.isfinite(x[2]) for x in st.loss)


@pytest.mark.parametrize("raw", [1e6, -1e6, 1e30])
def test_no_nan_with_extreme_density(raw):
    f = RadianceField(FieldConfig(res_schedule=(8,)), [-1] * 3, [1] * 3)
    with torch.no_grad():
        f.density.fill_(raw)
        f.color.fill_(1e4)
    o = torch.tensor([[0.0, 0.0, -3.0], [0.0, 0.0, 0.0]])
    d = torch.tensor([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    out = f.render_rays(o, d)
    assert torch.all(torch.isfinite(out["rgb"])) and torch.all(torch.isfinite(out["depth"]))
    f.density.requires_grad_(True)
    f.render_rays(o, d, jitter=torch.Generator().manual_seed(0))["rgb"].sum().backward()
    assert torch.all(torch.isfinite(f.density.grad))


# ---------------------------------------------------------------- degenerate inputs
def test_errors_for_degenerate_inputs(sphere_scene):
    cams, imgs = sphere_scene
    with pytest.raises(ValueError, match="at least 2"):
        train_field(_tiny_cfg(), cams[:1], imgs[:1], iters=5)
    same = Cameras(look_at(np.zeros((3, 3)) + 2.0, np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0.]])),
                   20, 20, 12, 12, 24, 24)
    with pytest.raises(ValueError, match="one point"):
        train_field(_tiny_cfg(), same, imgs[:3], iters=5)
    with pytest.raises(ValueError, match="images for"):
        train_field(_tiny_cfg(), cams, imgs[:3], iters=5)
    with pytest.raises(ValueError, match="degenerate scene box"):
        RadianceField(FieldConfig(), [0, 0, 0], [1, 1, 0])
    from curate.core.grid import NodeGrid
    empty = NodeGrid([-1] * 3, [1] * 3, 8, np.zeros((8, 8, 8), bool))
    with pytest.raises(ValueError, match="prior is empty"):
        train_field(_tiny_cfg(), cams, imgs, iters=5, box=([-1] * 3, [1] * 3), prior=empty)


# ---------------------------------------------------------------- resume
@pytest.mark.slow
def test_resume_continues_the_schedule(sphere_scene):
    """Two resumed halves of N iterations: finite, improving loss, and the resolution of one 2N run."""
    cams, imgs = sphere_scene
    cfg = _tiny_cfg(upsample_at=(130,))
    box = ([-1.2] * 3, [1.2] * 3)
    whole, st_w = train_field(cfg, cams, imgs, iters=200, seed=0, box=box)
    half, st1 = train_field(cfg, cams[:6], imgs[:6], iters=100, seed=0, box=box)
    assert half.res == 16
    again, st2 = train_field(cfg, cams, imgs, iters=100, seed=1, init=half, start_iter=100, box=box)
    assert again is half and again.res == whole.res == 24 and st2.iters == 100
    losses = [x[2] for x in st1.loss + st2.loss]
    assert [x[0] for x in st2.loss] == [150, 200]  # the global iteration count goes on
    assert all(np.isfinite(losses)) and losses[-1] < 0.5 * losses[0]
    assert losses[-1] < 2.0 * st_w.loss[-1][2]
    # a field coarser than the schedule at start_iter is upsampled at once
    late, _ = train_field(cfg, cams, imgs, iters=1, seed=2, init=train_field(cfg, cams, imgs, iters=2)[0],
                          start_iter=500)
    assert late.res == 24


def test_resume_errors(sphere_scene):
    cams, imgs = sphere_scene
    with pytest.raises(TypeError, match="RadianceField"):
        train_field(_tiny_cfg(), cams, imgs, iters=5, init="field.pt")
    with pytest.raises(ValueError, match="non-negative"):
        train_field(_tiny_cfg(), cams, imgs, iters=5, start_iter=-3)
    with pytest.raises(ValueError, match="as init"):
        train_field(_tiny_cfg(), cams, imgs, iters=5, start_iter=10)
    f = RadianceField(_tiny_cfg(), [-1] * 3, [1] * 3)
    with pytest.raises(ValueError, match="differs"):
        train_field(_tiny_cfg(), cams, imgs, iters=5, init=f, start_iter=5, box=([-2] * 3, [2] * 3))
