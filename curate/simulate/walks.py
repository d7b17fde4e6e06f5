"""Camera trajectories through the synthetic rooms (:mod:`curate.simulate.synthetic`)."""

from __future__ import annotations

import numpy as np

from curate.core.cameras import Cameras, look_at


def room_walk(n_loop: int = 110, n_orbit: int = 50, seed: int = 0) -> Cameras:
    """[n_loop + n_orbit] cameras of the sample walk through the living room (6 x 5 x 2.7 m, z up):
    a loop at eye height looking mostly ahead with head turns, then an orbit of the coffee
    table looking at it; 320x240, 60 degree horizontal field of view. Deterministic."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n_loop, endpoint=False)
    c_loop = np.stack([3.0 + 1.8 * np.cos(t), 2.5 + 1.2 * np.sin(t), 1.5 + 0.05 * np.sin(7 * t)], 1)
    ahead = np.roll(c_loop, -3, axis=0) - c_loop
    yaw = np.arctan2(ahead[:, 1], ahead[:, 0]) + 0.8 * np.sin(3 * t) + rng.normal(0, 0.1, n_loop)
    pitch = rng.normal(-0.25, 0.1, n_loop)
    d_loop = np.stack([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)], 1)
    a = np.linspace(0, 2 * np.pi, n_orbit, endpoint=False)
    table = np.array([2.5, 2.55, 0.5])
    c_orbit = np.stack([table[0] + 1.3 * np.cos(a), table[1] + 1.2 * np.sin(a), 1.2 + 0.2 * np.sin(2 * a)], 1)
    c2w = np.concatenate([look_at(c_loop, c_loop + d_loop), look_at(c_orbit, np.broadcast_to(table, c_orbit.shape))])
    n = n_loop + n_orbit
    return Cameras(c2w, 277.0, 277.0, 160.0, 120.0, 320, 240, names=tuple(f"images/frame_{i:04d}.jpg" for i in range(n)))
