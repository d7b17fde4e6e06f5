"""The project's one camera type: batched pinhole cameras, OpenCV camera-to-world.

Convention (used everywhere in curate):

* world frame: whatever the source gave (COLMAP's frame, the transforms.json frame, ...);
* camera frame: OpenCV axes, x right, y down, z forward (the viewing direction);
* pose: ``c2w`` maps camera coordinates to world coordinates, ``X_w = R @ X_c + t``
  with ``c2w = [[R, t], [0, 0, 0, 1]]``; the camera centre is ``t``;
* intrinsics: pinhole ``fx, fy, cx, cy`` in pixels for an image of ``width x height``
  pixels, pixel centres at half-integers (COLMAP's and OpenCV's convention), so a
  point projects to ``u = fx * x / z + cx`` and is inside the image for
  ``0 <= u < width, 0 <= v < height``;
* lens distortion (OpenCV ``k1 k2 p1 p2``) is carried along for export but ignored
  by visibility tests (a few pixels at the border do not change which nodes a
  camera sees in any way that matters for selection).

Every conversion from another convention is written once, here, and round-trip tested:
COLMAP's ``cam_from_world`` (world-to-camera, quaternion ``w x y z``) and NeRF/OpenGL
camera-to-world (x right, y up, z backward) as used by transforms.json.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

# OpenCV <-> OpenGL camera axes: flip y and z. The matrix is its own inverse.
_CV_GL_FLIP = np.diag([1.0, -1.0, -1.0, 1.0])


def _as_f64(a, shape_tail: tuple[int, ...], name: str, names: Sequence[str] = ()) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.shape[1:] != shape_tail or arr.ndim != len(shape_tail) + 1:
        raise ValueError(f"{name}: expected shape [N, {', '.join(map(str, shape_tail))}], got {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr.reshape(len(arr), int(np.prod(shape_tail)))).all(1))
    if len(bad):
        raise ValueError(f"{_which(bad[0], names)}: {name} holds NaN or infinite values")
    return arr


def _which(i: int, names: Sequence[str]) -> str:
    """How a message names camera ``i``: its index, and its name when it has one."""
    i = int(i)
    return f"camera {i} ({names[i]!r})" if i < len(names) and names[i] else f"camera {i}"


@dataclass(frozen=True)
class Cameras:
    """N pinhole cameras with OpenCV camera-to-world poses.

    Attributes:
        c2w: [N, 4, 4] float64, OpenCV camera-to-world.
        fx, fy, cx, cy: [N] float64 intrinsics in pixels.
        width, height: [N] int64 image size in pixels.
        dist: [N, 4] float64 OpenCV distortion ``k1 k2 p1 p2`` (zeros: pinhole).
        names: N image names (file names relative to the photo folder), may be "".
    """

    c2w: np.ndarray
    fx: np.ndarray
    fy: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    width: np.ndarray
    height: np.ndarray
    dist: np.ndarray = field(default=None)  # type: ignore[assignment]
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        c2w = np.asarray(self.c2w, dtype=np.float64)
        if c2w.ndim == 3 and c2w.shape[1:] == (3, 4):
            bottom = np.broadcast_to(np.array([0.0, 0.0, 0.0, 1.0]), (c2w.shape[0], 1, 4))
            c2w = np.concatenate([c2w, bottom], axis=1)
        label = tuple(self.names)
        c2w = _as_f64(c2w, (4, 4), "c2w", label)
        n = c2w.shape[0]
        vals = {}
        for k in ("fx", "fy", "cx", "cy"):
            v = np.broadcast_to(np.asarray(getattr(self, k), dtype=np.float64), (n,)).copy()
            bad = np.flatnonzero(~np.isfinite(v) | ((v <= 0) if k in ("fx", "fy") else False))
            if len(bad):
                raise ValueError(f"{_which(bad[0], label)}: {k} = {v[bad[0]]} is not a usable value"
                                 + (" (a focal length is > 0)" if k in ("fx", "fy") else ""))
            vals[k] = v
        for k in ("width", "height"):
            raw = np.broadcast_to(np.asarray(getattr(self, k), dtype=np.float64), (n,))
            bad = np.flatnonzero(~np.isfinite(raw) | (raw < 1))
            if len(bad):
                raise ValueError(f"{_which(bad[0], label)}: {k} = {raw[bad[0]]} is not a usable value (an image "
                                 "is at least 1 pixel)")
            vals[k] = raw.astype(np.int64)
        dist = np.zeros((n, 4)) if self.dist is None else np.broadcast_to(
            np.asarray(self.dist, dtype=np.float64), (n, 4)).copy()
        bad = np.flatnonzero(~np.isfinite(dist).all(1))
        if len(bad):
            raise ValueError(f"{_which(bad[0], label)}: the distortion (k1 k2 p1 p2) {dist[bad[0]].tolist()} holds NaN "
                             "or infinite values")
        names = tuple(self.names) if len(self.names) else ("",) * n
        if len(names) != n:
            raise ValueError(f"names: expected {n}, got {len(names)}")
        object.__setattr__(self, "c2w", c2w)
        for k, v in vals.items():
            object.__setattr__(self, k, v)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "names", names)

    # ------------------------------------------------------------------ basics
    def __len__(self) -> int:
        return self.c2w.shape[0]

    def __getitem__(self, idx) -> "Cameras":
        """A subset: ``idx`` is an int, slice, index array or boolean mask."""
        if isinstance(idx, (int, np.integer)):
            idx = [int(idx)]
        idx = np.arange(len(self))[idx]
        return Cameras(self.c2w[idx], self.fx[idx], self.fy[idx], self.cx[idx], self.cy[idx],
                       self.width[idx], self.height[idx], self.dist[idx],
                       tuple(self.names[i] for i in idx))

    @staticmethod
    def concat(parts: Sequence["Cameras"]) -> "Cameras":
        if not parts:
            return Cameras.empty()
        return Cameras(*(np.concatenate([getattr(p, k) for p in parts])
                         for k in ("c2w", "fx", "fy", "cx", "cy", "width", "height", "dist")),
                       names=tuple(n for p in parts for n in p.names))

    @staticmethod
    def empty() -> "Cameras":
        return Cameras(np.zeros((0, 4, 4)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0),
                       np.zeros(0, np.int64), np.zeros(0, np.int64))

    @property
    def rotations(self) -> np.ndarray:
        """[N, 3, 3] camera-to-world rotations (columns: camera x, y, z axes in world)."""
        return self.c2w[:, :3, :3]

    @property
    def centres(self) -> np.ndarray:
        """[N, 3] camera centres in world coordinates."""
        return self.c2w[:, :3, 3]

    @property
    def view_dirs(self) -> np.ndarray:
        """[N, 3] unit viewing directions (camera +z) in world coordinates."""
        d = self.c2w[:, :3, 2]
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    @property
    def K(self) -> np.ndarray:
        """[N, 3, 3] intrinsic matrices."""
        k = np.zeros((len(self), 3, 3))
        k[:, 0, 0], k[:, 1, 1], k[:, 0, 2], k[:, 1, 2], k[:, 2, 2] = self.fx, self.fy, self.cx, self.cy, 1
        return k

    def w2c(self) -> tuple[np.ndarray, np.ndarray]:
        """World-to-camera ``(R [N, 3, 3], t [N, 3])`` with ``X_c = R @ X_w + t``."""
        return w2c_from_c2w(self.c2w)

    def scaled_images(self, factor: float) -> "Cameras":
        """The same cameras for images resized by ``factor`` (e.g. 0.25 for 1/4 size).

        Sizes are rounded; focal lengths and principal points follow the actual
        ratio per axis so projections stay exact for the resized image.
        """
        w = np.maximum(1, np.round(self.width * factor)).astype(np.int64)
        h = np.maximum(1, np.round(self.height * factor)).astype(np.int64)
        sx, sy = w / self.width, h / self.height
        return Cameras(self.c2w, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy, w, h,
                       self.dist, self.names)

    def at_most(self, max_side: int) -> "Cameras":
        """The same cameras for images whose longer side is at most ``max_side`` (never upscaled): the size
        the field trains and renders at."""
        return self.scaled_images(np.minimum(1.0, max_side / np.maximum(self.width, self.height)))  # [N]

    def transformed(self, scale: float, R: np.ndarray | None = None, t: np.ndarray | None = None) -> "Cameras":
        """Apply the world similarity ``X' = scale * R @ X + t`` to every pose."""
        R = np.eye(3) if R is None else np.asarray(R, np.float64)
        t = np.zeros(3) if t is None else np.asarray(t, np.float64)
        c2w = self.c2w.copy()
        c2w[:, :3, :3] = R @ self.rotations
        c2w[:, :3, 3] = scale * self.centres @ R.T + t
        return Cameras(c2w, self.fx, self.fy, self.cx, self.cy, self.width, self.height, self.dist, self.names)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pinhole projection of world points into every camera.

        Args:
            points: [M, 3] world points.
        Returns:
            uv: [N, M, 2] pixel coordinates (undefined where depth <= 0),
            depth: [N, M] camera-frame z.
        """
        R, t = self.w2c()
        pc = np.einsum("nij,mj->nmi", R, np.asarray(points, np.float64)) + t[:, None, :]
        z = pc[..., 2]
        safe = np.where(np.abs(z) > 0, z, 1.0)
        u = self.fx[:, None] * pc[..., 0] / safe + self.cx[:, None]
        v = self.fy[:, None] * pc[..., 1] / safe + self.cy[:, None]
        return np.stack([u, v], axis=-1), z

    def to_dict(self) -> dict:
        """JSON-ready dict (the project's own camera file, ``cameras.json``)."""
        return {
            "convention": "opencv_c2w",
            "cameras": [
                {"name": self.names[i], "c2w": self.c2w[i].tolist(),
                 "fx": float(self.fx[i]), "fy": float(self.fy[i]), "cx": float(self.cx[i]), "cy": float(self.cy[i]),
                 "width": int(self.width[i]), "height": int(self.height[i]), "dist": self.dist[i].tolist()}
                for i in range(len(self))
            ],
        }

    @staticmethod
    def from_dict(d: dict) -> "Cameras":
        if d.get("convention", "opencv_c2w") != "opencv_c2w":
            raise ValueError(f"unsupported camera convention {d.get('convention')!r}")
        cams = d["cameras"]
        if not cams:
            return Cameras.empty()
        col = lambda k: np.array([c[k] for c in cams], dtype=np.float64)  # noqa: E731
        return Cameras(col("c2w"), col("fx"), col("fy"), col("cx"), col("cy"),
                       col("width").astype(np.int64), col("height").astype(np.int64),
                       np.array([c.get("dist", [0, 0, 0, 0]) for c in cams], np.float64),
                       tuple(c.get("name", "") for c in cams))

    def save(self, path) -> None:
        import json
        from pathlib import Path
        from curate.core.stage import writing
        with writing(path):
            Path(path).write_text(json.dumps(self.to_dict(), indent=1))

    @staticmethod
    def load(path) -> "Cameras":
        """The cameras of a ``cameras.json``; ValueError naming the file when it is not one."""
        import json
        from pathlib import Path
        try:
            return Cameras.from_dict(json.loads(Path(path).read_text()))
        except (ValueError, KeyError, TypeError) as e:   # truncated, not JSON, not UTF-8, fields missing
            raise ValueError(f"{path}: not a cameras file of curate ({type(e).__name__}: {e}); the stage that "
                             "wrote it can write it again with --force") from None


# ---------------------------------------------------------------------- conversions
def c2w_from_w2c(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """World-to-camera ``R [N, 3, 3], t [N, 3]`` (``X_c = R X_w + t``) -> camera-to-world [N, 4, 4]."""
    R = np.asarray(R, np.float64).reshape(-1, 3, 3)
    t = np.asarray(t, np.float64).reshape(-1, 3)
    out = np.zeros((R.shape[0], 4, 4))
    Rt = np.transpose(R, (0, 2, 1))
    out[:, :3, :3] = Rt
    out[:, :3, 3] = -np.einsum("nij,nj->ni", Rt, t)
    out[:, 3, 3] = 1.0
    return out


def w2c_from_c2w(c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera-to-world [N, 4, 4] -> world-to-camera ``(R [N, 3, 3], t [N, 3])``."""
    c2w = np.asarray(c2w, np.float64).reshape(-1, 4, 4)
    R = np.transpose(c2w[:, :3, :3], (0, 2, 1))
    t = -np.einsum("nij,nj->ni", R, c2w[:, :3, 3])
    return R, t


def opengl_from_opencv(c2w: np.ndarray) -> np.ndarray:
    """OpenCV camera-to-world [N, 4, 4] -> OpenGL/NeRF camera-to-world (y up, z backward)."""
    return np.asarray(c2w, np.float64) @ _CV_GL_FLIP


def opencv_from_opengl(c2w: np.ndarray) -> np.ndarray:
    """OpenGL/NeRF camera-to-world [N, 4, 4] -> OpenCV camera-to-world."""
    return np.asarray(c2w, np.float64) @ _CV_GL_FLIP


def rotmat_from_quat(q: np.ndarray) -> np.ndarray:
    """Unit quaternions [N, 4] in COLMAP order ``w x y z`` -> rotation matrices [N, 3, 3]."""
    q = np.asarray(q, np.float64).reshape(-1, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], axis=1).reshape(-1, 3, 3)


def quat_from_rotmat(R: np.ndarray) -> np.ndarray:
    """Rotation matrices [N, 3, 3] -> unit quaternions [N, 4] ``w x y z`` with ``w >= 0``.

    Uses the largest-diagonal branch for each matrix, stable near 180 degrees.
    """
    R = np.asarray(R, np.float64).reshape(-1, 3, 3)
    q = np.zeros((R.shape[0], 4))
    tr = np.trace(R, axis1=1, axis2=2)
    diag = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    best = np.argmax(diag, axis=1)
    for i in range(R.shape[0]):
        m = R[i]
        if best[i] == 0:
            s = 2.0 * np.sqrt(max(1.0 + tr[i], 1e-300))
            q[i] = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
        elif best[i] == 1:
            s = 2.0 * np.sqrt(max(1.0 + m[0, 0] - m[1, 1] - m[2, 2], 1e-300))
            q[i] = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
        elif best[i] == 2:
            s = 2.0 * np.sqrt(max(1.0 - m[0, 0] + m[1, 1] - m[2, 2], 1e-300))
            q[i] = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
        else:
            s = 2.0 * np.sqrt(max(1.0 - m[0, 0] - m[1, 1] + m[2, 2], 1e-300))
            q[i] = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    return q


def c2w_from_colmap(qvec_wxyz: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """COLMAP ``cam_from_world`` (quaternion ``w x y z`` [N, 4], translation [N, 3]) -> OpenCV c2w [N, 4, 4]."""
    return c2w_from_w2c(rotmat_from_quat(qvec_wxyz), tvec)


def colmap_from_c2w(c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV c2w [N, 4, 4] -> COLMAP ``cam_from_world`` as (quaternion ``w x y z`` [N, 4], translation [N, 3])."""
    R, t = w2c_from_c2w(c2w)
    return quat_from_rotmat(R), t


def look_at(centres: np.ndarray, targets: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """OpenCV c2w [N, 4, 4] for cameras at ``centres`` [N, 3] looking at ``targets`` [N, 3].

    The image's "down" (+y) points along ``-up`` as far as possible; a view straight
    along ``up`` falls back to another reference axis (no NaN).
    """
    centres = np.atleast_2d(np.asarray(centres, np.float64))
    targets = np.broadcast_to(np.asarray(targets, np.float64), centres.shape)
    z = targets - centres
    zn = np.linalg.norm(z, axis=1, keepdims=True)
    if np.any(zn == 0):
        raise ValueError("look_at: a camera centre equals its target")
    z = z / zn
    up = np.broadcast_to(np.asarray(up, np.float64), centres.shape)
    x = np.cross(z, up)
    bad = np.linalg.norm(x, axis=1) < 1e-9
    if np.any(bad):
        alt = np.where(np.abs(z[bad, 0:1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
        x[bad] = np.cross(z[bad], alt)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    out = np.zeros((centres.shape[0], 4, 4))
    out[:, :3, 0], out[:, :3, 1], out[:, :3, 2], out[:, :3, 3], out[:, 3, 3] = x, y, z, centres, 1.0
    return out


ROTATION_TOL = 1e-3
""":func:`check_poses`: largest allowed |R^T R - I| entry of a camera rotation."""


MAX_FOV_DEG = 170.0
""":func:`check_poses`: the widest field of view (degrees, across the width or the height) a perspective camera
may have; 180 is none (``camera_angle_x = pi`` made a focal length of 1e-14 pixels)."""
MIN_FOV_DEG = 0.05
""":func:`check_poses`: the narrowest (the longest telephoto is about 1 degree)."""
MAX_RADIAL = 5.0
""":func:`check_poses`: the radial distortion may stretch or shrink a ray's distance from the image centre at most
this many times, anywhere in the image (``k1 = 1e10`` exported an all-black undistorted image)."""
MAX_TANGENTIAL = 0.1
""":func:`check_poses`: largest |p1| and |p2| (a real lens has under 0.01)."""
MAX_COORD = 1e12
""":func:`check_poses`: largest coordinate of a camera centre (a centre at 1e300 overflowed every distance)."""
MAX_SPREAD = 1e6
""":func:`check_poses`: a camera farther from the others' median centre than this many times their median
distance from it is a broken pose, not a camera of the capture."""

FIELDS = {"c2w": "c2w", "centre": "c2w's translation", "fx": "fx", "fy": "fy", "cx": "cx", "cy": "cy",
          "width": "width", "height": "height", "dist": "dist (k1 k2 p1 p2)", "k1 k2": "k1 k2",
          "p1 p2": "p1 p2"}
"""How :func:`check_poses` names each field in its messages (a reader passes its file's own names)."""


def radial_range(k1: float, k2: float, r_max: float) -> tuple[float, float, bool]:
    """(smallest, largest) radial factor ``1 + k1 r^2 + k2 r^4`` over ``0 <= r <= r_max`` (normalised image
    radius), and whether the distorted radius ``r * factor`` keeps increasing there (a lens that folds the image
    back on itself has no inverse)."""
    r = np.linspace(0.0, max(float(r_max), 0.0), 257)
    with np.errstate(all="ignore"):
        f = 1 + k1 * r ** 2 + k2 * r ** 4
        d = 1 + 3 * k1 * r ** 2 + 5 * k2 * r ** 4
    ok = bool(np.all(np.isfinite(f)) and np.all(d > 0))
    return float(np.min(f)), float(np.max(f)), ok


def check_poses(c2w, fx, fy, cx, cy, width, height, labels, source: str, dist=None,
                fields: dict | None = None) -> None:
    """ValueError, one line naming ``source``, the frame and the field, unless every camera is one a camera can be.

    ``c2w`` [N, 4, 4] camera-to-world: finite, rotation orthonormal within :data:`ROTATION_TOL` with
    determinant +1 (not scaled, sheared or mirrored), bottom row [0, 0, 0, 1], centre within :data:`MAX_COORD` and
    not :data:`MAX_SPREAD` times farther from the others than they are from each other; intrinsics ``fx fy`` finite
    and > 0 with a field of view between :data:`MIN_FOV_DEG` and :data:`MAX_FOV_DEG`, ``cx cy`` finite,
    ``width height`` >= 1; ``dist`` [N, 4] (k1 k2 p1 p2) finite, the radial part within :data:`MAX_RADIAL` and
    never folding the image (:func:`radial_range`), the tangential within :data:`MAX_TANGENTIAL`. ``labels`` [N]:
    how to name each frame (its file path); ``fields``: how the file names a field (:data:`FIELDS`'s keys)."""
    name = {**FIELDS, **(fields or {})}
    c2w = np.asarray(c2w, np.float64)
    arrays = {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "width": width, "height": height}
    n = len(c2w)
    dist = np.zeros((n, 4)) if dist is None else np.broadcast_to(np.asarray(dist, np.float64), (n, 4))

    def what(i: int) -> str:
        return (f"{source}: frame {i} ({labels[i]!r})" if labels is not None and i < len(labels)
                else f"{source}: frame {i}")

    def value(k: str, i: int) -> float:
        v = arrays[k]
        return float(np.asarray(v, np.float64).reshape(-1)[i] if np.ndim(v) else v)
    for i in range(n):
        m = c2w[i]
        if not np.all(np.isfinite(m)):
            raise ValueError(f"{what(i)}: {name['c2w']}: the pose holds NaN or infinite values")
        if np.max(np.abs(m[3] - [0.0, 0.0, 0.0, 1.0])) > 1e-6:
            raise ValueError(f"{what(i)}: {name['c2w']}: the pose's bottom row is {m[3].tolist()}, not [0, 0, 0, 1]")
        R = m[:3, :3]
        err = float(np.max(np.abs(R.T @ R - np.eye(3))))
        if err > ROTATION_TOL:
            raise ValueError(f"{what(i)}: {name['c2w']}: the rotation is not orthonormal (|R^T R - I| = {err:.3g}: "
                             "scaled or sheared)")
        if np.linalg.det(R) < 0:
            raise ValueError(f"{what(i)}: {name['c2w']}: the rotation is a reflection (determinant -1)")
        if np.max(np.abs(m[:3, 3])) > MAX_COORD:
            raise ValueError(f"{what(i)}: {name['centre']}: the camera centre {m[:3, 3].tolist()} lies beyond "
                             f"{MAX_COORD:g}: not a position a camera can have")
        for k in arrays:
            x = value(k, i)
            if not np.isfinite(x) or (k in ("fx", "fy") and x <= 0) or (k in ("width", "height") and x < 1):
                raise ValueError(f"{what(i)}: {name[k]} = {x} is not a usable value")
        for f, side in (("fx", "width"), ("fy", "height")):
            fov = float(np.degrees(2 * np.arctan(0.5 * value(side, i) / value(f, i))))
            if not MIN_FOV_DEG <= fov <= MAX_FOV_DEG:
                raise ValueError(f"{what(i)}: {name[f]} = {value(f, i):.6g} gives a field of view of {fov:.3g} "
                                 f"degrees across the {side}: a perspective camera has between {MIN_FOV_DEG:g} and "
                                 f"{MAX_FOV_DEG:g}")
        d = dist[i]
        if not np.all(np.isfinite(d)):
            raise ValueError(f"{what(i)}: {name['dist']} = {d.tolist()} holds NaN or infinite values")
        if np.any(d[:2] != 0):
            r_max = float(np.hypot(max(value("cx", i), value("width", i) - value("cx", i)) / value("fx", i),
                                   max(value("cy", i), value("height", i) - value("cy", i)) / value("fy", i)))
            lo, hi, ok = radial_range(d[0], d[1], r_max)
            if not ok or hi > MAX_RADIAL or lo < 1 / MAX_RADIAL:
                why = ("folds the image back on itself" if not ok else
                       f"scales the distance from the centre by {hi if hi > MAX_RADIAL else lo:.3g} at the image's "
                       f"edge (a lens stays within 1/{MAX_RADIAL:g} and {MAX_RADIAL:g})")
                raise ValueError(f"{what(i)}: {name['k1 k2']} = {d[0]:.6g} {d[1]:.6g}: this radial distortion {why}")
        if np.max(np.abs(d[2:])) > MAX_TANGENTIAL:
            raise ValueError(f"{what(i)}: {name['p1 p2']} = {d[2]:.6g} {d[3]:.6g}: tangential distortion beyond "
                             f"{MAX_TANGENTIAL:g} is not a lens's")
    if n >= 3:
        centres = c2w[:, :3, 3]
        mid = np.median(centres, axis=0)
        dev = np.linalg.norm(centres - mid, axis=1)
        spread = float(np.median(dev))
        far = np.flatnonzero(dev > MAX_SPREAD * spread) if spread > 0 else np.zeros(0, int)
        if len(far):
            i = int(far[np.argmax(dev[far])])
            raise ValueError(f"{what(i)}: {name['centre']}: the camera centre {centres[i].tolist()} is "
                             f"{dev[i] / spread:.3g} times farther from the others than they are from each other: "
                             "a broken pose, not a camera of this capture")


def rotation_angle_deg(R: np.ndarray) -> np.ndarray:
    """Degrees turned by each rotation of R [..., 3, 3] (shape [...]; a single [3, 3] gives a 0-d array),
    the trace clipped so that rounding never makes a NaN."""
    R = np.asarray(R, np.float64)
    return np.degrees(np.arccos(np.clip((np.trace(R, axis1=-2, axis2=-1) - 1) / 2, -1.0, 1.0)))


def rotation_disagreement(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """[n] degrees: how far two reconstructions of the same n cameras disagree on each camera's
    orientation, once one rotation brings frame b onto frame a.

    Ra, Rb: [n, 3, 3] camera-to-world rotations of the same cameras in two world frames (any
    similarity apart: scale and translation do not enter). The aligning rotation Q (Ra_i ~ Q Rb_i)
    is the least-squares one, the projection of sum_i Ra_i Rb_i^T onto SO(3). 0 for n = 0.
    """
    Ra, Rb = np.asarray(Ra, np.float64), np.asarray(Rb, np.float64)
    if len(Ra) == 0:
        return np.zeros(0)
    U, _, Vt = np.linalg.svd((Ra @ np.transpose(Rb, (0, 2, 1))).sum(0))
    Q = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    E = np.transpose(Ra, (0, 2, 1)) @ Q @ Rb                   # identity where they agree
    return rotation_angle_deg(E)
