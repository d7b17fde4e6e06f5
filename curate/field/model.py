"""A grid radiance field that trains on a CPU in minutes (DirectVoxGO / Plenoxels style).

Scene parametrisation
---------------------
World points ``x`` are first normalised per axis into the scene box,
``n = (x - centre) / half_size`` (the box becomes ``[-1, 1]^3``), then contracted
(mip-NeRF 360 style, L-infinity norm) so that unbounded captures (a room, a fox on a
wall) fit in a finite grid::

    c(n) = n                                   if ||n||_inf <= 1
    c(n) = (2 - 1 / ||n||_inf) * n / ||n||_inf  otherwise          (c in [-2, 2]^3)

Two dense grids over the contracted cube ``[-2, 2]^3`` (``res^3`` nodes, trilinear
``grid_sample``, ``align_corners=True``; per axis the box ``[-1, 1]`` takes a fraction
``inner_frac`` = 0.75 of the nodes, the contracted outside the rest) hold the raw density (1 channel) and
spherical-harmonic colour coefficients (``3 * (deg + 1)^2`` channels). Density is
``softplus(raw + bias)`` (shifted softplus, clamped), colour ``sigmoid(SH(dir))``.
Rays leaving the grid see a learned constant background colour.

Sample spacing ``delta`` is measured in *contracted* space, so the density is "per
contracted unit": inside the box that is per ``half_size`` of world length.

Speed
-----
* an occupancy mask ``occ`` ([res, res, res] bool, same nodes as the grids) skips
  samples in empty cells before any grid lookup (they get zero density);
* only samples whose rendering weight exceeds ``color_thresh`` add their colour (DVGO's "fast
  colour threshold"): rendering looks colour up for those alone; training for every sample in an
  active cell, the others weighted 0, which costs less than taking the subset;
* training reads both grids through each sample's 8 corners (:func:`trilinear_corners`, once per
  batch), so that a lookup's gradient is an ``index_add``: ``grid_sample``'s CPU backward took 3-6
  times longer; rendering uses ``grid_sample``, whose forward is faster (docs/speed.md#trilinear);
* transmittance uses ``exp(-cumsum(sigma * delta))`` with ``sigma * delta`` clamped,
  which is stable for any density.
"""

from __future__ import annotations

import logging
import math
from typing import NamedTuple

import numpy as np
import torch
import torch.nn.functional as F

from curate.core.grid import NodeGrid
from curate.field.config import FieldConfig  # noqa: F401  (re-exported: the field's configuration)

log = logging.getLogger(__name__)

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
MAX_TAU = 30.0  # clamp on sigma * delta: exp(-30) ~ 1e-13, opaque for every purpose
MAX_RAW = 30.0  # clamp on the raw density before the softplus


def contract(n: torch.Tensor) -> torch.Tensor:
    """L-inf scene contraction: [..., 3] normalised points -> [..., 3] in [-2, 2]^3."""
    m = n.abs().amax(-1, keepdim=True).clamp_min(1e-9)
    return torch.where(m <= 1, n, (2 - 1 / m) * n / m)


def sh_basis(d: torch.Tensor, degree: int) -> torch.Tensor:
    """Real SH basis: unit directions [K, 3] -> [K, (degree + 1)^2]."""
    x, y, z = d.unbind(-1)
    out = [torch.full_like(x, SH_C0)]
    if degree >= 1:
        out += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if degree >= 2:
        out += [SH_C2[0] * x * y, SH_C2[1] * y * z, SH_C2[2] * (2 * z * z - x * x - y * y),
                SH_C2[3] * x * z, SH_C2[4] * (x * x - y * y)]
    return torch.stack(out, -1)


def composite_weights(sigma: torch.Tensor, delta: torch.Tensor) -> torch.Tensor:
    """Volume-rendering weights ``w_i = T_i * (1 - exp(-sigma_i * delta_i))`` with
    ``T_i = exp(-sum_{j<i} sigma_j * delta_j)``; ``sigma * delta`` clamped to ``MAX_TAU``.

    sigma, delta: [B, S] (non-negative) -> w: [B, S]; ``1 - w.sum(1)`` is the transmittance
    left for the background.
    """
    tau = (sigma * delta).clamp(min=0, max=MAX_TAU)
    T = torch.exp(-(torch.cumsum(tau, 1) - tau))
    return T * (1 - torch.exp(-tau))


class Corners(NamedTuple):
    """The 8 grid nodes around K points and their trilinear weights (:func:`trilinear_corners`)."""

    idx: torch.Tensor
    """[8, K] int64 flat node indices into a grid stored [z, y, x]."""
    w: torch.Tensor
    """[8, K] weights (each column sums to 1)."""

    def subset(self, k: torch.Tensor) -> "Corners":
        """The corners of points ``k`` ([K'] int64 indices into the K points)."""
        return Corners(self.idx[:, k], self.w[:, k])


def trilinear_corners(g: torch.Tensor, res: int) -> Corners:
    """The 8 nodes of a ``res``^3 grid around grid coordinates ``g`` [K, 3] ((x, y, z) in [-1, 1], the first and
    last node at -1 and 1: ``grid_sample``'s ``align_corners=True``), and their trilinear weights. Coordinates
    outside [-1, 1] are clamped to it."""
    p = ((g.t() + 1) * (0.5 * (res - 1))).clamp_(0, res - 1)        # [3, K] in node units
    p0 = p.floor().clamp_(max=res - 2)
    f = p - p0
    i0 = p0.long()
    base = (i0[2] * res + i0[1]) * res + i0[0]
    r2 = res * res
    offs = torch.tensor([0, 1, res, res + 1, r2, r2 + 1, r2 + res, r2 + res + 1], device=g.device)
    fx, fy, fz = f
    gx, gy, gz = 1 - f
    wyx = torch.stack([gy * gx, gy * fx, fy * gx, fy * fx])        # [4, K], in the order of offs
    return Corners(base[None] + offs[:, None], (torch.stack([gz, fz])[:, None] * wyx[None]).reshape(8, -1))


def trilinear(grid: torch.Tensor, cn: Corners) -> torch.Tensor:
    """A grid [1, C, R, R, R] interpolated at the corners' points -> [C, K].

    What ``grid_sample(mode="bilinear", align_corners=True)`` computes, to float rounding, with gradients to
    the grid by ``index_add`` instead of its CPU backward, which is 3-6 times slower (docs/speed.md#trilinear)."""
    c = grid.shape[1]
    v = grid.reshape(c, -1).index_select(1, cn.idx.reshape(-1)).reshape(c, 8, -1)
    return (v * cn.w).sum(1)


def ray_box(o: torch.Tensor, d: torch.Tensor, lo: float = -1.0, hi: float = 1.0):
    """Slab test. o, d: [B, 3] -> (t_enter [B], t_exit [B]); t_exit < t_enter for a miss."""
    inv = 1.0 / torch.where(d.abs() < 1e-12, torch.full_like(d, 1e-12), d)
    t0, t1 = (lo - o) * inv, (hi - o) * inv
    return torch.minimum(t0, t1).amax(-1), torch.maximum(t0, t1).amin(-1)


class RadianceField(torch.nn.Module):
    """Density + SH colour grids over a contracted scene box; see the module docstring.

    Args:
        cfg: the configuration.
        box_min, box_max: [3] world corners of the scene box (the uncontracted region).
    """

    def __init__(self, cfg: FieldConfig, box_min, box_max):
        super().__init__()
        lo = np.asarray(box_min, np.float64).reshape(3)
        hi = np.asarray(box_max, np.float64).reshape(3)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi - lo <= 0):
            raise ValueError(f"degenerate scene box {lo} .. {hi}")
        if not 0 < cfg.inner_frac < 1:
            raise ValueError("inner_frac must be in (0, 1)")
        if cfg.sh_degree not in (0, 1, 2):
            raise ValueError("sh_degree must be 0, 1 or 2")
        if not cfg.res_schedule or min(cfg.res_schedule) < 2:
            raise ValueError("res_schedule needs resolutions >= 2")
        self.cfg = cfg
        self.register_buffer("centre", torch.tensor(0.5 * (lo + hi), dtype=torch.float32))  # [3]
        self.register_buffer("half_size", torch.tensor(0.5 * (hi - lo), dtype=torch.float32))  # [3]
        r = int(cfg.res_schedule[0])
        inner_step = 2.0 / max(cfg.n_inner, 1)  # at the finest resolution
        # softplus(bias) * inner_step = -log(1 - alpha_init)
        target = -math.log(1 - cfg.alpha_init) / inner_step
        self.bias = float(math.log(math.expm1(target)))
        self.n_sh = (cfg.sh_degree + 1) ** 2
        self.density = torch.nn.Parameter(torch.zeros(1, 1, r, r, r))  # [1, 1, R, R, R] raw density
        self.color = torch.nn.Parameter(torch.zeros(1, 3 * self.n_sh, r, r, r))  # [1, 3*n_sh, R, R, R]
        self.bg = torch.nn.Parameter(torch.zeros(3))  # [3] raw background colour (sigmoid)
        self.register_buffer("occ", torch.ones(r, r, r, dtype=torch.bool))  # [R, R, R] active cells

    # ------------------------------------------------------------------ geometry
    @property
    def res(self) -> int:
        return int(self.density.shape[-1])

    def normalise(self, x: torch.Tensor) -> torch.Tensor:
        """World points [..., 3] -> box-normalised points [..., 3] (box = [-1, 1]^3)."""
        return (x - self.centre) / self.half_size

    def to_unit(self, c: torch.Tensor) -> torch.Tensor:
        """Contracted points [..., 3] -> grid coordinates in [-1, 1] (per axis piecewise linear:
        the box [-1, 1] takes ``inner_frac`` of the grid, the contracted outside the rest)."""
        f = self.cfg.inner_frac
        a = c.abs()
        return torch.where(a <= 1, f * c, torch.sign(c) * (f + (1 - f) * (a - 1)))

    def from_unit(self, g: torch.Tensor) -> torch.Tensor:
        """Inverse of :meth:`to_unit`: grid coordinates [..., 3] -> contracted points."""
        f = self.cfg.inner_frac
        a = g.abs()
        return torch.where(a <= f, g / f, torch.sign(g) * (1 + (a - f) / (1 - f)))

    def node_contracted(self) -> torch.Tensor:
        """[R, R, R, 3] contracted (x, y, z) coordinates of every grid node, in the grids' layout:
        node ``[k, j, i]`` is at x index i, y index j, z index k (grids are stored ``[1, C, Z, Y, X]``
        so that ``grid_sample`` takes (x, y, z) coordinates as they are)."""
        ax = torch.linspace(-1, 1, self.res, device=self.density.device)
        gz, gy, gx = torch.meshgrid(ax, ax, ax, indexing="ij")
        return self.from_unit(torch.stack([gx, gy, gz], -1))

    def _occ_lookup_unit(self, g: torch.Tensor) -> torch.Tensor:
        """Grid coordinates [..., 3] in [-1, 1] -> [...] bool, True where the nearest cell is active."""
        r = self.res
        idx = ((g + 1) * (0.5 * (r - 1))).round().long().clamp_(0, r - 1)
        flat = (idx[..., 2] * r + idx[..., 1]) * r + idx[..., 0]
        return self.occ.reshape(-1)[flat]

    def _occ_lookup(self, c: torch.Tensor) -> torch.Tensor:
        """Contracted points [..., 3] -> [...] bool, True where the nearest cell is active."""
        return self._occ_lookup_unit(self.to_unit(c))

    def _lookup(self, grid: torch.Tensor, c: "torch.Tensor | Corners", unit: bool) -> torch.Tensor:
        """``grid`` [1, C, R, R, R] at contracted points [K, 3] (grid coordinates when ``unit``), or at
        :class:`Corners` of this grid's resolution -> [C, K]."""
        if isinstance(c, Corners):
            return trilinear(grid, c)
        g = (c if unit else self.to_unit(c)).reshape(1, 1, 1, -1, 3)
        return F.grid_sample(grid, g, mode="bilinear", align_corners=True).reshape(grid.shape[1], -1)

    def sigma_at(self, c: "torch.Tensor | Corners", unit: bool = False) -> torch.Tensor:
        """Density per contracted unit at contracted points [K, 3] (grid coordinates when ``unit``, or their
        :func:`trilinear_corners`) -> [K]."""
        raw = self._lookup(self.density, c, unit).reshape(-1)
        return F.softplus(raw.clamp(max=MAX_RAW) + self.bias)

    def rgb_at(self, c: "torch.Tensor | Corners", d: torch.Tensor, unit: bool = False) -> torch.Tensor:
        """Colour at contracted points [K, 3] (grid coordinates when ``unit``, or their corners) seen along unit
        world directions [K, 3] -> [K, 3]."""
        coef = self._lookup(self.color, c, unit).reshape(3, self.n_sh, -1)  # [3, n_sh, K]
        basis = sh_basis(d, self.cfg.sh_degree).T  # [n_sh, K]
        return torch.sigmoid((coef * basis[None]).sum(1).T)

    def density_world(self, x: np.ndarray | torch.Tensor, chunk: int = 1 << 18) -> np.ndarray:
        """Density per *world* unit at world points [M, 3] -> [M] float (inside the box exact up to
        the per-axis scale, which is approximated by the geometric mean of the half sizes)."""
        x = torch.as_tensor(np.asarray(x), dtype=torch.float32, device=self.centre.device)
        out = []
        with torch.no_grad():
            for s in range(0, x.shape[0], chunk):
                c = contract(self.normalise(x[s:s + chunk]))
                sig = self.sigma_at(c) * self._occ_lookup(c)
                out.append(sig)
        g = float(torch.prod(self.half_size).item()) ** (1 / 3)
        return (torch.cat(out) / g).cpu().numpy() if out else np.zeros(0)

    # ------------------------------------------------------------------ rendering
    def sample(self, o: torch.Tensor, d: torch.Tensor, jitter: torch.Generator | None = None):
        """Sample points along rays.

        Args:
            o, d: [B, 3] world origins and unit directions.
            jitter: a generator for stratified jitter (training), None for midpoints.
        Returns:
            t: [B, S] depths (world units along d), c: [B, S, 3] contracted points,
            delta: [B, S] spacing in contracted space.
        """
        cfg = self.cfg
        on, dn = self.normalise(o), d / self.half_size  # normalised ray: x_n = on + t * dn
        mean_half = float(self.half_size.mean())
        near = cfg.near * mean_half
        t_in, t_out = ray_box(on, dn)
        hit = t_out > torch.clamp(t_in, min=near)
        t0 = torch.where(hit, torch.clamp(t_in, min=near), torch.full_like(t_in, near))
        t1 = torch.where(hit, t_out, t0)
        B = o.shape[0]
        scale = self.res / max(cfg.res_schedule)  # fewer samples on the coarse grids
        S1 = max(8, int(round(cfg.n_inner * scale)))
        S2 = max(4, int(round(cfg.n_outer * math.sqrt(scale))))
        if jitter is None:
            u1 = torch.full((B, S1), 0.5, device=o.device)
            u2 = torch.full((B, S2), 0.5, device=o.device)
        else:
            # drawn on the generator's device (CPU) then moved: same numbers on CPU and CUDA
            u1 = torch.rand((B, S1), generator=jitter, device=jitter.device).to(o.device)
            u2 = torch.rand((B, S2), generator=jitter, device=jitter.device).to(o.device)
        s1 = (torch.arange(S1, device=o.device) + u1) / S1  # [B, S1] in (0, 1)
        t_inner = t0[:, None] + (t1 - t0)[:, None] * s1
        tf = torch.maximum(t1 * 1.01, t1 + cfg.far * mean_half)
        s2 = (torch.arange(S2, device=o.device) + u2) / S2
        inv = 1 / t1.clamp_min(1e-6)
        t_outer = 1 / (inv[:, None] + (1 / tf - inv)[:, None] * s2)  # uniform in disparity
        t = torch.cat([t_inner, t_outer], 1)  # [B, S]
        c = contract(on[:, None, :] + t[..., None] * dn[:, None, :])  # [B, S, 3]
        gap = (c[:, 1:] - c[:, :-1]).norm(dim=-1)
        delta = torch.cat([gap, gap[:, -1:]], 1)
        return t, c, delta

    def render_rays(self, o: torch.Tensor, d: torch.Tensor, jitter: torch.Generator | None = None,
                    bg_override: torch.Tensor | None = None) -> dict:
        """Volume-render rays. o, d: [B, 3] world origins and unit directions.

        Returns a dict: ``rgb`` [B, 3], ``depth`` [B] (expected depth, world units),
        ``acc`` [B] (opacity), ``sparsity`` (scalar: mean over rays of the summed Cauchy penalty
        ``log(1 + (tau / 0.05)^2)`` of the samples' optical depths; zero unless ``cfg.sparsity``),
        ``n_density`` / ``n_color`` (samples evaluated).
        """
        B = o.shape[0]
        t, c, delta = self.sample(o, d, jitter)
        g = self.to_unit(c).reshape(-1, 3)  # [B*S, 3] grid coordinates
        fl = self._occ_lookup_unit(g).nonzero().squeeze(1)  # [K0] samples in active cells
        # training: the corners once for the density and the colour, a lookup's gradient an index_add (grid_sample's
        # CPU backward is 3-6 times slower); rendering: grid_sample, whose forward is faster (docs/speed.md#trilinear)
        at = trilinear_corners(g[fl], self.res) if torch.is_grad_enabled() else g[fl]
        S = t.shape[1]
        if torch.is_grad_enabled() and self.cfg.trans_thresh > 0:
            # pass 1 without gradients: drop samples hidden behind opaque ones (T < trans_thresh);
            # they form a suffix of each ray, so the prefix's transmittance stays exact in pass 2
            with torch.no_grad():
                sg = torch.zeros(B * S, device=o.device).index_put((fl,), self.sigma_at(at, unit=True))
                tau0 = (sg.reshape(B, S) * delta).clamp(max=MAX_TAU)
                T0 = torch.exp(-(torch.cumsum(tau0, 1) - tau0))
                kept = (T0.reshape(-1)[fl] > self.cfg.trans_thresh).nonzero().squeeze(1)
            flat, at = fl[kept], at.subset(kept)  # [K]; at: Corners, gradients are on
        else:
            flat = fl
        sig_k = self.sigma_at(at, unit=True)
        sigma = torch.zeros(B * S, device=o.device, dtype=sig_k.dtype).index_put((flat,), sig_k).reshape(B, S)
        w = composite_weights(sigma, delta)  # [B, S]
        acc = w.sum(1)
        tau = (sigma * delta).clamp(max=MAX_TAU)
        sparsity = torch.log1p((tau / 0.05) ** 2).sum(1).mean() if self.cfg.sparsity > 0 else tau.new_zeros(())
        wf = w.reshape(-1)
        wk = wf[flat]
        lit = wk > self.cfg.color_thresh   # a sample outside flat weighs 0
        if isinstance(at, Corners):   # training: every sample's colour, the unlit weighted 0 (cheaper than a subset)
            sel, wk = flat, torch.where(lit, wk, 0.0)
            n_color = int(lit.sum())
        else:
            k = lit.nonzero().squeeze(1)
            sel, wk, at = flat[k], wk[k], at[k]
            n_color = int(k.numel())
        ray_idx = torch.div(sel, S, rounding_mode="floor")
        rgb_k = self.rgb_at(at, d[ray_idx], unit=True)
        rgb = torch.zeros(B, 3, device=o.device, dtype=rgb_k.dtype).index_add(0, ray_idx, wk[:, None] * rgb_k)
        bg = torch.sigmoid(self.bg) if bg_override is None else bg_override
        rgb = rgb + (1 - acc)[:, None].clamp(0, 1) * bg
        depth = (w * t).sum(1) + (1 - acc).clamp(0, 1) * t[:, -1]
        return {"rgb": rgb, "depth": depth, "acc": acc, "sparsity": sparsity, "n_density": int(flat.numel()),
                "n_color": n_color}

    # ------------------------------------------------------------------ training helpers
    @torch.no_grad()
    def upsample(self, res: int) -> None:
        """Grow both grids (and the occupancy mask) to ``res`` nodes per axis (trilinear)."""
        size = (res, res, res)
        self.density = torch.nn.Parameter(F.interpolate(self.density.data, size=size, mode="trilinear",
                                                        align_corners=True))
        self.color = torch.nn.Parameter(F.interpolate(self.color.data, size=size, mode="trilinear",
                                                      align_corners=True))
        occ = F.interpolate(self.occ.float()[None, None], size=size, mode="trilinear", align_corners=True)
        self.occ = F.max_pool3d(occ, 3, 1, 1)[0, 0] > 0
        log.info("grids upsampled to %d^3, %.1f%% cells active", res, 100 * self.occ.float().mean().item())

    @torch.no_grad()
    def update_occupancy(self, prior: torch.Tensor | None = None) -> float:
        """Mark empty the cells whose opacity across one cell is below ``prune_thresh`` (dilated by
        ``prune_dilation``); cells already empty stay empty. Returns the active fraction."""
        f, step = self.cfg.inner_frac, 2.0 / (self.res - 1)  # node spacing in grid units
        inner = self.node_contracted().abs().amax(-1) <= 1
        cell = torch.where(inner, step / f, step / (1 - f))  # [R, R, R] cell side in contracted units
        sig = F.softplus(self.density.clamp(max=MAX_RAW) + self.bias)[0, 0]
        alive = (1 - torch.exp(-sig * cell)) > self.cfg.prune_thresh
        k = self.cfg.prune_dilation
        if k > 0:
            alive = F.max_pool3d(alive.float()[None, None], 2 * k + 1, 1, k)[0, 0] > 0
        self.occ &= alive
        if prior is not None:
            self.occ &= prior
        return float(self.occ.float().mean())

    def tv_loss(self, gen: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Total variation (mean squared neighbour difference): density over the whole grid, colour
        on one random block (``tv_block`` cells a side)."""
        r, b = self.res, min(self.cfg.tv_block, self.res)
        i = torch.randint(0, r - b + 1, (3,), generator=gen).tolist()
        out = []
        for g in (self.density, self.color[:, :, i[0]:i[0] + b, i[1]:i[1] + b, i[2]:i[2] + b]):
            blk = g
            tv = ((blk[:, :, 1:] - blk[:, :, :-1]) ** 2).mean() + ((blk[:, :, :, 1:] - blk[:, :, :, :-1]) ** 2).mean() \
                + ((blk[..., 1:] - blk[..., :-1]) ** 2).mean()
            out.append(tv)
        return out[0], out[1]

    # ------------------------------------------------------------------ checkpoints
    def save(self, path) -> None:
        """Checkpoint: state_dict + config + box (``torch.load`` -> :meth:`load`)."""
        lo = (self.centre - self.half_size).tolist()
        hi = (self.centre + self.half_size).tolist()
        from curate.core.stage import writing
        # through a file of ours: a full disk is an OSError naming the file (torch's own writer says only
        # "[enforce fail at inline_container.cc:672] ... file write failed")
        with writing(path), open(path, "wb") as f:
            torch.save({"config": self.cfg.to_dict(), "box_min": lo, "box_max": hi,
                        "state_dict": {k: v.detach().cpu() for k, v in self.state_dict().items()}}, f)

    @staticmethod
    def load(path, device: str | torch.device = "cpu") -> "RadianceField":
        try:
            ck = torch.load(path, map_location="cpu", weights_only=True)
        except (RuntimeError, EOFError) as e:      # truncated (a full disk, a copy cut short), or not a field
            raise ValueError(f"{path}: not a whole field checkpoint of curate ({str(e).splitlines()[0][:120]}); the "
                             "stage that wrote it writes it again with --force") from None
        cfg = FieldConfig.from_dict(ck["config"])
        f = RadianceField(cfg, ck["box_min"], ck["box_max"])
        r = ck["state_dict"]["density"].shape[-1]
        if r != f.res:
            f.upsample(r)
        f.load_state_dict(ck["state_dict"])
        return f.to(device)


def prior_mask(field, grid: NodeGrid) -> torch.Tensor:
    """The field's [res, res, res] cells allowed by an occupancy NodeGrid (world frame).

    Cells of the field's inner box whose world position is on an unoccupied node of
    ``grid`` (or outside ``grid``'s box, within the field's box) are False; cells of
    the contracted outer region stay True.
    """
    r = field.res
    c = field.node_contracted().cpu()  # [r, r, r, 3] contracted
    inner = c.abs().amax(-1) <= 1
    world = (c * field.half_size.cpu() + field.centre.cpu()).numpy().reshape(-1, 3)
    m = grid.mask if grid.mask is not None else np.ones((grid.res,) * 3, bool)
    g = grid.res
    span = np.where(grid.box_max > grid.box_min, grid.box_max - grid.box_min, 1.0)
    idx = np.round((world - grid.box_min) / span * (g - 1)).astype(np.int64)
    ok = np.all((idx >= 0) & (idx < g), axis=1)
    val = np.zeros(len(world), bool)
    val[ok] = m[tuple(idx[ok].T)]
    out = torch.from_numpy(val.reshape(r, r, r)) | ~inner
    return out.to(field.occ.device)
