"""Procedural rooms and the ray-casting renderer."""

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.simulate.synthetic import LAYOUTS, make_scene


def cam_at(c, target, size=(64, 48), f=50.0):
    return Cameras(look_at(np.array([c], float), np.array([target], float)), f, f, size[0] / 2, size[1] / 2, *size)


def test_depth_matches_analytic_distance_to_wall():
    s = make_scene("office", 0)
    # From (3.5, 2.5, 2.45) looking along -x at the wall x = 0 (nothing in between at that height):
    # every pixel that hits that wall has camera-frame depth 3.5 exactly.
    cam = cam_at([3.5, 2.5, 2.45], [0.0, 2.5, 2.45], size=(32, 24), f=60.0)
    rgb, depth = s.render(cam)
    d = depth[0]
    assert d.shape == (24, 32) and rgb[0].shape == (24, 32, 3)
    assert abs(d[12, 16] - 3.5) < 1e-4
    on_wall = np.abs(d - 3.5) < 1e-3
    assert on_wall.mean() > 0.5


@pytest.mark.parametrize("layout", LAYOUTS)
def test_render_deterministic_and_textured(layout):
    s1, s2 = make_scene(layout, 3), make_scene(layout, 3)
    lo, hi = s1.free_box
    cam = cam_at((lo + hi) / 2, s1.poi)
    a, da = s1.render(cam)
    b, db = s2.render(cam)
    assert a[0].tobytes() == b[0].tobytes() and np.array_equal(da[0], db[0])
    assert np.all(np.isfinite(da[0])) and da[0].min() > 0
    # Texture: strong local contrast everywhere in the image (what SfM features need).
    g = a[0].astype(float).mean(2)
    assert np.abs(np.diff(g, axis=1)).mean() > 2.0
    assert make_scene(layout, 4).render(cam)[0][0].tobytes() != a[0].tobytes()


def test_exact_occupancy():
    s = make_scene("kitchen", 0)
    lo, hi = s.free_box
    assert not s.occupied(((lo + hi) / 2)[None])[0]
    assert s.occupied(np.array([[-1.0, 1, 1], [2.5, 2.0, 100.0]])).all()  # outside the room
    top = next(x for x in s.solids[6:] if x.kind == "box" and abs(x.hi[2] - 0.76) < 1e-9)
    centre = (np.asarray(top.lo) + np.asarray(top.hi)) / 2
    assert s.occupied(centre[None])[0]
    # The free box is free of furniture.
    g = np.stack(np.meshgrid(*[np.linspace(lo[i], hi[i], 6) for i in range(3)], indexing="ij"), -1).reshape(-1, 3)
    assert not s.occupied(g).any()
    # Rendered depth agrees with occupancy: points just before a hit are free, just after occupied.
    cam = cam_at((lo + hi) / 2, s.poi, size=(16, 12))
    _, depth = s.render(cam)
    uv = np.stack(np.meshgrid(np.arange(16) + 0.5, np.arange(12) + 0.5), -1).reshape(-1, 2)
    rays = np.concatenate([(uv - [8, 6]) / 50.0, np.ones((uv.shape[0], 1))], 1) @ cam.rotations[0].T
    z = depth[0].reshape(-1, 1).astype(float)
    c = cam.centres[0]
    assert not s.occupied(c + rays * (z - 0.01)).any()
    assert s.occupied(c + rays * (z + 0.01)).mean() > 0.95


def test_unknown_layout():
    with pytest.raises(ValueError):
        make_scene("garage")
