"""3D Gaussian splatting as the evaluation's trainer (``--trainer gsplat``): for users who will train 3DGS, the
subsets are compared under the renderer they will use, at the capture's resolution.

gsplat's ``rasterization`` and ``DefaultStrategy`` densification, as its ``simple_trainer`` uses them: Gaussians
start from the run's sparse points (scales from the mean distance to the 3 nearest points, opacity 0.1, colour
from the point's; without points, random in the scene box), one photo a step, loss ``(1 - w) L1 + w (1 - SSIM)``,
spherical harmonics one degree more every 1,000 steps, simple_trainer's learning rates. Measured against curate's
field on three real captures: docs/evaluation.md#gaussian-splatting.

CUDA only, and gsplat is an optional dependency (``pip install 'curate[gsplat]'``), never downloaded at run time:
:func:`unavailable` says why it cannot run here, in one line. Nothing here is imported unless asked for.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from curate.core.cameras import Cameras
from curate.field.config import SplatConfig


def unavailable() -> str | None:
    """Why ``--trainer gsplat`` cannot run on this machine (None: it can): no CUDA device, or no gsplat package."""
    import importlib.util
    try:
        import torch
    except ImportError:                           # pragma: no cover - torch is a dependency
        return "--trainer gsplat needs torch with CUDA"
    if not torch.cuda.is_available():
        return ("--trainer gsplat needs a CUDA GPU and torch sees none here "
                "(the default trainer, curate's field, runs on the CPU)")
    if importlib.util.find_spec("gsplat") is None:
        return "--trainer gsplat needs the gsplat package: pip install 'curate[gsplat]'"
    return None


@dataclass
class SplatStats:
    """What a splat training did."""

    iters: int = 0
    """Steps run."""
    train_seconds: float = 0.0
    """Seconds of training (on CUDA, synchronised)."""
    n_gaussians: int = 0
    """Gaussians at the end (after densification)."""


def ssim_torch(a, b):
    """SSIM of two [1, 3, H, W] images in [0, 1] (11 x 11 Gaussian window, sigma 1.5), as 3DGS's loss uses it."""
    import torch
    import torch.nn.functional as F
    g = torch.exp(-((torch.arange(11, device=a.device) - 5.0) ** 2) / (2 * 1.5 ** 2))
    g = g / g.sum()
    w = (g[:, None] * g[None, :]).expand(3, 1, 11, 11).contiguous()
    mu_a, mu_b = F.conv2d(a, w, padding=5, groups=3), F.conv2d(b, w, padding=5, groups=3)
    saa = F.conv2d(a * a, w, padding=5, groups=3) - mu_a ** 2
    sbb = F.conv2d(b * b, w, padding=5, groups=3) - mu_b ** 2
    sab = F.conv2d(a * b, w, padding=5, groups=3) - mu_a * mu_b
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    return (((2 * mu_a * mu_b + c1) * (2 * sab + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (saa + sbb + c2))).mean()


def initial_points(points: np.ndarray | None, colors: np.ndarray | None, box: tuple, n_random: int,
                   seed: int) -> tuple[np.ndarray, np.ndarray]:
    """([P, 3] float32 positions, [P, 3] float32 colours in [0, 1]) the Gaussians start from: the sparse points
    (grey where they have no colour), else ``n_random`` uniform in ``box``."""
    if points is not None and len(points) >= 4:
        xyz = np.asarray(points, np.float32).reshape(-1, 3)
        rgb = (np.asarray(colors, np.float32).reshape(-1, 3) / 255.0 if colors is not None and len(colors) == len(xyz)
               else np.full_like(xyz, 0.5))
        return xyz, rgb
    rng = np.random.default_rng(seed)
    lo, hi = (np.asarray(v, np.float32) for v in box)
    xyz = (lo + (hi - lo) * rng.random((n_random, 3))).astype(np.float32)
    return xyz, rng.random((n_random, 3)).astype(np.float32)


def _params(xyz: np.ndarray, rgb: np.ndarray, scene_scale: float, sh_degree: int, device):
    import torch
    x = torch.tensor(xyz, dtype=torch.float32, device=device)
    n = len(x)
    d = []
    for s in range(0, n, 4096):                          # mean distance to the 3 nearest points
        dd = torch.cdist(x[s:s + 4096], x)
        d.append(dd.topk(min(4, n), largest=False).values[:, 1:].mean(1))
    dist = torch.cat(d).clamp_min(1e-7)
    C0 = 0.28209479177387814
    colors = torch.zeros(n, (sh_degree + 1) ** 2, 3, device=device)
    colors[:, 0, :] = (torch.tensor(rgb, dtype=torch.float32, device=device) - 0.5) / C0
    params = torch.nn.ParameterDict({
        "means": torch.nn.Parameter(x), "scales": torch.nn.Parameter(torch.log(dist)[:, None].repeat(1, 3)),
        "quats": torch.nn.Parameter(torch.rand(n, 4, device=device)),
        "opacities": torch.nn.Parameter(torch.logit(torch.full((n,), 0.1, device=device))),
        "sh0": torch.nn.Parameter(colors[:, :1, :].contiguous()),
        "shN": torch.nn.Parameter(colors[:, 1:, :].contiguous())})
    lrs = {"means": 1.6e-4 * scene_scale, "scales": 5e-3, "quats": 1e-3, "opacities": 5e-2, "sh0": 2.5e-3,
           "shN": 2.5e-3 / 20}
    opts = {k: torch.optim.Adam([{"params": params[k], "lr": lr, "name": k}], eps=1e-15) for k, lr in lrs.items()}
    return params, opts


def _camera_tensors(cams: Cameras, device):
    """(w2c [N, 4, 4], K [N, 3, 3]) float32 on ``device`` (OpenCV conventions, as gsplat's)."""
    import torch
    c2w = torch.tensor(cams.c2w, dtype=torch.float32, device=device)
    K = torch.tensor(cams.K, dtype=torch.float32, device=device)
    return torch.linalg.inv(c2w), K


def render(params, w2c, K, width: int, height: int, sh_degree: int):
    """One view: ([H, W, 3] image in [0, 1], gsplat's info for densification)."""
    import torch
    from gsplat import rasterization
    colors = torch.cat([params["sh0"], params["shN"]], 1)
    out, _, info = rasterization(params["means"], params["quats"], torch.exp(params["scales"]),
                                 torch.sigmoid(params["opacities"]), colors, w2c[None], K[None], int(width),
                                 int(height), sh_degree=sh_degree, packed=False)
    return out[0].clamp(0, 1), info


def train_splats(cfg: SplatConfig, cams: Cameras, images: Sequence, points, colors, box: tuple, seed: int = 0,
                 device: str | None = None, callback: Callable[[int], None] | None = None):
    """Train 3DGS on ``images`` (paths or arrays) seen by ``cams`` (at the cameras' sizes) -> (a model for
    :func:`render_view`, :class:`SplatStats`). ``device``: default CUDA (the CPU only where there is none: gsplat
    itself needs CUDA, the evaluation refuses the trainer first, :func:`unavailable`; tests run a stand-in).
    ``callback(step)`` after every step."""
    import torch
    from gsplat.strategy import DefaultStrategy
    from curate.field.train import check_cameras, load_image
    check_cameras(cams)
    dev = torch.device(device or ("cuda" if torch.cuda.is_available() else "cpu"))
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    imgs = [torch.from_numpy((load_image(im, int(cams.width[i]), int(cams.height[i])) * 255 + 0.5).astype(np.uint8))
            .to(dev) for i, im in enumerate(images)]            # uint8 on the device: a quarter of float32
    centres = cams.centres
    scene_scale = float(np.linalg.norm(centres - centres.mean(0), axis=1).max()) * 1.1 or 1.0
    xyz, rgb = initial_points(points, colors, box, cfg.init_points, seed)
    params, opts = _params(xyz, rgb, scene_scale, cfg.sh_degree, dev)
    strategy = DefaultStrategy(verbose=False)
    strategy.check_sanity(params, opts)
    state = strategy.initialize_state(scene_scale=scene_scale)
    w2c, K = _camera_tensors(cams, dev)
    t0 = time.perf_counter()
    for step in range(cfg.steps):
        i = int(rng.integers(len(cams)))
        img, info = render(params, w2c[i], K[i], cams.width[i], cams.height[i], min(step // 1000, cfg.sh_degree))
        gt = imgs[i].float() / 255.0
        strategy.step_pre_backward(params, opts, state, step, info)
        a, b = img.permute(2, 0, 1)[None], gt.permute(2, 0, 1)[None]
        loss = (1 - cfg.ssim_weight) * (img - gt).abs().mean() + cfg.ssim_weight * (1 - ssim_torch(a, b))
        loss.backward()
        strategy.step_post_backward(params, opts, state, step, info, packed=False)
        for o in opts.values():
            o.step()
            o.zero_grad(set_to_none=True)
        if callback is not None:
            callback(step + 1)
    if dev.type == "cuda":
        torch.cuda.synchronize()
    model = {"params": params, "sh_degree": cfg.sh_degree, "device": dev}
    return model, SplatStats(iters=cfg.steps, train_seconds=time.perf_counter() - t0,
                             n_gaussians=int(len(params["means"])))


def render_view(model, cams: Cameras, i: int) -> np.ndarray:
    """Camera ``i`` of ``cams`` rendered by a trained model: [H, W, 3] float32 in [0, 1]."""
    import torch
    w2c, K = _camera_tensors(cams[[i]], model["device"])
    with torch.no_grad():
        img, _ = render(model["params"], w2c[0], K[0], cams.width[i], cams.height[i], model["sh_degree"])
    return img.float().cpu().numpy()

