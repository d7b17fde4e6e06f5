"""Configuration of the radiance field and of its training (:mod:`curate.field.model`,
:mod:`curate.field.train`). A leaf module: importing it imports no torch."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Literal, get_args

if TYPE_CHECKING:
    import torch


@dataclass
class FieldConfig:
    """Configuration of :class:`RadianceField` and of its training (``curate.field.train``)."""

    res_schedule: tuple[int, ...] = (64, 96, 128)
    """Grid resolutions (nodes per axis over the contracted cube [-2, 2]^3), coarse to fine."""
    upsample_at: tuple[int, ...] = (400, 1200)
    """Iterations at which the grids grow to the next resolution of ``res_schedule``. Absolute, not a
    fraction of the run's iterations: at the default 800 iterations the last level (128) is never
    reached and the field trains at 64 then 96. Kept so on purpose: every figure of the evaluation
    rests on it, and reaching all three levels at 800 iterations (``(200, 600)``) gained +0.24 dB on the
    sample walk for 27% more training time (docs/speed.md#field-schedule)."""
    sh_degree: int = 0
    """Spherical-harmonic degree of the view-dependent colour (0: diffuse, 1 or 2). Each degree
    multiplies the colour lookups' cost (3 * (deg + 1)^2 channels)."""
    inner_frac: float = 0.75
    """Fraction of the grid (per axis) given to the scene box; the rest holds the contracted outside."""
    n_inner: int = 64
    """Samples per ray inside the scene box (uniform in depth) at the finest resolution; the
    coarser grids use proportionally fewer."""
    n_outer: int = 32
    """Samples per ray outside the box (uniform in disparity, i.e. in contracted space), at the
    finest resolution (fewer, by the square root of the resolution ratio, on coarser grids)."""
    trans_thresh: float = 1e-3
    """Training: samples whose transmittance is below this (hidden) get no gradient pass."""
    near: float = 0.02
    """Near plane as a fraction of the mean box half size."""
    far: float = 50.0
    """Far plane in box half sizes (contracts to 2 - 1/far)."""
    alpha_init: float = 1e-3
    """Initial opacity of one inner sample step (sets the density bias)."""
    color_thresh: float = 1e-4
    """Samples with a rendering weight below this add no colour (rendering skips their colour lookup; training
    looks it up and weights it 0, which costs less than taking their subset)."""
    prune_thresh: float = 2e-3
    """A cell whose opacity across one cell is below this is marked empty at occupancy updates."""
    prune_dilation: int = 2
    """Cells within this many cells of an occupied one stay active (Chebyshev distance)."""
    occ_update_every: int = 100
    """Iterations between occupancy-mask updates (0: never)."""
    occ_update_start: int = 100
    """First iteration with an occupancy update."""
    batch_rays: int = 4096
    """Rays per training iteration."""
    lr_density: float = 0.1
    """Adam learning rate of the density grid."""
    lr_color: float = 0.05
    """Adam learning rate of the SH colour grid."""
    lr_bg: float = 0.01
    """Adam learning rate of the background colour."""
    lr_decay_iters: int = 5000
    """Learning rates decay by 10x over this many iterations (exponentially; absolute like
    ``upsample_at``: at 800 iterations they end at 0.69x their start)."""
    tv_density: float = 1e-4
    """Weight of the total-variation loss on the density grid (the whole grid, every iteration)."""
    tv_color: float = 1e-5
    """Weight of the total-variation loss on the colour grid (random blocks)."""
    sparsity: float = 0.0
    """Weight of the Cauchy sparsity loss on sample optical depths (Plenoxels-style; pushes faint
    density in free space to zero, sharpening the occupancy). 0 disables."""
    tv_block: int = 24
    """Side in cells of the random block the TV losses are computed on each iteration."""
    val_every: int = 200
    """Iterations between validation renders (early stopping); 0 disables."""
    patience: int = 3
    """Stop after this many validations without a PSNR gain of ``min_delta``."""
    min_delta: float = 0.05
    """Validation PSNR gain (dB) that counts as progress."""
    device: str = "auto"
    """'auto' (CUDA when available, else CPU), 'cpu' or 'cuda'."""
    threads: int = 1
    """torch CPU threads (0: leave torch's default). 1 by default: on a shared 2-core machine,
    OpenMP threads competing with other processes made each iteration ~20x slower (measured)."""

    def resolve_device(self) -> "torch.device":
        """The torch device of :attr:`device` (imports torch)."""
        import torch
        if self.device == "auto":
            return torch.device("cuda" if torch.cuda.is_available() else "cpu")
        return torch.device(self.device)

    def to_dict(self) -> dict:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}

    @staticmethod
    def from_dict(d: dict) -> "FieldConfig":
        known = {f for f in FieldConfig.__dataclass_fields__}
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in known}
        return FieldConfig(**kw)


Trainer = Literal["field", "gsplat"]
TRAINERS = get_args(Trainer)
"""What the evaluation trains on each subset: curate's own radiance field (CPU or CUDA), or 3D Gaussian
splatting through the gsplat package (CUDA only; ``pip install 'curate[gsplat]'``)."""


@dataclass
class SplatConfig:
    """3D Gaussian splatting as the evaluation's trainer (``--trainer gsplat``, :mod:`curate.field.splat`): gsplat's
    rasterizer and its default densification, as its ``simple_trainer`` uses them."""

    steps: int = 7000
    """Training steps per subset (one photo a step; 7,000 is 3DGS's first checkpoint)."""
    max_side: int = 1600
    """Photos are trained and scored with their longer side at most this (pixels): the capture's own resolution up
    to the size SfM's working copies have; 0 keeps every photo as it is."""
    sh_degree: int = 3
    """Spherical-harmonic degree of the Gaussians' colour (one more every 1,000 steps, up to this)."""
    ssim_weight: float = 0.2
    """Loss: (1 - w) L1 + w (1 - SSIM), as 3DGS's."""
    init_points: int = 100_000
    """Gaussians to start from when the run has no sparse points (random in the scene box); with points, one
    per point."""

    def __post_init__(self) -> None:
        for name, lo in (("steps", 1), ("max_side", 0), ("sh_degree", 0), ("init_points", 1)):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < lo:
                raise ValueError(f"splat {name} must be an integer >= {lo}, got {v!r}")
        if not 0 <= self.ssim_weight <= 1:
            raise ValueError(f"splat ssim_weight must be in [0, 1], got {self.ssim_weight!r}")
