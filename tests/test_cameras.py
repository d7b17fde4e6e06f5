"""Camera type and conversions: every conversion round-trips, and agrees with a hand-made case."""

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from curate.core.cameras import (Cameras, c2w_from_colmap, c2w_from_w2c, colmap_from_c2w, look_at, opencv_from_opengl,
                            opengl_from_opencv, quat_from_rotmat, rotmat_from_quat, w2c_from_c2w)
from curate.core.transforms_json import read_transforms, write_transforms
from conftest import random_pool, shared_data


def random_rotations(n, seed=0):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return rotmat_from_quat(q)


def test_quaternion_round_trip_including_half_turns():
    R = np.concatenate([random_rotations(200), np.diag([1.0, -1, -1])[None], np.diag([-1.0, 1, -1])[None],
                        np.diag([-1.0, -1, 1])[None], np.eye(3)[None]])
    q = quat_from_rotmat(R)
    assert np.allclose(np.linalg.norm(q, axis=1), 1)
    assert np.all(q[:, 0] >= 0)
    assert np.allclose(rotmat_from_quat(q), R, atol=1e-12)


def test_colmap_convention_by_hand():
    # COLMAP: X_cam = R X_world + t. A camera at world (0, 0, -5) looking down +z with no rotation
    # has R = I, t = -R C = (0, 0, 5).
    c2w = c2w_from_colmap(np.array([[1.0, 0, 0, 0]]), np.array([[0.0, 0, 5]]))
    assert np.allclose(c2w[0, :3, 3], [0, 0, -5])
    assert np.allclose(c2w[0, :3, :3], np.eye(3))
    q, t = colmap_from_c2w(c2w)
    assert np.allclose(q, [[1, 0, 0, 0]]) and np.allclose(t, [[0, 0, 5]])


def test_w2c_c2w_and_colmap_round_trip():
    cams = random_pool(50, seed=3)
    R, t = w2c_from_c2w(cams.c2w)
    assert np.allclose(c2w_from_w2c(R, t), cams.c2w, atol=1e-12)
    q, t2 = colmap_from_c2w(cams.c2w)
    assert np.allclose(c2w_from_colmap(q, t2), cams.c2w, atol=1e-12)
    # World points go to the camera frame and back.
    X = np.random.default_rng(0).normal(size=(5, 3))
    Xc = np.einsum("nij,mj->nmi", R, X) + t[:, None]
    back = np.einsum("nij,nmj->nmi", cams.rotations, Xc) + cams.centres[:, None]
    assert np.allclose(back, X[None], atol=1e-12)


def test_opengl_opencv_round_trip_and_axes():
    cams = random_pool(10, seed=1)
    gl = opengl_from_opencv(cams.c2w)
    assert np.allclose(opencv_from_opengl(gl), cams.c2w)
    # OpenGL looks down its -z: the same world direction as OpenCV's +z.
    assert np.allclose(-gl[:, :3, 2], cams.view_dirs)
    assert np.allclose(gl[:, :3, 1], -cams.c2w[:, :3, 1])  # y up vs y down


def test_look_at_projects_target_to_principal_point():
    cams = Cameras(look_at([[1.0, 2, 3], [0, 0, 5], [0, 0, -4]], [[0.0, 0, 0]] * 3), 100.0, 100.0, 64.0, 48.0, 128, 96)
    uv, z = cams.project(np.zeros((1, 3)))
    assert np.allclose(uv[:, 0], [64, 48]) and np.all(z > 0)
    # Rotations are proper (det +1), even for views straight along "up".
    assert np.allclose(np.linalg.det(cams.rotations), 1.0)
    # Image "down" points away from world up where possible.
    assert cams.c2w[0, 2, 1] < 0


def test_subset_concat_save_load(tmp_path):
    cams = random_pool(6, seed=2)
    cams = Cameras(cams.c2w, cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height,
                   np.tile([0.1, -0.01, 0.001, 0.0], (6, 1)), tuple(f"im{i}.jpg" for i in range(6)))
    sub = cams[[4, 1]]
    assert sub.names == ("im4.jpg", "im1.jpg") and np.allclose(sub.c2w[0], cams.c2w[4])
    both = Cameras.concat([sub, cams[5]])
    assert len(both) == 3
    cams.save(tmp_path / "c.json")
    back = Cameras.load(tmp_path / "c.json")
    for k in ("c2w", "fx", "fy", "cx", "cy", "width", "height", "dist"):
        assert np.array_equal(getattr(back, k), getattr(cams, k))
    assert back.names == cams.names


def test_invalid_cameras_raise():
    with pytest.raises(ValueError):
        Cameras(np.full((1, 4, 4), np.nan), 1.0, 1.0, 0.0, 0.0, 10, 10)
    with pytest.raises(ValueError):
        Cameras(np.eye(4)[None], -1.0, 1.0, 0.0, 0.0, 10, 10)
    with pytest.raises(ValueError):
        Cameras(np.eye(4)[None], 1.0, 1.0, 0.0, 0.0, 0, 10)


def test_scaled_images_keep_projection():
    cams = random_pool(4, seed=5, size=(640, 480), fx=500.0)
    X = np.random.default_rng(1).normal(size=(20, 3))
    uv, _ = cams.project(X)
    uv2, _ = cams.scaled_images(0.25).project(X)
    assert np.allclose(uv2, uv * 0.25)


@pytest.mark.parametrize("shared", [True, False])
def test_transforms_json_round_trip(tmp_path, shared):
    cams = random_pool(5, seed=7, size=(320, 240))
    if not shared:
        cams = Cameras(cams.c2w, cams.fx * np.arange(1, 6), cams.fy * np.arange(1, 6), cams.cx, cams.cy,
                       cams.width, cams.height, np.tile([0.05, 0.0, 0.0, 0.001], (5, 1)), cams.names)
    p = write_transforms(tmp_path / "transforms.json", cams, [f"images/{i}.png" for i in range(5)])
    meta = json.loads(p.read_text())
    assert ("fl_x" in meta) == shared
    back, files = read_transforms(p)
    for k in ("c2w", "fx", "fy", "cx", "cy", "width", "height", "dist"):
        assert np.allclose(getattr(back, k), getattr(cams, k), atol=1e-12), k
    assert files[0] == str(tmp_path / "images/0.png")


def test_transforms_camera_angle_x_and_image_size_from_file(tmp_path):
    from PIL import Image
    (tmp_path / "train").mkdir()
    Image.new("RGB", (200, 100)).save(tmp_path / "train" / "r_0.png")
    gl = np.eye(4)
    gl[:3, 3] = [0, 0, 4]  # OpenGL camera at +4 z looking down -z: towards the origin
    (tmp_path / "transforms.json").write_text(json.dumps(
        {"camera_angle_x": 2 * math.atan(0.5),
         "frames": [{"file_path": "./train/r_0", "transform_matrix": gl.tolist()}]}))
    cams, files = read_transforms(tmp_path / "transforms.json")
    # tan(angle/2) = 0.5 -> fx = 0.5 * w / 0.5 = w.
    assert (cams.width[0] == 200 and cams.height[0] == 100 and np.isclose(cams.fx[0], 200)
            and np.isclose(cams.fy[0], 200))
    assert np.isclose(cams.cx[0], 100) and np.isclose(cams.cy[0], 50)
    assert np.allclose(cams.view_dirs[0], [0, 0, -1])
    assert files[0].endswith("r_0.png")


def test_transforms_errors(tmp_path):
    p = tmp_path / "t.json"
    p.write_text(json.dumps({"frames": []}))
    with pytest.raises(ValueError, match="frames"):
        read_transforms(p)
    p.write_text(json.dumps({"w": 10, "h": 10, "frames": [{"transform_matrix": np.eye(4).tolist()}]}))
    with pytest.raises(ValueError, match="fl_x"):
        read_transforms(p)


def test_fox_transforms_read_matches_file():
    path = shared_data("fox") / "transforms.json"
    cams, files = read_transforms(path)
    meta = json.loads(path.read_text())
    assert len(cams) == len(meta["frames"]) == 67
    assert np.isclose(cams.fx[0], meta["fl_x"]) and cams.width[0] == 1080 and cams.height[0] == 1920
    gl = np.array(meta["frames"][10]["transform_matrix"])
    assert np.allclose(opengl_from_opencv(cams.c2w[10:11])[0], gl)
    assert all(__import__("os").path.exists(f) for f in files)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3), min_size=7, max_size=7).filter(lambda v: np.linalg.norm(v[:4]) > 1e-3))
def test_pose_round_trip_property(v):
    c2w = c2w_from_colmap(np.array([v[:4]]), np.array([v[4:]]))
    q, t = colmap_from_c2w(c2w)
    assert np.allclose(c2w_from_colmap(q, t), c2w, atol=1e-9 * max(1.0, np.abs(v[4:]).max()))


def test_rotation_disagreement_ignores_the_frame_and_finds_the_bent_camera():
    from scipy.spatial.transform import Rotation

    from curate.core.cameras import rotation_disagreement
    rng = np.random.default_rng(0)
    Rb = Rotation.random(40, random_state=1).as_matrix()
    Q = Rotation.random(random_state=2).as_matrix()
    Ra = Q @ Rb                                              # the same cameras in another world frame
    assert np.allclose(rotation_disagreement(Ra, Rb), 0, atol=1e-5)
    bent = Ra.copy()
    bent[7] = Rotation.from_rotvec([0, 0, np.radians(10)]).as_matrix() @ bent[7]
    d = rotation_disagreement(bent, Rb)
    assert 9.0 < d[7] < 10.5 and np.median(d) < 0.5
    half = Ra.copy()                                         # half the cameras turned 14 deg: a bent model
    half[20:] = Rotation.from_rotvec([np.radians(14), 0, 0]).as_matrix() @ half[20:]
    assert np.median(rotation_disagreement(half, Rb)) > 5
    assert rotation_disagreement(np.zeros((0, 3, 3)), np.zeros((0, 3, 3))).shape == (0,)
    noisy = Rotation.from_rotvec(rng.normal(0, 1e-3, (40, 3))).as_matrix() @ Ra
    assert np.isfinite(rotation_disagreement(noisy, Rb)).all()


def test_rotation_angle_is_the_turn_of_each_rotation_and_never_nan():
    from scipy.spatial.transform import Rotation

    from curate.core.cameras import rotation_angle_deg
    angles = np.array([0.0, 1e-7, 5.0, 90.0, 179.999, 180.0])
    R = Rotation.from_rotvec(np.radians(angles)[:, None] * [[0.0, 0.6, 0.8]]).as_matrix()
    assert np.allclose(rotation_angle_deg(R), angles, atol=1e-3)
    assert rotation_angle_deg(R[3]).shape == () and abs(float(rotation_angle_deg(R[3])) - 90.0) < 1e-9
    noisy = np.eye(3) * (1 + 1e-12)                      # a trace just over 3, as rounding gives
    assert float(rotation_angle_deg(noisy)) == 0.0 and rotation_angle_deg(np.zeros((0, 3, 3))).shape == (0,)
