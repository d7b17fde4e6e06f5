"""A frame no mapper part confirms is kept on its own evidence (issue 36): its pose, estimated again
from its matches to points the other frames see with the model held fixed, must agree with the model's."""

from __future__ import annotations

import numpy as np
import pytest

pycolmap = pytest.importorskip("pycolmap")

from curate.core.cameras import Cameras, look_at, w2c_from_c2w  # noqa: E402
from curate.sfm.parts import JOIN_MIN_FRAMES, VERIFY_MIN_POINTS, join_parts, verify_frames  # noqa: E402


def model(perturb: dict[int, np.ndarray] | None = None, n_points: int = 600, seed: int = 0,
          moved: np.ndarray | None = None):
    """A model of 8 cameras on an arc looking at a cloud of points, every observation exact; the poses of
    ``perturb`` (index -> 3x3 rotation applied to its world-to-camera rotation) are wrong in the model;
    ``moved`` [3, 3], a rotation of the world about its origin, moves cameras 4-7 together (a rigid part put
    in the wrong place)."""
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 1.2, 8)
    centres = np.stack([4 * np.cos(a), 4 * np.sin(a), np.full(8, 1.5)], 1)
    cams = Cameras(look_at(centres, np.zeros((8, 3))), 300, 300, 320, 240, 640, 480,
                   names=tuple(f"f{i:02d}.jpg" for i in range(8)))
    X = rng.uniform(-1.5, 1.5, (n_points, 3))
    R, t = w2c_from_c2w(cams.c2w)
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(camera_id=1, model="PINHOLE", width=640, height=480,
                                                    params=[300, 300, 320, 240]))
    obs = {}
    for i in range(8):
        x = X @ R[i].T + t[i]
        uv = x[:, :2] / x[:, 2:] * 300 + [320, 240]
        seen = np.flatnonzero((x[:, 2] > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < 640) & (uv[:, 1] >= 0) & (uv[:, 1] < 480))
        obs[i] = {int(j): k for k, j in enumerate(seen)}
        Ri = R[i] if not perturb or i not in perturb else perturb[i] @ R[i]
        if moved is not None and i >= 4:      # centre c -> moved c, orientation turned with it: t unchanged
            Ri = Ri @ moved.T
        rec.add_image_with_trivial_frame(pycolmap.Image(name=cams.names[i], keypoints=uv[seen], camera_id=1,
                                                        image_id=i + 1),
                                         pycolmap.Rigid3d(pycolmap.Rotation3d(Ri), t[i]))
    for j in range(n_points):
        els = [pycolmap.TrackElement(i + 1, obs[i][j]) for i in range(8) if j in obs[i]]
        if len(els) >= 2:
            rec.add_point3D(X[j], pycolmap.Track(els), np.zeros(3, np.uint8))
    return rec, cams


def rot_z(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def test_a_frame_whose_pose_agrees_with_its_matches_is_kept_and_a_wrong_one_is_not():
    rec, cams = model({5: rot_z(8.0)})
    v = verify_frames(rec, list(cams.names), max_rot_deg=3.0)
    assert all(v[n]["ok"] for n in cams.names if n != "f05.jpg"), v
    assert all(v[n]["rot_deg"] < 0.5 and v[n]["step"] < 0.01 for n in cams.names if n != "f05.jpg"), v
    assert not v["f05.jpg"]["ok"] and v["f05.jpg"]["why"]


def test_a_frame_with_too_few_matches_to_other_frames_is_not_kept():
    rec, cams = model(n_points=12)
    v = verify_frames(rec, ["f03.jpg"], max_rot_deg=3.0)
    assert not v["f03.jpg"]["ok"] and f"< {VERIFY_MIN_POINTS}" in v["f03.jpg"]["why"]
    assert verify_frames(rec, ["not_there.jpg"], 3.0) == {}


def test_a_part_joins_where_its_frames_check_out_against_the_frames_already_kept():
    """Two parts of a model (cameras 0-3 and 4-7), each sound among itself: the second joins the first
    only where its frames, posed from the points the first part's frames see, land where the model put
    them; moved together by 10 deg about the scene (still agreeing with itself), or tied to the first by
    too few points, it stays out."""
    first, second = {f"f{i:02d}.jpg" for i in range(4)}, {f"f{i:02d}.jpg" for i in range(4, 8)}
    rec, cams = model()
    keep, joins = join_parts(rec, [first, second], 3.0)
    assert keep == first | second and joins == [{"photos": 4, "frames_passed": 4, "joined": True}]
    rec, _ = model(moved=rot_z(10.0))
    keep, joins = join_parts(rec, [first, second], 3.0)
    assert keep == first and joins[0]["joined"] is False and joins[0]["frames_passed"] < JOIN_MIN_FRAMES
    rec, _ = model(n_points=20)
    keep, joins = join_parts(rec, [first, second], 3.0)
    assert keep == first and joins[0]["frames_passed"] == 0
    assert join_parts(rec, [], 3.0) == (set(), [])


def test_a_part_joins_through_another_that_joined_first():
    """Parts are tied one to another in turn: a part that only a later part touches still joins."""
    rec, _ = model()
    a, b, c = {"f00.jpg", "f01.jpg"}, {"f02.jpg", "f03.jpg", "f04.jpg"}, {"f05.jpg", "f06.jpg", "f07.jpg"}
    keep, joins = join_parts(rec, [a, b, c], 3.0)
    assert keep == a | b | c and all(j["joined"] for j in joins)
    v = verify_frames(rec, ["f05.jpg"], 3.0, trusted={"f05.jpg", "f06.jpg"})   # itself and one other: never enough
    assert not v["f05.jpg"]["ok"] and "matches to points" in v["f05.jpg"]["why"]
