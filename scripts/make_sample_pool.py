"""Generate data_samples/room_walk: rendered photos of a walk through a synthetic living room.

The living room of ``curate.simulate.synthetic.make_scene("livingroom", seed=0)`` (6 x 5 x 2.7 m,
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

from curate.simulate.synthetic import make_scene
from curate.simulate.walks import room_walk
from curate.core.transforms_json import write_transforms


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
