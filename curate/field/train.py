"""Train a :class:`curate.field.model.RadianceField` on posed images, within a time or iteration budget.

Images are loaded and downscaled once to the cameras' sizes (pass
``cams.scaled_images(1/8)`` for 1/8 resolution), every pixel's ray is built once and
cached as float32 tensors, and random batches of rays are drawn from all images.
Training stops at the first of: ``iters`` iterations, ``time_budget_s`` seconds of
training (validation and callbacks excluded), or a validation PSNR plateau
(``FieldConfig.patience``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field as dc_field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from curate.core.cameras import Cameras
from curate.field.model import FieldConfig, RadianceField, prior_mask
from curate.core.grid import NodeGrid, box_from_cameras, focus_point
from curate.field.metrics import camera_rays, psnr, render_image

log = logging.getLogger(__name__)


def load_image(src, width: int, height: int) -> np.ndarray:
    """One image (path, or [H, W, 3] uint8 / float array) -> [height, width, 3] float32 in [0, 1]."""
    from PIL import Image
    if isinstance(src, (str, Path)):
        from curate.core.images import decode_upright   # the one decoder: EXIF orientation, 16-bit, grey, CMYK
        try:
            with Image.open(src) as im:
                return decode_upright(im, (width, height)).astype(np.float32) / 255.0
        except OSError as e:
            raise ValueError(f"{src}: cannot decode ({type(e).__name__}: {e})") from None
    arr = np.asarray(src)
    if arr.ndim != 3 or arr.shape[2] < 3:
        raise ValueError(f"image must be [H, W, 3], got {arr.shape}")
    arr = arr[..., :3]
    arr = arr.astype(np.float32) / 255.0 if arr.dtype == np.uint8 else arr.astype(np.float32)
    if arr.shape[:2] != (height, width):
        from skimage.transform import resize
        arr = resize(arr, (height, width), anti_aliasing=True, preserve_range=True).astype(np.float32)
    return arr


def load_images(images: Sequence, cams: Cameras, progress: bool = False) -> list[np.ndarray]:
    """Every image at its camera's size: list of [H_i, W_i, 3] float32 (``progress``: a bar, shown
    only when loading takes more than a second)."""
    if len(images) != len(cams):
        raise ValueError(f"{len(images)} images for {len(cams)} cameras")
    return [load_image(im, int(cams.width[i]), int(cams.height[i]))
            for i, im in enumerate(tqdm(images, desc="load images", leave=False, delay=1.0, disable=not progress))]


def default_box(cams: Cameras, object_cover: float = 0.9, margin: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """A field box from the cameras alone.

    Object capture (most cameras look at a common focus point): a cube around the focus
    whose half side is ``object_cover`` x the half extent a median camera sees at the focus
    distance (distance x tan of half its larger field of view), so that what the cameras
    see around the object (a wall behind it) is mostly inside the box. Otherwise (a walk
    through a room): the box of the camera centres padded by ``margin`` of its largest side
    (``curate.core.grid.box_from_cameras``). The contraction covers everything beyond.
    """
    f = focus_point(cams)
    if f is not None:
        to_f = f[None] - cams.centres
        dist = np.linalg.norm(to_f, axis=1)
        cos = np.einsum("ij,ij->i", to_f / np.maximum(dist[:, None], 1e-12), cams.view_dirs)
        if np.mean(cos > 0.8) > 0.7:
            half_fov = np.maximum(cams.width / (2 * cams.fx), cams.height / (2 * cams.fy))  # tan
            r = object_cover * float(np.median(dist * half_fov))
            return f - r, f + r
    return box_from_cameras(cams, margin)


def check_cameras(cams: Cameras) -> None:
    """ValueError for inputs a radiance field cannot be trained on."""
    if len(cams) < 2:
        raise ValueError(f"a radiance field needs at least 2 training images, got {len(cams)}")
    c = cams.centres
    spread = float(np.linalg.norm(c - c.mean(0), axis=1).max())
    if spread < 1e-6 * max(1.0, float(np.abs(c).max())):
        raise ValueError("all cameras are at one point: no parallax, the scene's depth cannot be learned")


@dataclass
class TrainStats:
    """What a training run did."""

    iters: int = 0
    """Iterations run."""
    train_seconds: float = 0.0
    """Seconds of training (validation and callbacks excluded)."""
    rays_per_s: float = 0.0
    """Training throughput."""
    stop_reason: str = ""
    """'iters', 'time' or 'plateau'."""
    loss: list = dc_field(default_factory=list)
    """(iteration, train_seconds, batch MSE) every 50 iterations."""
    val: list = dc_field(default_factory=list)
    """(iteration, train_seconds, validation PSNR)."""
    occupancy: list = dc_field(default_factory=list)
    """(iteration, active cell fraction) at each occupancy update."""
    samples_per_ray: float = 0.0
    """Mean density lookups per ray (after empty-space skipping), last 50 iterations."""


def _optimizer(f: RadianceField, cfg: FieldConfig) -> torch.optim.Optimizer:
    groups = [{"params": [f.density], "lr": cfg.lr_density, "base": cfg.lr_density},
              {"params": [f.color], "lr": cfg.lr_color, "base": cfg.lr_color},
              {"params": [f.bg], "lr": cfg.lr_bg, "base": cfg.lr_bg}]
    try:
        return torch.optim.Adam(groups, betas=(0.9, 0.99), eps=1e-15, fused=True)
    except (RuntimeError, TypeError):
        return torch.optim.Adam(groups, betas=(0.9, 0.99), eps=1e-15)


def _default_val(cams: Cameras, images: list[np.ndarray], n: int = 2):
    idx = np.linspace(0, len(cams) - 1, min(n, len(cams))).round().astype(int)
    vc = cams[idx].scaled_images(0.5)
    vi = [load_image(images[i], int(vc.width[k]), int(vc.height[k])) for k, i in enumerate(idx)]
    return vc, vi


def train_field(cfg: FieldConfig, cams: Cameras, images: Sequence, run_dir: str | Path | None = None,
                time_budget_s: float | None = None, iters: int | None = None,
                val_cams: Cameras | None = None, val_images: Sequence | None = None, seed: int = 0,
                box: tuple | None = None, prior: NodeGrid | None = None,
                callback: Callable[[int, float, RadianceField], None] | None = None,
                ckpt_name: str = "field.pt", init: RadianceField | None = None,
                start_iter: int = 0, progress_desc: str | None = None) -> tuple[RadianceField, TrainStats]:
    """Train a field on ``images`` seen by ``cams`` (at the cameras' sizes).

    Args:
        cfg: field and training configuration.
        cams: N training cameras; images are resized to ``cams.width/height``.
        images: N paths or [H, W, 3] arrays.
        run_dir: the checkpoint ``run_dir/field.pt`` (or ``run_dir`` itself when it ends
            in ``.pt``) is written there at the end; None writes nothing.
        time_budget_s, iters: budgets (None: unlimited; at least one should be set,
            else 20000 iterations).
        val_cams, val_images: validation views for early stopping (default: 2 training
            views at half resolution).
        seed: seeds torch and the ray/jitter generator (same seed -> same weights).
        box: (box_min [3], box_max [3]) world scene box; default :func:`default_box`.
        prior: an occupancy NodeGrid (``curate.occupancy.masks``); cells of the box outside its
            mask are never sampled.
        callback: ``callback(iteration, train_seconds, field)`` after every iteration
            (its time is not counted; used to evaluate along the way).
        init, start_iter: resume. ``init`` is trained further in place (its box is kept;
            ``box`` must be None or equal to it) as if this call were iterations
            ``start_iter .. start_iter + iters`` of one run: the learning-rate decay, the
            upsampling schedule (a field coarser than the schedule at ``start_iter`` is
            upsampled at once) and the occupancy-update schedule continue from there, and
            ``iters``, ``time_budget_s`` and ``stats.iters`` count this call only. Differences
            from one uninterrupted run: the Adam optimizer is re-created (its moments restart,
            as they already do at every upsampling); the field's empty-space mask is reset to
            all cells active, since the images of this call may see space pruned before, and
            is first re-pruned ``occ_update_start`` iterations after ``start_iter``; the
            ray/jitter generator restarts from ``seed`` (pass a different seed per call).
            Validation / early stopping work as usual (``cfg.val_every = 0`` turns them off).
        progress_desc: show a progress bar with this label (None: only with INFO logging).
    Returns:
        (field, stats).
    """
    if init is not None and not isinstance(init, RadianceField):
        raise TypeError(f"init must be a RadianceField, got {type(init).__name__}")
    if int(start_iter) != start_iter or start_iter < 0:
        raise ValueError(f"start_iter must be a non-negative integer, got {start_iter!r}")
    if start_iter and init is None:
        raise ValueError("start_iter > 0 resumes a field: pass it as init")
    start_iter = int(start_iter)
    check_cameras(cams)
    if iters is None and time_budget_s is None:
        iters = 20000
    dev = cfg.resolve_device()
    if cfg.threads > 0:
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(seed)
    gen = torch.Generator(device="cpu").manual_seed(seed)
    imgs = load_images(images, cams, progress=progress_desc is not None)
    if val_cams is None:
        val_cams, val_imgs = _default_val(cams, imgs)
    else:
        val_imgs = load_images(val_images if val_images is not None else [], val_cams)

    # every pixel's ray, cached once
    O, D = zip(*(camera_rays(cams, i) for i in range(len(cams))))
    O, D = torch.cat(O).to(dev), torch.cat(D).to(dev)  # [NR, 3]
    RGB = torch.as_tensor(np.concatenate([im.reshape(-1, 3) for im in imgs]), device=dev)  # [NR, 3]
    n_rays = O.shape[0]

    if init is not None:
        lo = (init.centre - init.half_size).detach().cpu().numpy().astype(np.float64)
        hi = (init.centre + init.half_size).detach().cpu().numpy().astype(np.float64)
        if box is not None and not (np.allclose(box[0], lo, atol=1e-5) and np.allclose(box[1], hi, atol=1e-5)):
            raise ValueError(f"box {box} differs from the resumed field's box {lo} .. {hi}")
        fld = init.to(dev)
        # the upsampling the schedule has done by start_iter (none if the field is already finer)
        done = [r for at, r in zip(cfg.upsample_at, cfg.res_schedule[1:]) if at < start_iter and r > fld.res]
        if done:
            fld.upsample(max(done))
        fld.occ.fill_(True)  # new images may see space pruned before
    else:
        lo, hi = box if box is not None else default_box(cams)
        fld = RadianceField(cfg, lo, hi).to(dev)
    if prior is not None and prior.mask is not None and not prior.mask.any():
        raise ValueError("the occupancy prior is empty: nothing to train")
    pm = prior_mask(fld, prior) if prior is not None else None
    if pm is not None:
        fld.occ &= pm
    opt = _optimizer(fld, cfg)
    log.info("training field: %d images, %d rays, box %s .. %s, device %s", len(cams), n_rays,
             np.round(lo, 3), np.round(hi, 3), dev)

    st = TrainStats()
    best, bad, train_s, it = -np.inf, 0, 0.0, start_iter
    n_dens = 0
    ups = list(zip(cfg.upsample_at, cfg.res_schedule[1:]))
    if init is not None:
        ups = [(at, r) for at, r in ups if at >= start_iter and r > fld.res]
    occ_start = cfg.occ_update_start + (start_iter if init is not None else 0)
    pbar = tqdm(total=iters, desc=progress_desc or "train field", leave=False,
                disable=progress_desc is None and not log.isEnabledFor(logging.INFO))
    while True:
        if iters is not None and it - start_iter >= iters:
            st.stop_reason = "iters"
            break
        if time_budget_s is not None and train_s >= time_budget_s:
            st.stop_reason = "time"
            break
        t0 = time.perf_counter()
        if ups and it == ups[0][0]:
            fld.upsample(ups.pop(0)[1])
            if pm is not None:
                pm = prior_mask(fld, prior)
                fld.occ &= pm
            opt = _optimizer(fld, cfg)
        if cfg.occ_update_every and it >= occ_start and (it - occ_start) % cfg.occ_update_every == 0:
            st.occupancy.append((it, fld.update_occupancy(pm)))
        decay = 0.1 ** (it / max(cfg.lr_decay_iters, 1))
        for g in opt.param_groups:
            g["lr"] = g["base"] * decay
        idx = torch.randint(0, n_rays, (cfg.batch_rays,), generator=gen).to(dev)
        out = fld.render_rays(O[idx], D[idx], jitter=gen)
        mse = F.mse_loss(out["rgb"], RGB[idx])
        loss = mse + cfg.sparsity * out["sparsity"] if cfg.sparsity > 0 else mse
        if cfg.tv_density > 0 or cfg.tv_color > 0:
            tvd, tvc = fld.tv_loss(gen)
            loss = loss + cfg.tv_density * tvd + cfg.tv_color * tvc
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        n_dens += out["n_density"]
        it += 1
        train_s += time.perf_counter() - t0
        pbar.update(1)
        if it % 50 == 0:
            st.loss.append((it, round(train_s, 3), float(mse.detach())))
            st.samples_per_ray = n_dens / (50 * cfg.batch_rays)
            n_dens = 0
            pbar.set_postfix(psnr=f"{-10 * np.log10(max(float(mse.detach()), 1e-10)):.2f}",
                             rps=f"{(it - start_iter) * cfg.batch_rays / train_s:.0f}", spr=f"{st.samples_per_ray:.1f}",
                             occ=f"{float(fld.occ.float().mean()):.3f}")
        if not np.isfinite(float(mse.detach())):
            raise FloatingPointError(f"non-finite loss at iteration {it}")
        if callback is not None:
            callback(it, train_s, fld)
        if cfg.val_every and it % cfg.val_every == 0 and len(val_cams):
            p = float(np.mean([psnr(render_image(fld, val_cams, k), val_imgs[k]) for k in range(len(val_cams))]))
            st.val.append((it, round(train_s, 3), p))
            log.info("it %d  %.1fs  val PSNR %.2f  active %.1f%%", it, train_s, p, 100 * fld.occ.float().mean())
            if p > best + cfg.min_delta:
                best, bad = p, 0
            else:
                bad += 1
                if cfg.patience and bad >= cfg.patience:
                    st.stop_reason = "plateau"
                    break
    pbar.close()
    st.iters, st.train_seconds = it - start_iter, train_s
    st.rays_per_s = st.iters * cfg.batch_rays / max(train_s, 1e-9)
    log.info("trained %d iterations in %.1fs (%.0f rays/s, %.1f density samples/ray), stop: %s",
             it, train_s, st.rays_per_s, st.samples_per_ray, st.stop_reason)
    if run_dir is not None:
        p = Path(run_dir)
        p = p if p.suffix == ".pt" else p / ckpt_name
        p.parent.mkdir(parents=True, exist_ok=True)
        fld.save(p)
    return fld, st
