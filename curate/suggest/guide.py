"""Walking instructions: each suggested pose from the nearest frame of the capture, in the walker's own frame.

The nearest frame is the capture camera whose view is closest to the suggestion's: the distance between the
centres plus the distance between the points both look at ``look_depth`` ahead (a frame the user stood near
*and* looked roughly the same way from, so the instruction is short). The walker's frame at that photo:
*forward* is its viewing direction laid flat (orthogonal to the capture's up), *left* is ``up x forward``.
The step is the suggestion's centre minus the frame's, split into forward / left / up; the turn is the angle
between the two viewing directions laid flat (positive: to the left), the tilt the change of pitch (positive:
up). Distances are in the capture's units ("units": SfM's scale is arbitrary, a transforms.json is often
rescaled), or in metres when the user says the poses are (``--metres``); in metres an instruction also counts
steps of :data:`STEP_M`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from curate.core.cameras import Cameras

STEP_M = 0.7
"""A walking step, in metres (only for captures in metres)."""
MIN_TURN_DEG = 5.0
"""Turns and tilts smaller than this are left out of the text."""
MIN_MOVE = 0.05
"""Moves shorter than this fraction of the look depth are left out of the text."""
_WORDS = ("no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten")


@dataclass
class Instruction:
    """How to get from a capture frame to a suggested pose (module docstring)."""

    frame: int
    """Index of the reference frame in the capture (``RUN/sfm/cameras.json``)."""
    name: str
    """Its camera name (image file)."""
    forward: float
    left: float
    up: float
    """The move, in the capture's units, in the walker's frame at the reference frame."""
    turn_deg: float
    """Yaw change in degrees, positive to the left."""
    tilt_deg: float
    """Pitch change in degrees, positive up."""
    text: str
    """The instruction for a person."""

    def to_dict(self) -> dict:
        return asdict(self)


def view_distance(a: Cameras, b: Cameras, look_depth: float) -> np.ndarray:
    """[len(a), len(b)] distance between centres plus distance between look-at points ``look_depth`` ahead."""
    la = a.centres + look_depth * a.view_dirs
    lb = b.centres + look_depth * b.view_dirs
    dc = np.linalg.norm(a.centres[:, None] - b.centres[None], axis=2)
    dl = np.linalg.norm(la[:, None] - lb[None], axis=2)
    return dc + dl


def nearest_frames(capture: Cameras, sugg: Cameras, look_depth: float) -> np.ndarray:
    """[K] index of each suggestion's nearest capture frame (module docstring)."""
    if len(capture) == 0:
        raise ValueError("no capture frames to start from")
    out = np.zeros(len(sugg), np.int64)
    for s in range(0, len(sugg), 64):
        out[s:s + 64] = view_distance(sugg[s:s + 64], capture, look_depth).argmin(1)
    return out


def _flat(d: np.ndarray, up: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    f = d - up * (d @ up)
    n = float(np.linalg.norm(f))
    if n < 1e-6:                     # looking straight up or down: its image's up laid flat is "forward"
        f = fallback - up * (fallback @ up)
        n = float(np.linalg.norm(f))
    return f / n if n > 1e-12 else np.array([1.0, 0, 0])


def _length(v: float, units: str) -> str:
    v = abs(v)
    return f"{v:.1f} m" if units == "m" else f"{v:.2f} units"


def _count(n: int) -> str:
    return _WORDS[n] if 0 <= n < len(_WORDS) else str(n)


def instruction(ref: Cameras, k: int, sugg: Cameras, s: int, up: np.ndarray, units: str, look_depth: float,
                label: str | None = None) -> Instruction:
    """How to go from camera ``k`` of ``ref`` to camera ``s`` of ``sugg`` (module docstring); ``units``: 'm' or
    'units'; ``label``: how the frame is named in the text (default: its name)."""
    up = np.asarray(up, float)
    fwd = _flat(ref.view_dirs[k], up, -ref.c2w[k, :3, 1])
    left = np.cross(up, fwd)
    delta = sugg.centres[s] - ref.centres[k]
    f, lft, u = float(delta @ fwd), float(delta @ left), float(delta @ up)
    ds = sugg.view_dirs[s]
    fs = _flat(ds, up, -sugg.c2w[s, :3, 1])
    turn = float(np.degrees(np.arctan2(fs @ left, fs @ fwd)))
    pitch = lambda d: float(np.degrees(np.arcsin(np.clip(d @ up, -1, 1))))  # noqa: E731
    tilt = pitch(ds) - pitch(ref.view_dirs[k])
    thr = MIN_MOVE * look_depth
    moves = []
    for v, pos, neg in ((lft, "left", "right"), (f, "forward", "back")):
        if abs(v) >= thr:
            txt = f"{_length(v, units)} {pos if v > 0 else neg}"
            if units == "m" and round(abs(v) / STEP_M) >= 1:
                n = int(round(abs(v) / STEP_M))
                txt += f" (about {_count(n)} step{'s' if n > 1 else ''})"
            moves.append(txt)
    if abs(u) >= thr:
        moves.append(f"hold the camera {_length(u, units)} {'higher' if u > 0 else 'lower'}")
    looks = []
    if abs(turn) >= MIN_TURN_DEG:
        looks.append(f"turn {abs(turn):.0f}° {'left' if turn > 0 else 'right'}")
    if abs(tilt) >= MIN_TURN_DEG:
        looks.append(f"tilt {abs(tilt):.0f}° {'up' if tilt > 0 else 'down'}")
    what = ", ".join(moves) if moves else "stay where it was taken"
    text = f"From {label or ref.names[k] or f'frame {k}'}: {what}" + (f"; {', '.join(looks)}" if looks else
                                                                       "; look the same way") + "."
    return Instruction(int(k), ref.names[k], f, lft, u, turn, tilt, text)
