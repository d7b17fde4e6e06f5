"""Direction bins on the sphere, and each bin's share of the uniform distribution.

Directions are polar with respect to the scene's +z axis: ``theta`` in [0, pi] is
the angle from +z, ``phi = atan2(y, x)`` in [-pi, pi) (``phi = +pi`` is the same
direction as ``-pi`` and falls in the first phi bin). Bin index
``b = i_theta * n_phi + i_phi``. Intervals are half-open ``[lo, hi)``, except the
last theta bin, which also holds ``theta = pi`` (the -z pole); a direction exactly
on an edge, up to floating-point rounding, goes to one of the two bins it touches. A
vertical direction (horizontal part at most ``VERTICAL_TOL`` of its largest component,
i.e. rounding noise) has no azimuth and takes ``phi = 0``, at every scale: its bin does not
depend on the signs or sizes of the noise left in x and y.

* ``paper`` (default, as in the authors' code): ``n_theta`` bins uniform in theta;
  bin ``i``'s uniform share is its solid angle over 4 pi,
  ``(cos(theta_i) - cos(theta_{i+1})) / (2 n_phi)``; polar bins are smaller.
* ``equal-area``: bins uniform in ``cos(theta)``, so every bin covers the same solid
  angle and its uniform share is ``1 / (n_theta n_phi)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, get_args

if TYPE_CHECKING:
    import numpy as np

Binning = Literal["paper", "equal-area"]
BINNINGS = get_args(Binning)
"""How the direction bins are laid out (module docstring)."""

MAX_BINS = 4096
"""The most direction bins (theta x phi) a node's histogram may have: memory grows with nodes x bins."""

VERTICAL_TOL = 1e-12
"""A direction whose horizontal part is at most this fraction of its largest component is vertical."""


@dataclass(frozen=True)
class DirectionBins:
    """Polar direction binning (light: numpy is imported when bins are computed, so the selection's config can hold
    one).

    Attributes:
        n_theta: bins along theta (angle from +z).
        n_phi: bins along phi (azimuth around z).
        binning: "paper" (uniform in theta, solid-angle shares) or "equal-area" (uniform in cos theta).
    """

    n_theta: int = 5
    n_phi: int = 10
    binning: str = "paper"

    def __post_init__(self) -> None:
        if self.n_theta < 1 or self.n_phi < 1:
            raise ValueError("n_theta and n_phi must be >= 1")
        if self.n_theta * self.n_phi > MAX_BINS:   # each node keeps a histogram of this many bins
            raise ValueError(f"--bins {self.n_theta}x{self.n_phi}: at most {MAX_BINS} direction bins in all (the "
                             "paper uses 5x10)")
        if self.binning not in BINNINGS:
            raise ValueError(f"binning must be one of {BINNINGS}, got {self.binning!r}")

    @property
    def n_bins(self) -> int:
        return self.n_theta * self.n_phi

    def shares(self) -> np.ndarray:
        """[B] the uniform distribution's mass in each bin (sums to 1)."""
        import numpy as np
        if self.binning == "equal-area":
            return np.full(self.n_bins, 1.0 / self.n_bins)
        edges = np.cos(np.linspace(0.0, np.pi, self.n_theta + 1))
        ring = (edges[:-1] - edges[1:]) / 2.0  # [n_theta], sums to 1
        return np.repeat(ring / self.n_phi, self.n_phi)

    def assign(self, dirs: np.ndarray) -> np.ndarray:
        """Bin index of each direction.

        Args:
            dirs: [P, 3] directions (need not be unit; a zero vector counts as +z).
        Returns:
            [P] int64 bin indices in [0, n_bins).
        """
        import numpy as np
        d = np.asarray(dirs, np.float64).reshape(-1, 3)
        norm = np.sqrt(np.einsum("ij,ij->i", d, d))
        # Guard against overflow/underflow of the squared norm at extreme scales.
        bad = ~np.isfinite(norm) | (norm == 0)
        if np.any(bad):
            scale = np.max(np.abs(d[bad]), axis=1, keepdims=True)
            scale[scale == 0] = 1.0
            dd = d[bad] / scale
            norm_bad = np.sqrt(np.einsum("ij,ij->i", dd, dd))
            cz = np.where(norm_bad > 0, dd[:, 2] / np.where(norm_bad > 0, norm_bad, 1.0), 1.0)
        cos_t = np.empty(d.shape[0])
        good = ~bad
        cos_t[good] = d[good, 2] / norm[good]
        if np.any(bad):
            cos_t[bad] = cz
        np.clip(cos_t, -1.0, 1.0, out=cos_t)
        if self.binning == "equal-area":
            it = np.floor((1.0 - cos_t) * (0.5 * self.n_theta))
        else:
            it = np.floor(np.arccos(cos_t) * (self.n_theta / np.pi))
        it = np.clip(it, 0, self.n_theta - 1).astype(np.int64)
        phi = np.arctan2(d[:, 1], d[:, 0])  # [-pi, pi]
        # a vertical direction has no azimuth: phi := 0, whatever rounding left in x and y (and their signs)
        hyp = np.hypot(d[:, 0], d[:, 1])
        mag = np.max(np.abs(d), axis=1)
        phi[~(hyp > VERTICAL_TOL * mag)] = 0.0
        ip = np.floor((phi + np.pi) * (self.n_phi / (2.0 * np.pi))).astype(np.int64)
        ip %= self.n_phi  # phi = +pi wraps onto -pi's bin
        return it * self.n_phi + ip
