"""curate suggest: observed free space, feasible poses, the greedy placement, walking instructions, output formats,
and the command end to end on the sample walk."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.select.config import EnergyConfig
from curate.select.energy import compute_energy
from curate.suggest.candidates import Envelope, Feasibility, capture_envelope, make_cameras, up_vector
from curate.suggest.freespace import cast_free_space, probe_directions, voxel_index
from curate.suggest.guide import instruction, nearest_frames
from curate.suggest.outputs import read_images_txt, suggestion_names, write_colmap_text, write_transforms_json
from curate.suggest.place import place_cameras

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "room_walk"


def _cam(centre, target, w=64, h=64, hfov=90.0, up=(0, 0, 1.0)):
    f = 0.5 * w / np.tan(np.radians(hfov) / 2)
    return Cameras(look_at(np.atleast_2d(centre), np.atleast_2d(target), up=up), f, f, w / 2, h / 2, w, h)


# ------------------------------------------------------------------ free space
def _wall_and_pillar():
    """10^3 grid over [0, 9]^3 (node i at coordinate i): a wall at x = 7 and a one-voxel pillar at (4, 4, 4)."""
    occ = np.zeros((10, 10, 10), bool)
    occ[7] = True
    occ[4, 4, 4] = True
    return occ, np.zeros(3), np.full(3, 9.0)


def test_free_space_known_answer():
    occ, lo, hi = _wall_and_pillar()
    cam = _cam([1.0, 4.0, 4.0], [5.0, 4.0, 4.0])                 # looking +x, 90 degrees wide
    fs = cast_free_space(cam, occ, lo, hi, probe=(32, 32), step=0.05)
    free = fs.free
    assert free[1, 4, 4] and free[2, 4, 4] and free[3, 4, 4]   # in front of the pillar
    assert not free[5, 4, 4] and not free[6, 4, 4]             # in its shadow
    assert free[6, 2, 4] and free[6, 6, 4]                     # beside it, in view
    assert not free[7:].any()                                  # the wall and behind it
    assert not free[0].any()                                   # behind the camera
    assert not (free & occ).any()
    # the central rays stop at the pillar's cell face (x = 3.5, 2.5 from the camera)
    centre_rays = np.abs(np.arccos(np.clip(fs.axis_cos[0], -1, 1))) < np.radians(3)
    assert np.allclose(fs.hit_depth[0, centre_rays], 2.5, atol=0.1)
    h = fs.hit_depth[0]
    assert np.isfinite(h).mean() > 0.8                         # the corner rays leave the box through its sides
    assert abs(fs.median_depth[0] - np.median(h[np.isfinite(h)])) < 1e-12


def _reference_free(cams, occ, lo, hi, probe, step, near):
    """The same definition, one ray and one sample at a time (slow)."""
    R = occ.shape[0]
    free = np.zeros(occ.shape, bool)
    dirs, _ = probe_directions(cams, probe)
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    for k in range(len(cams)):
        c = cams.centres[k]
        S = int(np.ceil((np.linalg.norm(corners - c, axis=1).max() + step) / step))
        ts = (np.arange(S) + 0.5) * step
        hits, walks = [], []
        for d in dirs[k]:
            cells, hit = [], None
            for t in ts:
                f = int(voxel_index(c + t * d, lo, hi, R))
                if f >= 0 and occ.ravel()[f] and t >= near:
                    hit = t
                    break
                cells.append((t, f))
            hits.append(hit)
            walks.append(cells)
        for hit, cells in zip(hits, walks):          # a ray that hits nothing carves nothing
            for _, f in cells:
                if f >= 0 and hit is not None:
                    free.ravel()[f] = True
    return free & ~occ


def test_free_space_matches_a_ray_by_ray_reference():
    rng = np.random.default_rng(3)
    occ = rng.random((9, 9, 9)) < 0.04
    occ[:, :, 0] = True                                         # a floor: most rays hit something
    lo, hi = np.array([-1.0, -1, -1]), np.array([2.5, 2.0, 1.5])
    cams = Cameras.concat([_cam(rng.uniform(lo + 0.5, hi - 0.5), rng.uniform(lo, hi), 40, 30, 70) for _ in range(4)])
    step, near = 0.11, 0.3
    fast = cast_free_space(cams, occ, lo, hi, probe=(6, 5), step=step, near=near, chunk=97)  # chunks split rays
    assert np.array_equal(fast.free, _reference_free(cams, occ, lo, hi, (6, 5), step, near))


def test_rays_that_hit_nothing_carve_nothing():
    occ = np.zeros((10, 10, 10), bool)
    occ[6, 3:6, 3:6] = True                                     # a small panel straight ahead
    lo, hi = np.zeros(3), np.full(3, 9.0)
    cam = _cam([1.0, 4.0, 4.0], [5.0, 4.0, 4.0])
    fs = cast_free_space(cam, occ, lo, hi, probe=(16, 16), step=0.05)
    assert 4.4 < fs.median_depth[0] < 5.5                       # the panel's face at x = 5.5
    assert not fs.free[:, 1, 4].any()                           # only misses cross y = 1 (31-45 degrees): not carved
    assert fs.free[3, 4, 4]                                     # the panel's own rays carve in front of it
    none = cast_free_space(cam, np.zeros_like(occ), lo, hi, probe=(16, 16))
    assert not none.free.any() and np.isnan(none.median_depth[0]) and np.isinf(none.nearest_surface()[0])


def test_a_plain_wall_beside_a_far_surface_is_not_carved_through():
    """A camera stands 1.5 from a wall without points (x = 0) and looks along it at a textured far wall (y = 8):
    nothing at or behind the plain wall is observed free (its rays hit nothing; the default carves only hits)."""
    R = 19
    lo, hi = np.array([-3.0, 0.0, 0.0]), np.array([6.0, 9.0, 9.0])
    x = lo[0] + np.arange(R) * 0.5                              # node spacing 0.5
    occ = np.zeros((R, R, R), bool)
    occ[x >= 0, 16, :] = True                                   # the far wall at y = 8, inside the room only
    cam = _cam([1.5, 1.0, 4.5], [1.5, 8.0, 4.5], hfov=100)
    fs = cast_free_space(cam, occ, lo, hi, probe=(32, 24))
    assert fs.free[(x > 2) & (x < 4)].any()                     # in front of the far wall: seen
    assert not fs.free[x < 0].any()                             # behind the plain wall: never


# ------------------------------------------------------------------ feasibility
@pytest.fixture(scope="module")
def room():
    """The kitchen, its exact occupancy on a 24^3 grid, and a hand-held loop through it."""
    from curate.simulate.synthetic import make_scene
    from curate.simulate.walks import hand_held_walk
    from curate.core.grid import NodeGrid
    s = make_scene("kitchen", 0)
    lo, hi = s.interior
    g = NodeGrid(lo - 0.1, hi + 0.1, 24)
    occ = s.occupied(g.all_nodes()).reshape((24,) * 3)
    walk, _ = hand_held_walk(60, "loop", seed=2, width=80, height=60, room=s.interior)
    fs = cast_free_space(walk, occ, g.box_min, g.box_max, probe=(16, 12))
    env = capture_envelope(walk, fs, occ, g.box_min, g.box_max)
    return s, g, occ, walk, fs, env


def test_envelope_comes_from_the_capture(room):
    s, g, occ, walk, fs, env = room
    assert np.allclose(env.up, [0, 0, 1], atol=0.05)            # the walk's image up
    h = walk.centres @ env.up
    assert np.isclose(env.heights[0], np.percentile(h, 5)) and np.isclose(env.heights[1], np.percentile(h, 95))
    p = np.arcsin(walk.view_dirs @ env.up)
    assert np.isclose(env.pitches[0], np.percentile(p, 5)) and np.isclose(env.pitches[1], np.percentile(p, 95))
    vox = float(np.max((g.box_max - g.box_min) / 23))
    assert env.clearance >= vox and env.view_margin >= vox
    assert env.intrinsics[4:] == (80, 60)


def test_drawn_poses_are_feasible_and_never_inside_or_near_occupied_nodes(room):
    s, g, occ, walk, fs, env = room
    feas = Feasibility(occ, g.box_min, g.box_max, fs.free, env)
    cams = feas.draw(np.random.default_rng(0), 300)
    assert len(cams) == 300 and np.all(feas.feasible(cams))
    c = cams.centres
    occ_pts = g.all_nodes()[occ.ravel()]
    nearest = np.sqrt(((c[:, None, :] - occ_pts[None]) ** 2).sum(-1)).min(1)   # brute force
    assert nearest.min() >= env.clearance - 1e-9
    flat = voxel_index(c, g.box_min, g.box_max, g.res)
    assert np.all(flat >= 0) and np.all(fs.free.ravel()[flat]) and not occ.ravel()[flat].any()
    assert not s.occupied(c).any()                              # nor inside the room's true solids
    h = c @ env.up
    assert h.min() >= env.heights[0] - 1e-9 and h.max() <= env.heights[1] + 1e-9
    p = np.arcsin(np.clip(cams.view_dirs @ env.up, -1, 1))
    assert p.min() >= env.pitches[0] - 1e-9 and p.max() <= env.pitches[1] + 1e-9
    assert np.allclose(cams.c2w[:, :3, 0] @ env.up, 0, atol=1e-9)   # no roll: the image's x axis is level
    from curate.simulate.progressive import GridOracle
    assert np.all(GridOracle(g.box_min, g.box_max, occ, env.view_margin).min_depth(cams) >= env.view_margin)
    # each test rejects what it must
    bad = make_cameras(np.array([[2.5, 2.0, 2.59], c[0], c[1]]), np.zeros(3),
                       np.array([0.0, env.pitches[1] + 0.3, 0.0]), env)
    ch = feas.checks(bad)
    assert not ch["height"][0] and not ch["pitch"][1]
    inside = make_cameras(occ_pts[:1], np.zeros(1), np.zeros(1), env)
    assert not feas.feasible(inside)[0] and not feas.checks(inside)["free"][0]


def test_no_feasible_space_draws_nothing(room):
    s, g, occ, walk, fs, env = room
    feas = Feasibility(occ, g.box_min, g.box_max, np.zeros_like(fs.free), env)
    assert len(feas.cells) == 0 and len(feas.draw(np.random.default_rng(0), 10)) == 0


# ------------------------------------------------------------------ placement
def test_greedy_raises_the_energy_at_each_step_and_takes_the_best_candidate(room):
    s, g, occ, walk, fs, env = room
    from curate.occupancy.masks import dilate
    nodes_mask = occ & dilate(~occ, 1)
    nodes = g.with_mask(nodes_mask).nodes()
    feas = Feasibility(occ, g.box_min, g.box_max, fs.free, env)
    cfg = EnergyConfig()
    pl = place_cameras(walk, nodes, feas, 4, n_candidates=40, energy=cfg, seed=5)
    assert len(pl.cams) == 4 and pl.n_candidates == [40] * 4
    e = np.array([pl.energy_before] + pl.energy)
    assert np.all(np.diff(e) > 0) and np.all(np.array(pl.gains) > 0)
    ref = compute_energy(Cameras.concat([walk, pl.cams]), nodes, cfg)
    assert np.isclose(pl.energy[-1], ref.energy, rtol=1e-9)
    assert np.isclose(pl.energy_before, compute_energy(walk, nodes, cfg).energy, rtol=1e-9)
    assert np.isclose(pl.after.angular_per_node.sum() + pl.after.frequency_per_node.sum(), ref.energy, rtol=1e-9)
    # the first placed pose is the best of the first step's candidates (the same draws, scored from scratch)
    cands = feas.draw(np.random.default_rng(5), 40)
    best = max(compute_energy(Cameras.concat([walk, cands[k]]), nodes, cfg).energy for k in range(len(cands)))
    assert np.isclose(pl.energy[0], best, rtol=1e-12)
    t = pl.timing()
    assert t["steps"] == 4 and t["ms_per_candidate"] > 0 and t["ms_per_camera"] > 0
    assert not any(np.isnan(v) for v in (pl.before.angular_per_node.sum(), pl.after.frequency_per_node.sum()))


# ------------------------------------------------------------------ instructions
def test_instruction_in_the_walkers_frame():
    ref = _cam([0.0, 0, 1.5], [1.0, 0, 1.5])                    # facing +x, up +z: left is +y
    s = _cam([1.0, 2.1, 1.9], [1.0, 3.1, 1.9])                  # 1 forward, 2.1 left, 0.4 up, facing +y
    ins = instruction(ref, 0, s, 0, np.array([0, 0, 1.0]), "m", look_depth=2.0, label="frame 7")
    assert np.allclose([ins.forward, ins.left, ins.up], [1.0, 2.1, 0.4])
    assert np.isclose(ins.turn_deg, 90) and np.isclose(ins.tilt_deg, 0, atol=1e-9)
    assert ins.text == ("From frame 7: 2.1 m left (about three steps), 1.0 m forward (about one step), hold the "
                        "camera 0.4 m higher; turn 90° left.")
    s2 = _cam([-0.5, -0.3, 1.5], [-0.5 + np.cos(np.radians(-30)), -0.3 + np.sin(np.radians(-30)), 1.0])
    ins2 = instruction(ref, 0, s2, 0, np.array([0, 0, 1.0]), "units", look_depth=2.0)
    assert "0.30 units right" in ins2.text and "0.50 units back" in ins2.text and "turn 30° right" in ins2.text
    assert "tilt" in ins2.text and "down" in ins2.text and "step" not in ins2.text
    same = instruction(ref, 0, ref, 0, np.array([0, 0, 1.0]), "m", 2.0, label="x")
    assert same.text == "From x: stay where it was taken; look the same way."


def test_nearest_frame_weighs_where_it_stands_and_where_it_looks():
    cap = Cameras.concat([_cam([0.0, 0, 0], [1.0, 0, 0]), _cam([0.3, 0, 0], [0.3, -1, 0]),
                          _cam([3.0, 0, 0], [4, 0, 0])])
    s = _cam([0.4, 0.0, 0], [1.4, 0.1, 0])                      # stands by camera 1, looks like camera 0
    assert nearest_frames(cap, s, look_depth=2.0).tolist() == [0]


# ------------------------------------------------------------------ outputs
def test_outputs_round_trip(tmp_path):
    from curate.core.transforms_json import read_transforms
    rng = np.random.default_rng(1)
    c = rng.uniform(-2, 2, (5, 3))
    cams = Cameras(look_at(c, c + rng.normal(size=(5, 3))), 300.0, 300.0, 160, 120, 320, 240)
    names = suggestion_names(5)
    assert names[0] == "suggest_01.jpg" and len(set(names)) == 5 and suggestion_names(120)[0] == "suggest_001.jpg"
    write_transforms_json(tmp_path / "transforms.json", cams, names)
    back, files = read_transforms(tmp_path / "transforms.json")
    assert np.allclose(back.c2w, cams.c2w, atol=1e-12) and list(back.names) == names
    assert np.allclose(back.fx, 300) and np.all(back.width == 320)
    cam_txt, img_txt = write_colmap_text(tmp_path, cams, names)
    got_names, c2w, cids = read_images_txt(img_txt)
    assert got_names == names and cids == [1] * 5 and np.allclose(c2w, cams.c2w, atol=1e-9)
    lines = [ln for ln in img_txt.read_text().splitlines() if not ln.startswith("#")]
    assert len(lines) == 10 and all(ln == "" for ln in lines[1::2])   # COLMAP: an (empty) points line per image
    cam_line = [ln for ln in cam_txt.read_text().splitlines() if not ln.startswith("#")]
    assert cam_line[0].split()[:4] == ["1", "PINHOLE", "320", "240"]
    assert np.allclose([float(v) for v in cam_line[0].split()[4:]], [300, 300, 160, 120])
    (tmp_path / "bad.txt").write_text("1 0.5 x 0 0 0 0 0 1 a.jpg\n\n")
    with pytest.raises(ValueError, match="bad.txt"):
        read_images_txt(tmp_path / "bad.txt")


def test_up_vector_and_degenerate_envelope():
    cams = Cameras.concat([_cam([0.0, 0, 1.5], [1.0, 0, 1.5]), _cam([1.0, 0, 1.5], [2.0, 1, 1.5])])
    assert np.allclose(up_vector(cams), [0, 0, 1])
    # a walk looking 20 degrees down over a quarter turn: the mean image up leans forward, the level x axes do not
    yaw = np.radians(np.linspace(0, 90, 12))
    d = np.stack([np.cos(yaw) * np.cos(np.radians(-20)), np.sin(yaw) * np.cos(np.radians(-20)),
                  np.full(12, np.sin(np.radians(-20)))], 1)
    tilted = Cameras(look_at(np.zeros((12, 3)), d), 100.0, 100.0, 50, 50, 100, 100)
    lean = -tilted.c2w[:, :3, 1].mean(0)
    assert np.degrees(np.arccos(lean[2] / np.linalg.norm(lean))) > 5
    assert np.allclose(up_vector(tilted), [0, 0, 1], atol=1e-9)
    one_way = Cameras(look_at(np.zeros((3, 3)), d[:1].repeat(3, 0)), 100.0, 100.0, 50, 50, 100, 100)
    assert np.isfinite(up_vector(one_way)).all() and up_vector(one_way)[2] > 0.9
    occ = np.zeros((6, 6, 6), bool)
    occ[:, :, 0] = True
    fs = cast_free_space(cams, occ, np.array([-1.0, -2, 0]), np.array([4.0, 3, 3]), probe=(8, 6))
    env = capture_envelope(cams, fs, occ, np.array([-1.0, -2, 0]), np.array([4.0, 3, 3]))
    assert isinstance(env, Envelope) and env.heights == (1.5, 1.5)     # all at one height: a range of zero
    assert all(np.isfinite(v) for v in (env.clearance, env.view_margin, env.look_depth))


# ------------------------------------------------------------------ the command
def _curate(*args, check=True):
    p = subprocess.run([sys.executable, "-m", "curate", *args], capture_output=True, text=True, timeout=900,
                       cwd=ROOT)
    if check and p.returncode != 0:
        raise AssertionError(p.stderr[-3000:])
    return p


@pytest.mark.slow
def test_suggest_command_end_to_end_on_the_sample_walk(tmp_path):
    from curate.core.transforms_json import read_transforms
    run = tmp_path / "run"
    _curate("run", str(SAMPLE / "images"), "--poses", str(SAMPLE / "transforms.json"), "--no-evaluate",
            "--budget", "12", "--res", "16", "--triangulate", "off", "--refine-iters", "40", "--refine-size", "32",
            "--out", str(run))   # no points: a field
    # a field trained 60 iterations at 64 px is haze: nowhere is seen empty around a camera; said in one line,
    # and the run's report says so instead of recommending the command
    bad = _curate("suggest", str(run), "--add", "3", "--candidates", "150", "--field-iters", "60", "--field-size", "64",
                  "--preview-size", "48", "--metres", check=False)
    assert bad.returncode != 0 and "Traceback" not in bad.stderr
    why = json.loads((run / "suggest" / "unanswered.json").read_text())["reason"]
    assert why in bad.stderr.strip().splitlines()[-1]
    assert "found nowhere to propose" in (run / "report.html").read_text()
    out = json.loads(_curate("suggest", str(run), "--add", "3", "--candidates", "150", "--field-iters", "200",
                             "--field-size", "80", "--preview-size", "48", "--metres", "--json").stdout)
    assert out["ran"] is True
    d = run / "suggest"
    rec = json.loads((d / "suggestions.json").read_text())
    assert rec["placed"] == 3 and len(rec["suggestions"]) == 3 and rec["units"] == "m"
    assert rec["occupancy"].startswith("the density of suggest_field")   # imported poses: no points, a field
    assert rec["energy"][0] > rec["energy_before"] and np.all(np.diff(rec["energy"]) > 0)
    for s in rec["suggestions"]:
        assert s["nearest"]["text"].startswith("From frame_") and (d / s["preview"]).is_file()
    cams, _ = read_transforms(d / "transforms.json")
    assert np.allclose(cams.c2w, [s["c2w"] for s in rec["suggestions"]], atol=1e-9)
    names, c2w, _ = read_images_txt(d / "images.txt")
    assert names == [s["name"] for s in rec["suggestions"]] and np.allclose(c2w, cams.c2w, atol=1e-9)
    page = (d / "suggest.html").read_text()
    assert "Where to shoot next" in page and page.count('class="card"') == 3 and "<svg" in page
    assert "http://" not in page.replace("http://www.w3.org", "")              # self-contained
    # the room's true solids: no suggestion inside one (the field's occupancy is only 200 iterations old)
    from curate.simulate.synthetic import make_scene
    assert not make_scene("livingroom", 0).occupied(cams.centres).any()
    again = json.loads(_curate("suggest", str(run), "--add", "3", "--candidates", "150", "--field-iters", "200",
                               "--field-size", "80", "--preview-size", "48", "--metres", "--json").stdout)
    assert again["ran"] is False                                                 # unchanged: skipped
    more = json.loads(_curate("suggest", str(run), "--add", "4", "--candidates", "150", "--field-iters", "200",
                              "--field-size", "80", "--preview-size", "48", "--json").stdout)   # in units now
    assert json.loads((d / "suggestions.json").read_text())["units"] == "units"
    assert more["ran"] is True and len(json.loads((d / "suggestions.json").read_text())["suggestions"]) == 4
    assert json.loads((run / "suggest_field" / "stage.json").read_text())["key"]   # the field was reused, not retrained


def test_suggest_command_refuses_what_is_not_a_run_folder(tmp_path):
    p = _curate("suggest", str(tmp_path / "nothing"), check=False)
    assert p.returncode == 2 and "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) == 1
    (tmp_path / "empty").mkdir()
    p = _curate("suggest", str(tmp_path / "empty"), "--add", "0", check=False)
    assert p.returncode == 2 and "Traceback" not in p.stderr


def test_frontier_is_unobserved_space_touching_observed_free_space():
    from curate.suggest.stage import frontier, surface_band
    free = np.zeros((6, 6, 6), bool)
    free[1:3, 1:3, 1:3] = True
    occ = np.zeros_like(free)
    occ[3, 1:3, 1:3] = True                                    # a wall on one side of the free block
    f = frontier(free, occ)
    assert f[0, 1, 1] and f[1, 0, 1] and f[1, 1, 3]            # beside the free block, unknown
    assert not f[3, 1, 1] and not f[1, 1, 1] and not f[5, 5, 5]   # occupied, free, far away
    assert not f[0, 0, 1]                                      # diagonal only: not a 6-neighbour
    solid = np.zeros((8, 8, 8), bool)
    solid[2:6, 2:6, 2:6] = True
    shell = surface_band(solid, 0)
    assert shell.sum() == 4 ** 3 - 2 ** 3 and not shell[3, 3, 3]   # the cube's outer layer
    assert surface_band(solid, 1)[1, 3, 3] and not surface_band(np.zeros_like(solid), 1).any()


def test_frame_labels_name_video_frames_by_time():
    from curate.suggest.stage import frame_labels
    rec = {"photos": [{"working": "v_000001.200.jpg", "rel": "v_000001.200.jpg",
                       "extra": {"video_rel": "walk.mp4", "time": 1.2}},
                      {"working": "", "rel": "images/a.jpg", "extra": {}}]}
    assert frame_labels(["v_000001.200.jpg", "images/a.jpg", "other.png"], rec) == \
        ["walk.mp4 at 1.2 s", "a.jpg", "other.png"]


def test_read_run_names_what_is_missing(tmp_path):
    from curate.suggest.stage import read_run
    (tmp_path / "sfm").mkdir()
    with pytest.raises(FileNotFoundError, match="cameras.json"):
        read_run(tmp_path)


def test_a_capture_from_one_spot_does_not_forbid_going_nearer_than_it_stood(room):
    from curate.suggest.candidates import MAX_CLEARANCE_SHARE, MAX_VIEW_MARGIN_SHARE
    s, g, occ, walk, fs, env = room
    yaw = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    spot = np.array([2.6, 2.0, 1.5])                           # mid-room: far from everything
    turn = Cameras(look_at(np.tile(spot, (24, 1)), spot + np.stack([np.cos(yaw), np.sin(yaw), -0.1 + 0 * yaw], 1)),
                   69.3, 69.3, 40, 30, 80, 60)
    fs1 = cast_free_space(turn, occ, g.box_min, g.box_max, probe=(16, 12))
    e1 = capture_envelope(turn, fs1, occ, g.box_min, g.box_max)
    from scipy.spatial import cKDTree
    stood = cKDTree(g.all_nodes()[occ.ravel()]).query(spot)[0]
    assert e1.clearance <= MAX_CLEARANCE_SHARE * e1.look_depth + 1e-12 < stood
    assert e1.view_margin <= MAX_VIEW_MARGIN_SHARE * e1.look_depth + 1e-12
    feas = Feasibility(occ, g.box_min, g.box_max, fs1.free, e1)
    assert len(feas.draw(np.random.default_rng(0), 50)) == 50


def test_add_beyond_what_a_reshoot_can_use_is_refused_naming_the_flag_and_its_bound():
    """Issue 49: `curate suggest RUN --add 100000` ran without limit; the option is refused (the CLI turns the
    ValueError into its one-line error), with the bound and why."""
    from curate.suggest.config import MAX_ADD, SuggestConfig
    with pytest.raises(ValueError, match=f"--add must be an integer from 1 to {MAX_ADD}, got 100000"):
        SuggestConfig(add=100000)
    assert SuggestConfig(add=MAX_ADD).add == MAX_ADD


# ------------------------------------------------------------------ standing in the room (issue 49)
def _object_capture(n=36, radius=2.0, rise=0.8, seed=0, half=3.0):
    """A ring of cameras around a cube (half side 0.4) at the origin of a (2 half)^3 box on a 25^3 grid, looking at
    it (``half`` < 2: the cameras stand outside the grid, as the occupancy's box of an object capture leaves them)."""
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c = np.stack([radius * np.cos(a), radius * np.sin(a), np.full(n, rise)], 1) + rng.normal(0, 0.03, (n, 3))
    cams = Cameras(look_at(c, np.zeros((n, 3))), 60.0, 60.0, 40.0, 30.0, 80, 60)
    lo, hi = np.full(3, -half), np.full(3, half)
    x = np.linspace(-half, half, 25)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    occ = (np.abs(X) <= 0.4) & (np.abs(Y) <= 0.4) & (np.abs(Z) <= 0.4)
    return cams, occ, lo, hi


@pytest.mark.parametrize("half", [3.0, 1.2])
def test_an_object_capture_gets_suggestions_on_its_view_sphere_at_heights_it_did_not_film(half):
    from curate.suggest.config import SuggestConfig
    from curate.suggest.stage import RunInputs, suggest, surface_band
    cams, occ, lo, hi = _object_capture(half=half)
    inp = RunInputs(cams, [""] * len(cams), [f"f{i}" for i in range(len(cams))], "m", occ, surface_band(occ, 1),
                    lo, hi, [], [])
    pl, feas, *_ = suggest(SuggestConfig(add=6, n_candidates=200), inp)
    o = feas.orbit                                              # an object capture: the view sphere's poses
    assert np.linalg.norm(o.centre) < 0.1
    s = pl.cams
    assert len(s) == 6
    r = np.linalg.norm(s.centres - o.centre, axis=1)
    assert np.all((r >= o.radii[0] - 1e-9) & (r <= o.radii[1] + 1e-9))
    to = (o.centre - s.centres) / r[:, None]
    assert np.allclose(np.sum(to * s.view_dirs, axis=1), 1.0, atol=1e-9)       # each looks at the object
    assert np.allclose(s.c2w[:, :3, 0] @ feas.env.up, 0, atol=1e-9)             # no roll
    el = np.degrees(np.arcsin((s.centres - o.centre) @ feas.env.up / r))
    cap = np.degrees(o.captured)
    assert np.any((el > cap[1] + 5) | (el < cap[0] - 5))                       # heights the ring did not film
    assert np.all(feas.clearance(s.centres) >= feas.env.clearance)
    again = suggest(SuggestConfig(add=6, n_candidates=200), inp)[0]
    assert np.array_equal(again.cams.c2w, s.c2w)                               # the same answer every time


def test_a_capture_that_saw_no_empty_space_is_told_what_it_lacks():
    from curate.suggest.config import SuggestConfig
    from curate.suggest.stage import RunInputs, suggest, surface_band
    occ = np.zeros((12, 12, 12), bool)
    occ[11] = True                                              # one far wall: every ray from x < 0 misses it
    cams = Cameras.concat([_cam([0.5, 4.0 + i * 0.3, 1.5], [-5.0, 4.0 + i * 0.3, 1.5]) for i in range(5)])
    inp = RunInputs(cams, [""] * 5, list("abcde"), "m", occ, surface_band(occ, 1), np.zeros(3), np.full(3, 11.0),
                    [], [])
    with pytest.raises(ValueError, match="saw no empty space to stand in"):
        suggest(SuggestConfig(add=2), inp)


def test_a_suggestion_keeps_its_clearance_from_space_the_capture_did_not_see():
    """Free space seen in x < 5 only (beyond it: a plain wall, no points, never carved): a centre 0.5 from its edge
    is refused though nothing occupied is near it; one 2.5 from it stands."""
    R = 11
    lo, hi = np.zeros(3), np.full(3, 10.0)
    occ = np.zeros((R, R, R), bool)
    occ[:, :, 0] = True                                         # a floor
    free = np.zeros((R, R, R), bool)
    free[:6, :, 1:] = True
    env = Envelope(np.array([0, 0, 1.0]), (0.0, 10.0), (-1.0, 1.0), 1.0, 0.5, (40.0, 40.0, 40.0, 30.0, 80, 60), 4.0)
    feas = Feasibility(occ, lo, hi, free, env)
    assert list(feas.seen_around(np.array([[4.5, 5.0, 5.0], [2.5, 5.0, 5.0]]))) == [False, True]
    cams = make_cameras(np.array([[4.5, 5.0, 5.0], [2.5, 5.0, 5.0]]), np.zeros(2), np.zeros(2), env)
    ch = feas.checks(cams)
    assert ch["clearance"].all() and list(ch["seen"]) == [False, True]
    assert all(feas.node_xyz(feas.cells)[:, 0] <= 3.0)          # no feasible voxel within the clearance of x = 5


def test_a_truncated_occupancy_or_stage_record_is_a_one_line_error_not_a_crash(tmp_path):
    """The adversarial sweep (issue 49): a truncated occupancy.npz ended `curate suggest` in BadZipFile, and a
    stage.json that is not UTF-8 ended `curate export` in UnicodeDecodeError."""
    from curate.core.stage import read_stage
    from curate.suggest.stage import read_run
    run = tmp_path / "run"
    (run / "sfm").mkdir(parents=True)
    (run / "occupancy").mkdir()
    cams = Cameras.concat([_cam([0, 0, 1.0], [1, 0, 1.0]), _cam([0, 1, 1.0], [1, 1, 1.0])])
    (run / "sfm" / "cameras.json").write_text(json.dumps(cams.to_dict()))
    (run / "sfm" / "images.json").write_text("{}")
    np.savez_compressed(run / "occupancy" / "occupancy.npz", refined_mask=np.zeros((4, 4, 4), bool))
    data = (run / "occupancy" / "occupancy.npz").read_bytes()
    (run / "occupancy" / "occupancy.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=r"occupancy.npz: not an occupancy grid of curate"):
        read_run(run)
    (run / "occupancy" / "stage.json").write_bytes(b'{"key": "\xaf\xff"}')
    assert read_stage(run / "occupancy") is None
    (run / "sfm" / "cameras.json").write_text('{"c2w": [[')
    with pytest.raises(ValueError, match=r"cameras.json: not a cameras file of curate"):
        read_run(run)
