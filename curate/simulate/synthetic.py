"""Procedural indoor scenes and a CPU ray-casting renderer (open3d / Embree).

A scene is a room (floor at z = 0, z up; walls, floor and ceiling as 0.2 m slabs outside
the interior box) furnished with axis-aligned boxes, vertical cylinders and spheres. Every
solid is closed and known analytically, so the scene gives exact occupancy. Surfaces carry
procedural 3D textures (multi-octave value noise, checkers, stripes, colour patches:
plenty of corners for SfM features), shaded diffusely by point lights with ray-traced
shadows plus an ambient term. Everything is deterministic from (layout, seed).

Rendering follows the project's conventions: OpenCV cameras, pixel (i, j) centred at
(i + 0.5, j + 0.5); depth is the camera-frame z (as a depth sensor gives), inf where a
ray escapes (it cannot inside a closed room).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from curate.core.cameras import Cameras

LAYOUTS = ("livingroom", "office", "kitchen")
PATTERNS = ("noise", "checker", "stripes", "patches")


@dataclass(frozen=True)
class Material:
    """Albedo ``color`` [3] in [0, 1] modulated by a procedural ``pattern`` at ``freq`` cycles per metre."""

    color: tuple
    pattern: str = "noise"
    freq: float = 4.0
    color2: tuple = (0.1, 0.1, 0.1)
    seed: int = 0


@dataclass(frozen=True)
class Solid:
    """A closed solid: ``box`` (lo, hi corners), ``cylinder`` (vertical; lo = base centre, hi[0] = radius,
    hi[2] = height) or ``sphere`` (lo = centre, hi[0] = radius)."""

    kind: str
    lo: tuple
    hi: tuple
    material: Material

    def contains(self, p: np.ndarray) -> np.ndarray:
        """[n] bool, points [n, 3] inside (boundary included)."""
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        if self.kind == "box":
            return np.all((p >= lo) & (p <= hi), axis=1)
        if self.kind == "cylinder":
            r2 = ((p[:, :2] - lo[:2]) ** 2).sum(1)
            return (r2 <= hi[0] ** 2) & (p[:, 2] >= lo[2]) & (p[:, 2] <= lo[2] + hi[2])
        return ((p - lo) ** 2).sum(1) <= hi[0] ** 2

    def mesh(self):
        import open3d as o3d
        lo, hi = np.asarray(self.lo, float), np.asarray(self.hi, float)
        if self.kind == "box":
            m = o3d.geometry.TriangleMesh.create_box(*(hi - lo))
            m.translate(lo)
        elif self.kind == "cylinder":
            m = o3d.geometry.TriangleMesh.create_cylinder(hi[0], hi[2], resolution=48, split=1)
            m.translate(lo + [0, 0, hi[2] / 2])
        else:
            m = o3d.geometry.TriangleMesh.create_sphere(hi[0], resolution=32)
            m.translate(lo)
        return m


@dataclass
class Scene:
    """A furnished room.

    Attributes:
        name: layout name.
        interior: (lo [3], hi [3]) the room's free interior box.
        solids: every solid, walls included.
        lights: [L, 3] point light positions.
        free_box: (lo, hi) an open region of the room, clear of furniture (the paper's B^f).
        poi: [3] point of interest (hemisphere captures look at it).
    """

    name: str
    interior: tuple
    solids: list
    lights: np.ndarray
    free_box: tuple
    poi: np.ndarray
    _rc: object = field(default=None, repr=False)

    # ------------------------------------------------------------------ geometry
    def _raycaster(self):
        if self._rc is None:
            import open3d as o3d
            rc = o3d.t.geometry.RaycastingScene()
            for s in self.solids:
                rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(s.mesh()))
            self._rc = rc
        return self._rc

    def occupied(self, points: np.ndarray) -> np.ndarray:
        """[n] bool: inside a solid or outside the room's interior (exact, analytic)."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        lo, hi = self.interior
        out = ~np.all((p > lo) & (p < hi), axis=1)
        for s in self.solids[6:]:  # the first six are the room's slabs
            out |= s.contains(p)
        return out

    def cast(self, origins: np.ndarray, dirs: np.ndarray) -> dict:
        """Cast rays [n, 3] + [n, 3] (directions need not be unit); returns open3d's hit dict as numpy."""
        import open3d as o3d
        rays = np.concatenate([origins, dirs], axis=1).astype(np.float32)
        r = self._raycaster().cast_rays(o3d.core.Tensor(rays))
        return {k: v.numpy() for k, v in r.items()}

    # ------------------------------------------------------------------ rendering
    def render(self, cams: Cameras, supersample: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Render every camera.

        Returns:
            rgb: list of [H, W, 3] uint8 images (one per camera; sizes may differ),
            depth: list of [H, W] float32 camera-frame depths.
        """
        rgbs, depths = [], []
        for k in range(len(cams)):
            rgb, depth = self._render_one(cams[k], max(1, int(supersample)))
            rgbs.append(rgb)
            depths.append(depth)
        return rgbs, depths

    def depth(self, cams: Cameras) -> np.ndarray:
        """[N, H, W] float32 camera-frame depth of every camera (all of one size), one batched cast."""
        if len(cams) == 0:
            return np.zeros((0, 1, 1), np.float32)
        W, H = int(cams.width[0]), int(cams.height[0])
        if np.any(cams.width != W) or np.any(cams.height != H):
            raise ValueError("depth(): all cameras must have one image size")
        uu, vv = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
        x = (uu.ravel()[None] - cams.cx[:, None]) / cams.fx[:, None]              # [N, H*W]
        y = (vv.ravel()[None] - cams.cy[:, None]) / cams.fy[:, None]
        d = np.stack([x, y, np.ones_like(x)], -1) @ np.transpose(cams.rotations, (0, 2, 1))  # [N, H*W, 3]
        o = np.broadcast_to(cams.centres[:, None, :], d.shape)
        t = self.cast(o.reshape(-1, 3), d.reshape(-1, 3))["t_hit"]
        return t.reshape(len(cams), H, W).astype(np.float32)

    def _render_one(self, cam: Cameras, ss: int):
        W, H = int(cam.width[0]), int(cam.height[0])
        off = (np.arange(ss) + 0.5) / ss
        u = (np.arange(W)[:, None] + off[None]).ravel()
        v = (np.arange(H)[:, None] + off[None]).ravel()
        uu, vv = np.meshgrid(u, v)                                  # [H*ss, W*ss]
        d_cam = np.stack([(uu - cam.cx[0]) / cam.fx[0], (vv - cam.cy[0]) / cam.fy[0], np.ones_like(uu)], -1)
        R = cam.rotations[0]
        d = d_cam.reshape(-1, 3) @ R.T                              # [n, 3], camera z component 1
        o = np.broadcast_to(cam.centres[0], d.shape)
        hit = self.cast(o, d)
        t = hit["t_hit"].astype(np.float64)                         # along d: equals the camera-frame z
        ok = np.isfinite(t)
        p = o + d * np.where(ok, t, 0.0)[:, None]
        n = hit["primitive_normals"].astype(np.float64)
        n *= -np.sign((n * d).sum(1, keepdims=True) + 1e-12)        # face the camera
        rgb = np.zeros((d.shape[0], 3))
        if np.any(ok):
            rgb[ok] = self._albedo(p[ok], hit["geometry_ids"][ok]) * self._shade(p[ok], n[ok])[:, None]
        rgb = np.clip(rgb, 0, 1) ** (1 / 2.2)
        rgb = rgb.reshape(H, ss, W, ss, 3).mean((1, 3))
        depth = np.where(ok, t, np.inf).reshape(H, ss, W, ss)[:, ss // 2, :, ss // 2]
        return (rgb * 255 + 0.5).astype(np.uint8), depth.astype(np.float32)

    def _shade(self, p: np.ndarray, n: np.ndarray) -> np.ndarray:
        """[n] irradiance: ambient + diffuse from each light, with ray-traced shadows."""
        light = np.full(p.shape[0], 0.3)
        for L in self.lights:
            to = L - p
            dist = np.linalg.norm(to, axis=1)
            ldir = to / dist[:, None]
            ndotl = np.clip((n * ldir).sum(1), 0, None)
            lit = ndotl > 0
            vis = np.zeros(p.shape[0], bool)
            if np.any(lit):
                h = self.cast(p[lit] + n[lit] * 1e-3, ldir[lit])
                vis[lit] = h["t_hit"] >= dist[lit] - 2e-3
            light += 0.9 / len(self.lights) * ndotl * vis / (1 + (dist / 4.0) ** 2)
        return light

    def _albedo(self, p: np.ndarray, gid: np.ndarray) -> np.ndarray:
        out = np.zeros((p.shape[0], 3))
        for g in np.unique(gid):
            sel = gid == g
            out[sel] = texture(p[sel], self.solids[int(g)].material)
        return out


# ---------------------------------------------------------------------- textures
def _hash(ix, iy, iz, seed: int) -> np.ndarray:
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791) ^ (seed * 2654435761)
    h &= 0xFFFFFFFF
    h ^= h >> 13
    h = (h * 1274126177) & 0xFFFFFFFF
    h ^= h >> 16
    return h.astype(np.float64) / 4294967295.0


def value_noise(p: np.ndarray, seed: int) -> np.ndarray:
    """[n] smooth value noise in [0, 1] at points [n, 3] (lattice spacing 1)."""
    i = np.floor(p).astype(np.int64)
    f = p - i
    f = f * f * (3 - 2 * f)
    out = np.zeros(p.shape[0])
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                w = ((f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1])
                     * (f[:, 2] if dz else 1 - f[:, 2]))
                out += w * _hash(i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz, seed)
    return out


def fbm(p: np.ndarray, seed: int, octaves: int = 3) -> np.ndarray:
    """[n] fractal noise in [0, 1]."""
    acc, amp, tot = np.zeros(p.shape[0]), 1.0, 0.0
    for o in range(octaves):
        acc += amp * value_noise(p * 2 ** o, seed + 17 * o)
        tot += amp
        amp *= 0.5
    return acc / tot


def texture(p: np.ndarray, m: Material) -> np.ndarray:
    """[n, 3] albedo of material ``m`` at world points [n, 3]."""
    c1, c2 = np.asarray(m.color), np.asarray(m.color2)
    q = p * m.freq
    g = fbm(q, m.seed)
    if m.pattern == "checker":
        k = (np.floor(q).astype(np.int64).sum(1) & 1).astype(float)
        mix = 0.85 * k + 0.15 * g
    elif m.pattern == "stripes":
        mix = 0.5 + 0.5 * np.sin(2 * np.pi * (q[:, 0] + q[:, 1] + 0.5 * q[:, 2]) + 4 * g)
    elif m.pattern == "patches":
        mix = (fbm(q * 0.5, m.seed + 5, 2) > 0.5).astype(float) * 0.8 + 0.2 * g
    else:
        mix = g
    # Fine detail at 8x the pattern's frequency: texture at every scale, as real surfaces have.
    mix = np.clip(mix + 0.35 * (value_noise(q * 8.0, m.seed + 99) - 0.5), 0.0, 1.0)
    return c1 * (1 - mix[:, None]) + c2 * mix[:, None]


# ---------------------------------------------------------------------- layouts
class _Builder:
    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)
        self.solids: list[Solid] = []
        self.k = 0

    def mat(self, pattern=None, freq=None) -> Material:
        r = self.rng
        self.k += 1
        c1 = tuple(r.uniform(0.25, 0.95, 3))
        c2 = tuple(np.clip(np.asarray(c1) * r.uniform(0.1, 0.5) + r.uniform(0, 0.3, 3), 0, 1))
        return Material(c1, pattern or str(r.choice(PATTERNS)), freq or float(r.uniform(2, 8)), c2,
                        int(r.integers(1 << 30)))

    def box(self, lo, hi, m=None):
        self.solids.append(Solid("box", tuple(map(float, lo)), tuple(map(float, hi)), m or self.mat()))

    def cyl(self, base, r, h, m=None):
        self.solids.append(Solid("cylinder", tuple(map(float, base)), (float(r), 0.0, float(h)), m or self.mat()))

    def sphere(self, c, r, m=None):
        self.solids.append(Solid("sphere", tuple(map(float, c)), (float(r), 0.0, 0.0), m or self.mat()))

    def room(self, W, D, H, t=0.2):
        m = lambda p, f: self.mat(p, f)  # noqa: E731
        self.box([-t, -t, -t], [W + t, D + t, 0], m("checker", 2.0))        # floor
        self.box([-t, -t, H], [W + t, D + t, H + t], m("noise", 3.0))       # ceiling
        self.box([-t, -t, 0], [0, D + t, H], m("patches", 1.5))             # walls
        self.box([W, -t, 0], [W + t, D + t, H], m("stripes", 1.0))
        self.box([0, -t, 0], [W, 0, H], m("patches", 2.0))
        self.box([0, D, 0], [W, D + t, H], m("noise", 4.0))

    def table(self, x, y, w, d, h, leg=0.05):
        m = self.mat()
        self.box([x, y, h - 0.04], [x + w, y + d, h], self.mat())
        for lx, ly in ((x, y), (x + w - leg, y), (x, y + d - leg), (x + w - leg, y + d - leg)):
            self.box([lx, ly, 0], [lx + leg, ly + leg, h - 0.04], m)

    def shelf(self, x, y, w, d, h, n=4):
        m = self.mat()
        self.box([x, y, 0], [x + 0.03, y + d, h], m)
        self.box([x + w - 0.03, y, 0], [x + w, y + d, h], m)
        for i in range(n + 1):
            z = i * (h - 0.03) / n
            self.box([x, y, z], [x + w, y + d, z + 0.03], m)
            if i < n:  # books
                bx = x + 0.05
                while bx < x + w - 0.12:
                    bw = self.rng.uniform(0.03, 0.08)
                    bh = self.rng.uniform(0.15, 0.8 * (h / n))
                    self.box([bx, y + 0.02, z + 0.03], [bx + bw, y + d - 0.02, z + 0.03 + bh])
                    bx += bw + self.rng.uniform(0.0, 0.04)


def make_scene(layout: str = "livingroom", seed: int = 0) -> Scene:
    """A furnished room; ``layout`` in LAYOUTS, deterministic from ``seed``."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    b = _Builder(seed * 1000 + LAYOUTS.index(layout))
    j = lambda s=0.1: float(b.rng.uniform(-s, s))  # noqa: E731
    if layout == "livingroom":
        W, D, H = 6.0, 5.0, 2.7
        b.room(W, D, H)
        b.box([0.3, 3.9 + j(), 0], [2.5, 4.8, 0.45])                      # sofa seat
        b.box([0.3, 4.55, 0.45], [2.5, 4.8, 0.9])                         # sofa back
        b.table(1.9 + j(), 2.2 + j(), 1.2, 0.7, 0.45)                     # coffee table
        b.sphere([2.3, 2.5, 0.58], 0.09)
        b.cyl([2.8, 2.6, 0.45], 0.06, 0.22)
        b.box([5.4, 1.0, 0], [5.9, 3.2, 0.55])                            # TV cabinet
        b.box([5.8, 1.4, 0.9], [5.87, 2.8, 1.7])                          # TV
        b.shelf(0.1, 0.1, 1.6 + j(), 0.35, 2.0)
        b.cyl([5.2, 4.4, 0], 0.2, 0.4)                                    # plant
        b.sphere([5.2, 4.4, 0.8], 0.38)
        free = ([1.0, 1.0, 0.9], [4.8, 3.6, 2.2])
        poi = np.array([2.5, 2.55, 0.5])
    elif layout == "office":
        W, D, H = 7.0, 5.0, 2.8
        b.room(W, D, H)
        for k, x in enumerate((0.8, 3.4)):
            b.table(x + j(), 0.3, 1.6, 0.8, 0.75)                          # desks along a wall
            b.box([x + 0.5, 0.45, 0.75], [x + 1.1, 0.5, 1.15])             # monitor
            b.box([x + 0.6, 1.3, 0], [x + 1.0, 1.7, 0.45])                 # chair seat
            b.box([x + 0.6, 1.65, 0.45], [x + 1.0, 1.7, 0.95])             # chair back
        b.shelf(6.5, 0.5, 0.45, 2.4, 2.0)                                 # bookcase (deep along y)
        b.box([6.3, 3.6, 0], [6.9, 4.9, 1.3])                              # filing cabinet
        b.box([2.0, 4.95, 0.9], [4.5, 5.0, 2.0])                           # whiteboard
        b.table(2.2, 2.6 + j(), 1.8, 1.0, 0.75)                            # meeting table
        b.cyl([2.8, 3.0, 0.75], 0.05, 0.12)
        b.sphere([3.5, 3.2, 0.83], 0.08)
        free = ([1.0, 1.9, 1.0], [5.8, 4.3, 2.3])
        poi = np.array([3.1, 3.1, 0.75])
    else:
        W, D, H = 5.0, 4.0, 2.6
        b.room(W, D, H)
        b.box([0, 0, 0], [W, 0.6, 0.9])                                    # counter along a wall
        b.box([0, 0, 1.5], [W, 0.35, 2.2])                                 # upper cabinets
        b.box([0, 0.6, 0], [0.6, 2.4, 0.9])                                # corner counter
        b.box([4.2, 3.2, 0], [4.95, 3.95, 1.9])                            # fridge
        b.table(1.8 + j(), 1.8 + j(), 1.4, 0.9, 0.76)
        for x, y in ((2.0, 2.1), (2.6, 2.3), (2.9, 2.0)):
            b.cyl([x, y, 0.76], 0.07, 0.1)                                 # bowls / cups
        b.sphere([2.3, 2.45, 0.84], 0.08)
        for x in (1.6, 3.3):
            b.box([x, 2.0, 0], [x + 0.4, 2.4, 0.45])                       # stools
        b.cyl([1.0, 0.3, 0.9], 0.1, 0.25)                                  # kettle on the counter
        free = ([1.0, 1.0, 1.0], [4.0, 3.0, 2.2])
        poi = np.array([2.5, 2.25, 0.8])
    lights = np.array([[W * 0.3, D * 0.4, H - 0.15], [W * 0.7, D * 0.6, H - 0.15]])
    lo, hi = np.zeros(3), np.array([W, D, H])
    return Scene(layout, (lo, hi), b.solids, lights, (np.asarray(free[0]), np.asarray(free[1])), poi)
