"""research.suggest_eval: its stand-in SfM points lie on the rendered surfaces, its deficient walks have the sizes
they say, and its summary pairs the arms per test view."""

import numpy as np

from research import suggest_eval as se


def test_sfm_points_lie_on_the_rendered_surfaces():
    from curate.simulate.synthetic import make_scene
    world = make_scene("kitchen", 0)
    base, cont = se.deficient_walk(world, "turn", seed=1)
    assert len(base) == int(0.85 * 80) and len(cont) == len(base) // 2 + 1
    cams = base[::20]
    _, depths = se.render(world, cams, depth=True)
    pts = se.sfm_points(cams, depths, per_frame=50, noise=0.0)
    assert 0 < len(pts) <= 50 * len(cams)
    uv, z = cams.project(pts)                       # each point seen by its own camera at the rendered depth
    k = np.repeat(np.arange(len(cams)), 50)[: len(pts)]
    zz = z[k, np.arange(len(pts))]
    u, v = uv[k, np.arange(len(pts))].T
    rendered = np.array([depths[c][int(vv), int(uu)] for c, uu, vv in zip(k, u, v)])
    assert np.allclose(zz, rendered, rtol=1e-4)
    # just in front of a point is free space, but for the few points on a depth edge (a pixel's depth applied
    # anywhere in the pixel: half a pixel of misplacement, as SfM's own)
    assert world.occupied(pts - 0.02 * (pts - cams.centres[k]) / zz[:, None]).mean() < 0.05


def test_summary_pairs_per_view_and_closes_the_gap():
    views = np.linspace(20, 22, 10)
    c = {"room": "r", "deficiency": "d", "n_base": 50, "add": 10,
         "psnr": {"base": views.tolist(), "suggest": (views + 1.0).tolist(), "random": (views + 0.5).tolist(),
                  "continue": (views + 0.25).tolist(), "full": (views + 2.0).tolist()},
         "suggest_inside_solid": 0, "suggest_timing": {"ms_per_camera": 10.0, "ms_per_candidate": 0.01}}
    s = se.summarise(c)
    assert np.isclose(s["suggest-random"]["mean"], 0.5) and np.isclose(s["suggest-random"]["lo"], 0.5)
    assert s["gap_closed"] == {"suggest": 0.5, "random": 0.25, "continue": 0.125}
    assert s["beats_both"]
    table = se.table([s])
    assert table.count("\n") == 2 and "+0.50 (+0.50 to +0.50)" in table and "0.50 / 0.25 / 0.12" in table
