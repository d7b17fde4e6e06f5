"""Generate the samples: rendered photos of walks through a synthetic living room.

``--walk even`` (data_samples/room_walk, the tests' sample):

The living room of ``curate.simulate.synthetic.make_scene("livingroom", seed=0)`` (6 x 5 x 2.7 m,
z up). A person walks a loop at eye height (1.5 m, +-5 cm bob), looking mostly ahead along
the path with head turns, then circles the coffee table looking at it: the kind of pool
curate chooses from. 160 photos, 320x240 JPEG, fx = 277 (60 degree horizontal field of
view), rendered by the project's own ray caster. Deterministic.

``--walk filmed`` (data_samples/room_capture, the README's main job): the same room filmed as people film
(:func:`curate.simulate.walks.filmed_walk`): 200 frames that linger twice and look around, swing the camera
fast twice, turn back for a few steps and pass again lower the other way; frames turned fast are blurred as
by a 1/60 s shutter (:func:`curate.simulate.walks.motion_blur`).

Writes OUT/images/frame_XXXX.jpg and transforms.json (nerfstudio convention, file paths relative to the json)
plus scene.json (the scene box).

Usage: python scripts/make_sample_pool.py [--walk even|filmed] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from curate.simulate.synthetic import make_scene
from curate.simulate.walks import filmed_walk, motion_blur, room_walk
from curate.core.transforms_json import write_transforms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--walk", choices=("even", "filmed"), default="even")
    ap.add_argument("--out", default=None, help="default: data_samples/room_walk (even), data_samples/room_capture "
                                                "(filmed)")
    a = ap.parse_args()
    from PIL import Image
    from tqdm import tqdm
    scene = make_scene("livingroom", seed=0)
    samples = Path(__file__).resolve().parents[1] / "data_samples"
    if a.walk == "even":
        cams, omega, out = room_walk(), None, a.out or samples / "room_walk"
    else:
        (cams, omega), out = filmed_walk(), a.out or samples / "room_capture"
    if scene.occupied(cams.centres).any():
        raise SystemExit("a camera centre lies in occupied space: fix the walk")
    out = Path(out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    for k in tqdm(range(len(cams)), desc="render", unit="img"):
        rgb = scene.render(cams[k])[0][0]
        if omega is not None:        # a 1/60 s shutter on frames 1/5 s apart: a twelfth of a frame's turn
            rgb = motion_blur(rgb, float(omega[k]), float(cams.fx[k]), 1 / 12)
        Image.fromarray(rgb).save(out / cams.names[k], quality=90)
    write_transforms(out / "transforms.json", cams, list(cams.names))
    lo, hi = scene.interior
    (out / "scene.json").write_text(json.dumps({"scene": "livingroom", "seed": 0,
                                                "box": [*map(float, lo), *map(float, hi)]}))
    print(f"wrote {len(cams)} photos and transforms.json to {out}")


if __name__ == "__main__":
    main()
