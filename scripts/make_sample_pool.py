"""Generate data_samples/room_walk: rendered photos of a walk through a synthetic living room.

The living room of ``curate.synthetic.make_scene("livingroom", seed=0)`` (6 x 5 x 2.7 m,
z up). A person walks a loop at eye height (1.5 m, +-5 cm bob), looking mostly ahead along
the path with head turns, then circles the coffee table looking at it: the kind of pool
curate chooses from. 160 photos, 320x240 JPEG, fx = 277 (60 degree horizontal field of
view), rendered by the project's own ray caster. Deterministic.

Writes data_samples/room_walk/images/frame_XXXX.jpg and transforms.json (nerfstudio
convention, file paths relative to the json) plus scene.json (the scene box).

Usage: python scripts/make_sample_pool.py [--out data_samples/room_walk]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from curate.cameras import Cameras, look_at
from curate.synthetic import make_scene
from curate.transforms_json import write_transforms


def room_walk(n_loop: int = 110, n_orbit: int = 50, seed: int = 0) -> Cameras:
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"))
    a = ap.parse_args()
    from PIL import Image
    from tqdm import tqdm
    scene = make_scene("livingroom", seed=0)
    cams = room_walk()
    if scene.occupied(cams.centres).any():
        raise SystemExit("a camera centre lies in occupied space: fix the walk")
    out = Path(a.out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    for k in tqdm(range(len(cams)), desc="render", unit="img"):
        rgb, _ = scene.render(cams[k])
        Image.fromarray(rgb[0]).save(out / cams.names[k], quality=90)
    write_transforms(out / "transforms.json", cams, list(cams.names))
    lo, hi = scene.interior
    (out / "scene.json").write_text(json.dumps({"scene": "livingroom", "seed": 0,
                                                "box": [*map(float, lo), *map(float, hi)]}))
    print(f"wrote {len(cams)} photos and transforms.json to {out}")


if __name__ == "__main__":
    main()
