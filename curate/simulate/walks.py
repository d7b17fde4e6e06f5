"""Camera trajectories through the synthetic rooms (:mod:`curate.simulate.synthetic`)."""

from __future__ import annotations

import numpy as np

from curate.core.cameras import Cameras, look_at


def room_walk(n_loop: int = 110, n_orbit: int = 50, seed: int = 0) -> Cameras:
    """[n_loop + n_orbit] cameras of the sample walk through the living room (6 x 5 x 2.7 m, z up):
    a loop at eye height looking mostly ahead with head turns, then an orbit of the coffee
    table looking at it; 320x240, 60 degree horizontal field of view. Deterministic."""
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
    return Cameras(c2w, 277.0, 277.0, 160.0, 120.0, 320, 240,
                   names=tuple(f"images/frame_{i:04d}.jpg" for i in range(n)))


def filmed_walk(seed: int = 0, width: int = 320, height: int = 240, fov_deg: float = 60.0
                ) -> tuple[Cameras, np.ndarray]:
    """[N] cameras (N = 200) of a walk through the living room (6 x 5 x 2.7 m, z up) as people film one, candidate
    frames of a video at 5 per second, and [N] the camera's angular speed (radians per frame, for motion blur):
    a first lap that stops twice to look around (frames close together: a fifth of the pace, the head sweeping
    across the room), swings the camera fast twice (blurred frames), turns back for a few steps to film again
    what it passed, then a second, lower and shorter pass the other way round. What an evenly paced walk lacks
    and real walks have: frames crowded where the walker lingered and sparse where they hurried.
    Deterministic from ``seed``; 60 degree horizontal field of view."""
    rng = np.random.default_rng(seed)
    mid, rx, ry = np.array([3.0, 2.5]), 1.8, 1.25
    lap = 2 * np.pi * np.sqrt((rx ** 2 + ry ** 2) / 2)              # metres round the ellipse
    walk, slow = 0.12, 0.02                                         # metres per frame: walking, lingering
    # (frames, metres per frame, head sweep amplitude in radians, second pass?) per stretch
    plan = [(30, walk, 0.0, False), (32, slow, 1.1, False), (26, walk, 0.0, False), (10, -walk, 0.0, False),
            (24, walk, 0.0, False), (28, slow, 0.9, False), (50, 1.4 * walk, 0.0, True)]
    ds = np.concatenate([np.full(k, v) for k, v, _, _ in plan])
    sweep = np.concatenate([np.full(k, a) for k, _, a, _ in plan])
    second = np.concatenate([np.full(k, p) for k, _, _, p in plan])
    n = len(ds)
    f = np.arange(n, dtype=float)
    s = np.cumsum(ds)
    s = np.where(second, s[~second][-1] - (s - s[~second][-1]), s)  # the second pass goes the other way round
    ang = 2 * np.pi * s / lap
    shrink = np.where(second, 0.72, 1.0)
    c = np.stack([mid[0] + shrink * rx * np.cos(ang), mid[1] + shrink * ry * np.sin(ang),
                  np.where(second, 1.15, 1.55) + 0.03 * np.sin(2 * np.pi * f / 3.0)], 1)
    tangent = np.stack([-rx * np.sin(ang), ry * np.cos(ang)], 1) * np.sign(np.gradient(s))[:, None]
    yaw = np.arctan2(tangent[:, 1], tangent[:, 0])
    inward = np.arctan2(mid[1] - c[:, 1], mid[0] - c[:, 0])
    yaw = np.unwrap(yaw + 0.45 * np.angle(np.exp(1j * (inward - yaw))))     # half-way to the room's centre
    win = np.hanning(7)
    yaw = np.convolve(np.pad(yaw, 3, mode="edge"), win / win.sum(), "valid")  # turning round takes a second
    yaw = yaw + sweep * np.sin(2 * np.pi * f / 30.0)                # looking round where the walker stopped
    for at in (70, 150):                                            # two fast swings of the camera
        yaw = yaw + 0.9 * np.exp(-0.5 * ((f - at) / 1.5) ** 2) * np.sign(np.sin(at))
    yaw = yaw + smooth_noise(rng, n, 0.03, 3)
    pitch = -0.15 + 0.08 * np.sin(2 * np.pi * f / 23.0) + smooth_noise(rng, n, 0.02, 3)
    d = np.stack([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)], 1)
    fx = width / 2 / np.tan(np.radians(fov_deg) / 2)
    omega = np.abs(np.gradient(yaw)) + np.abs(np.gradient(pitch))
    cams = Cameras(look_at(c, c + d), fx, fx, width / 2, height / 2, width, height,
                   names=tuple(f"images/frame_{i:04d}.jpg" for i in range(n)))
    return cams, omega


WALK_KINDS = ("loop", "corridor", "turn", "linger", "two_sessions")
"""Kinds of :func:`hand_held_walk`: laps around the room; back and forth along its long side;
standing at a few spots and turning on the spot; lingering slowly, then moving fast; and two
sessions of one room (a loop, then a second, lower loop the other way round, started elsewhere)."""


def smooth_noise(rng, n: int, scale: float, corr: int) -> np.ndarray:
    """[n] zero-mean noise of standard deviation ~``scale``, correlated over ~``corr`` samples."""
    k = max(1, int(corr))
    x = rng.normal(0, 1, n + 2 * k)
    x = np.convolve(x, np.hanning(2 * k + 1), mode="same")[k:k + n]
    return scale * x / (x.std() + 1e-12)


def hand_held_walk(n: int, kind: str = "loop", seed: int = 0, width: int = 640, height: int = 480,
                   fov_deg: float = 60.0, speed: float = 0.35, fps: float = 10.0,
                   room: tuple = ((0.0, 0.0, 0.0), (6.0, 5.0, 2.7))) -> tuple[Cameras, np.ndarray]:
    """[n] cameras of a hand-held walk of ``kind`` (:data:`WALK_KINDS`) through a room of interior
    box ``room`` (z up), one per video frame at ``fps``, and [n] the camera's angular speed
    (radians per frame, for motion blur).

    The walker moves at ``speed`` m/s (``linger``: a fifth of it, then three times it) at eye
    height with a bob, looks half-way between ahead and the room's centre with slow head turns, and the hand adds shake
    (a few tenths of a degree per frame, correlated over a few frames) and roll. Frames are
    named ``frame_00000.png``...; deterministic from (n, kind, seed).
    """
    if kind not in WALK_KINDS:
        raise ValueError(f"walk kind must be one of {WALK_KINDS}, got {kind!r}")
    if n < 2:
        raise ValueError("a walk needs at least 2 frames")
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(room[0], float), np.asarray(room[1], float)
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    step = speed / fps
    f = np.arange(n, dtype=float)
    look = None
    if kind in ("loop", "two_sessions", "linger"):
        if kind == "linger":  # a fifth of the speed for the first 40% of the frames, then three times it
            ds = np.where(f < 0.4 * n, 0.2 * step, 3.0 * step)
        else:
            ds = np.full(n, step)
        s = np.cumsum(ds)
        r = 0.55 + 0.12 * np.sin(2 * np.pi * s / 23.0)            # fraction of the half extent, varies per lap
        ang = s / (np.mean(half[:2]) * 0.55)
        if kind == "two_sessions":                                 # second half: other way round, lower, elsewhere
            second = f >= n // 2
            ang = np.where(second, 2.0 - (ang - ang[n // 2]), ang)
            r = np.where(second, 0.42 + 0.05 * np.sin(ang), r)
        x = mid[0] + r * half[0] * np.cos(ang)
        y = mid[1] + r * half[1] * np.sin(ang)
        z = np.full(n, lo[2] + 1.55)
        if kind == "two_sessions":
            z = np.where(f >= n // 2, lo[2] + 1.15, z)
    elif kind == "corridor":
        s = np.cumsum(np.full(n, step))
        L = 2 * half[0] * 0.6
        u = np.abs(((s / L) % 2) - 1)                                # 0..1..0 triangle wave
        x = mid[0] - L / 2 + L * (1 - u)
        y = mid[1] + 0.35 * half[1] * np.sin(s / 3.1)
        z = np.full(n, lo[2] + 1.55)
    else:  # turn: a few spots, a full turn on each, a short walk between
        spots = mid[:2] + np.array([[0.45 * half[0] * np.cos(a), 0.45 * half[1] * np.sin(a)]
                                    for a in (0.3, 2.4, 4.4)])
        per = n / len(spots)
        k = np.minimum((f // per).astype(int), len(spots) - 1)
        ph = (f - k * per) / per                                     # 0..1 within a spot
        move = ph > 0.85                                             # the last 15%: walk to the next spot
        nxt = np.minimum(k + 1, len(spots) - 1)
        w = np.clip((ph - 0.85) / 0.15, 0, 1)[:, None] * move[:, None]
        xy = spots[k] * (1 - w) + spots[nxt] * w
        x, y = xy[:, 0], xy[:, 1]
        z = np.full(n, lo[2] + 1.55)
        look = 2 * np.pi * (k + np.clip(ph / 0.85, 0, 1))           # yaw: one full turn per spot, continuous
    c = np.stack([x, y, z + 0.03 * np.sin(f * 2 * np.pi * 1.8 / fps)], 1)   # walking bob ~1.8 Hz
    if look is None:
        ahead = np.gradient(c[:, :2], axis=0)
        ahead[np.linalg.norm(ahead, axis=1) < 1e-12] = [1.0, 0.0]
        yaw = np.arctan2(ahead[:, 1], ahead[:, 0])
        inward = np.arctan2(mid[1] - c[:, 1], mid[0] - c[:, 0])     # people look across the room, not at the
        yaw = np.unwrap(yaw + 0.5 * np.angle(np.exp(1j * (inward - yaw))))  # wall beside them: half-way to its centre
        k = int(fps)                                                 # turning round takes a second or two
        win = np.hanning(2 * k + 1)
        yaw = np.convolve(np.pad(yaw, k, mode="edge"), win / win.sum(), "valid")
        yaw = yaw + 0.6 * np.sin(2 * np.pi * f / (6 * fps)) + smooth_noise(rng, n, 0.15, 3 * fps)
    else:
        yaw = look + smooth_noise(rng, n, 0.05, fps)
    shake = 0.004 * np.sqrt(30 / fps)                               # radians of hand shake per frame
    yaw = yaw + smooth_noise(rng, n, shake, 2)
    pitch = -0.12 + 0.1 * np.sin(2 * np.pi * f / (9 * fps)) + smooth_noise(rng, n, shake, 2)
    roll = smooth_noise(rng, n, 0.03, fps)
    d = np.stack([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)], 1)
    c2w = look_at(c, c + d)
    cr, sr = np.cos(roll), np.sin(roll)
    Rz = np.zeros((n, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = cr, -sr, sr, cr, 1.0
    c2w[:, :3, :3] = c2w[:, :3, :3] @ Rz                            # roll about the optical axis
    fx = width / 2 / np.tan(np.radians(fov_deg) / 2)
    omega = np.abs(np.gradient(yaw)) + np.abs(np.gradient(pitch))
    cams = Cameras(c2w, fx, fx, width / 2, height / 2, width, height,
                   names=tuple(f"frame_{i:05d}.png" for i in range(n)))
    return cams, omega


def motion_blur(rgb: np.ndarray, omega: float, fx: float, exposure_frames: float) -> np.ndarray:
    """[H, W, 3] uint8 ``rgb`` blurred as by a camera turning ``omega`` radians per frame with the
    shutter open for ``exposure_frames`` of a frame: a horizontal box blur as long as the image
    moved (``omega * exposure_frames * fx`` pixels; none under 2)."""
    from scipy.ndimage import uniform_filter1d
    n = int(round(omega * exposure_frames * fx))
    if n < 2:
        return rgb
    return uniform_filter1d(rgb.astype(np.float32), n, axis=1, mode="nearest").round().astype(np.uint8)
