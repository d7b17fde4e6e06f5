"""Generate data_samples/room_walk: a posed camera pool of a walk through a synthetic room.

A 6 x 4 x 2.5 m room (z up, floor at z = 0). A person walks a loop at eye height
(1.5 m, +-5 cm bob), looking mostly ahead along the path with head turns, and circles a
table in the middle (looking at it), the kind of capture curate chooses from. 240
cameras, 320x240 pixels, fx = 277 (60 degree horizontal field of view). Deterministic.

Writes data_samples/room_walk/transforms.json (nerfstudio convention, file names
frame_0000.jpg ... as a video export would name them; no image files: the pool is for
``curate score`` and ``curate select`` on poses alone).

Usage: python scripts/make_sample_pool.py [--out data_samples/room_walk]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from curate.cameras import Cameras, look_at
from curate.transforms_json import write_transforms


def room_walk(n_loop: int = 180, n_orbit: int = 60, seed: int = 0) -> Cameras:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n_loop, endpoint=False)
    # A rounded-rectangle loop 0.8 m inside the walls.
    x = 2.2 * np.sign(np.cos(t)) * np.abs(np.cos(t)) ** 0.5
    y = 1.2 * np.sign(np.sin(t)) * np.abs(np.sin(t)) ** 0.5
    z = 1.5 + 0.05 * np.sin(7 * t)
    c_loop = np.stack([x, y, z], 1)
    ahead = np.roll(c_loop, -3, axis=0) - c_loop
    yaw = np.arctan2(ahead[:, 1], ahead[:, 0]) + 0.6 * np.sin(3 * t) + rng.normal(0, 0.1, n_loop)
    pitch = rng.normal(-0.1, 0.1, n_loop)
    d_loop = np.stack([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)], 1)
    a = np.linspace(0, 2 * np.pi, n_orbit, endpoint=False)
    c_orbit = np.stack([1.3 * np.cos(a), 1.0 * np.sin(a), 1.2 + 0.3 * np.sin(2 * a)], 1)
    table = np.array([0.0, 0.0, 0.75])
    c2w = np.concatenate([look_at(c_loop, c_loop + d_loop), look_at(c_orbit, np.broadcast_to(table, c_orbit.shape))])
    n = n_loop + n_orbit
    return Cameras(c2w, 277.0, 277.0, 160.0, 120.0, 320, 240, names=tuple(f"frame_{i:04d}.jpg" for i in range(n)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"))
    a = ap.parse_args()
    cams = room_walk()
    out = write_transforms(Path(a.out) / "transforms.json", cams, list(cams.names),
                           extra={"curate_sample": "synthetic room walk, scripts/make_sample_pool.py",
                                  "scene_box": [-3.0, -2.0, 0.0, 3.0, 2.0, 2.5]})
    print(f"wrote {len(cams)} cameras to {out}")


if __name__ == "__main__":
    main()
