"""Synthetic-room experiments: the paper's comparison of camera placements.

For a procedural room (:mod:`curate.simulate.synthetic`), each method places ``budget`` cameras:

* ``ours``: progressive placement by the energy (Algorithm 1, :mod:`curate.simulate.progressive`);
* ``random``: random cameras in free space (the same rejection test as ours);
* ``hemisphere``: cameras on a hemisphere around the room's point of interest, looking at it
  (the usual object-centric capture), kept where they are in free space;
* ``fvs``: farthest-view sampling (position and orientation) from a large random free-space pool.

The photos are rendered, the same field is trained on each set, and PSNR/SSIM are measured
on three test sets drawn the hemisphere, random and ours ways (all distinct from every
training set), as in the paper's table.

Occupancy for ours (``SimulateConfig.occupancy``): ``"oracle"`` rejects candidates with
the scene's exact geometry; ``"field"`` is the paper's setting (Algorithm 1): after each
added camera its photo is rendered ("taken"), the loop's field resumes training for
``train_between`` iterations on all photos taken so far, and the next step's occupancy
comes from that field (:class:`curate.simulate.progressive.FieldOracle`: thresholded density, and
unobserved space counts as occupied; the free box B^f is free throughout, and is the only
known free space until ``field_occupancy.warmup`` photos are taken). The baselines and
the three test sets always use the scene's occupancy (the test sets are the measuring
instrument: the same for both variants at one seed). The final, compared training of
every method is a fresh field on its photos, as for the baselines.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, get_args

import numpy as np

from curate.select.baselines import farthest_view, fibonacci_hemisphere
from curate.core.cameras import Cameras, look_at
from curate.core.grid import NodeGrid
from curate.simulate.choices import Scene, SimOccupancy
from curate.simulate.progressive import (CameraSpec, FieldOccupancyConfig, FieldOracle, ProgressiveConfig, acceptable,
                          draw_acceptable, progressive_placement, scene_oracle)

if TYPE_CHECKING:
    from curate.field.model import FieldConfig

log = logging.getLogger(__name__)

METHODS = ("ours", "random", "hemisphere", "fvs")
TEST_SETS = ("hemisphere", "random", "ours")


@dataclass(frozen=True)
class SimulateConfig:
    """A synthetic-room comparison."""

    scene: Scene = "livingroom"
    """Layout: livingroom, office or kitchen."""
    scene_seed: int = 0
    """Seed of the room's furniture and textures."""
    budget: int = 100
    """Training cameras per method."""
    n_test: int = 50
    """Views in each test set."""
    methods: tuple = METHODS
    """Placement methods to compare: ours (the energy, placed progressively), random, hemisphere, fvs."""
    placement: ProgressiveConfig = field(default_factory=ProgressiveConfig)
    """Progressive placement settings (its budget is ``budget``)."""
    node_res: int = 32
    """Node grid resolution over the room; nodes are the occupied ones next to free space."""
    hemisphere_radius: float = 1.6
    """Radius of the hemisphere captures around the point of interest (shrunk where walls intervene)."""
    fvs_pool: int = 2000
    """Random free-space cameras FVS chooses from."""
    train_seconds: float = 120.0
    """Field training time per method."""
    train_iters: int | None = None
    """Field training iterations per method instead of a time (default: --train-seconds)."""
    seed: int = 0
    """Seed of every random draw (placements, test sets, training)."""
    occupancy: SimOccupancy = "oracle"
    """Where ours finds the scene's surfaces when it places cameras: oracle (the room's own geometry)
    or field (a field trained as cameras are added, the paper's setting).

    See the module docstring."""
    train_between: int = 250
    """With --occupancy field: training iterations after each added camera (the paper: 250)."""
    field_occupancy: FieldOccupancyConfig = field(default_factory=FieldOccupancyConfig)
    """'field': how occupancy is derived from the loop's field."""
    loop_field: FieldConfig | None = None
    """'field': the loop field's :class:`curate.field.model.FieldConfig` (None: the default field without
    validation, its empty-space mask re-pruned every min(100, train_between / 2) iterations)."""

    def __post_init__(self):
        if self.occupancy not in get_args(SimOccupancy):
            raise ValueError(f"occupancy must be 'oracle' or 'field', got {self.occupancy!r}")
        if self.train_between < 1:
            raise ValueError(f"--train-between must be >= 1, got {self.train_between}")
        unknown = [m for m in self.methods if m not in METHODS]
        if unknown:
            raise ValueError(f"--methods: unknown placement method {unknown[0]!r} (one of {', '.join(METHODS)})")


def surface_nodes(scene, res: int) -> NodeGrid:
    """Grid over the room whose active nodes are occupied and 6-adjacent to a free node."""
    from scipy import ndimage
    lo, hi = scene.interior
    g = NodeGrid(lo, hi, res)
    occ = scene.occupied(g.all_nodes()).reshape((res,) * 3)
    return g.with_mask(occ & ndimage.binary_dilation(~occ))


def hemisphere_set(scene, n: int, radius: float, spec: CameraSpec, margin: float, phase: float = 0.0) -> Cameras:
    """n acceptable cameras on hemispheres around ``scene.poi`` looking at it, radius shrinking
    by 15% per round until n are found; ``phase`` rotates the pattern (distinct test sets)."""
    occupied, min_depth = scene_oracle(scene)
    got: list[Cameras] = []
    r = radius
    while sum(len(g) for g in got) < n and r > 0.2:
        d = fibonacci_hemisphere(4 * n, min_elevation=np.radians(10))
        c, s = np.cos(phase), np.sin(phase)
        d = d @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1.0]])
        centres = scene.poi + r * d
        cams = Cameras(look_at(centres, np.broadcast_to(scene.poi, centres.shape)), spec.fx, spec.fx,
                       spec.width / 2, spec.height / 2, spec.width, spec.height)
        ok = acceptable(cams, occupied, min_depth, margin)
        got.append(cams[ok])
        r *= 0.85
    pool = Cameras.concat(got)
    if len(pool) < n:
        raise RuntimeError(f"only {len(pool)} hemisphere cameras fit in the room")
    return pool[farthest_view(pool, n, rot_weight=0.0)]


def place(method: str, scene, cfg: SimulateConfig, nodes: np.ndarray, seed: int, n: int, occupancy: str = "oracle"):
    """(cameras [n], trace or None) placed by ``method``; ``occupancy`` is ours' ('oracle' or 'field')."""
    occupied, min_depth = scene_oracle(scene)
    pc = replace(cfg.placement, budget=n, seed=seed)
    lo, hi = scene.interior
    box = (lo + 0.05, hi - 0.05)
    rng = np.random.default_rng(seed)
    if method == "ours" and occupancy == "field":
        return field_placement(scene, cfg, nodes, pc, box)
    if method == "ours":
        return progressive_placement(nodes, box, scene.free_box, pc, occupied, min_depth)
    if method == "random":
        return draw_acceptable(rng, *box, n, pc, occupied, min_depth), None
    if method == "hemisphere":
        return hemisphere_set(scene, n, cfg.hemisphere_radius, pc.camera, pc.margin, phase=seed * 0.618), None
    if method == "fvs":
        pool = draw_acceptable(rng, *box, cfg.fvs_pool, pc, occupied, min_depth)
        return pool[farthest_view(pool, n, rot_weight=1.0)], None
    raise ValueError(f"unknown method {method!r}")


def field_placement(scene, cfg: SimulateConfig, nodes: np.ndarray, pc: ProgressiveConfig, box: tuple):
    """Algorithm 1 with occupancy from the field being trained (see the module docstring).

    Returns (cameras, trace); the trace gets ``field_loop``: per added camera the seconds of
    rendering the photo, of training, of deriving occupancy, and the occupied fraction.
    """
    from curate.field.model import FieldConfig
    from curate.field.train import train_field
    oracle = FieldOracle(scene.interior, scene.free_box, pc.margin, cfg.field_occupancy)
    tb = cfg.train_between
    warmup = pc.n_free_first if cfg.field_occupancy.warmup is None else cfg.field_occupancy.warmup
    u = max(1, min(100, tb // 2))  # re-prune the empty-space mask within each resumed call
    fcfg = cfg.loop_field or FieldConfig(val_every=0, occ_update_start=u, occ_update_every=u)
    images: list = []
    st = {"field": None, "iters": 0}
    loop = {"render_s": [], "train_s": [], "occupancy_s": [], "occupied_fraction": [], "iters": [],
            "false_free": []}
    # diagnostics only: the scene's occupancy at the volume's nodes, faces of B excluded (the walls)
    truth = scene.occupied(oracle.grid.all_nodes()).reshape(oracle.occ.shape)
    inner = np.zeros_like(truth)
    inner[1:-1, 1:-1, 1:-1] = True

    def on_add(step, placed):
        t0 = time.perf_counter()
        images.append(scene.render(placed[len(placed) - 1:])[0][0])
        t1 = time.perf_counter()
        if len(placed) >= 2:  # a field needs two views
            st["field"], ts = train_field(fcfg, placed, images, iters=tb, seed=pc.seed + st["iters"],
                                          box=scene.interior, init=st["field"], start_iter=st["iters"])
            st["iters"] += ts.iters
        t2 = time.perf_counter()
        frac = float(oracle.occ.mean())
        if st["field"] is not None and len(placed) >= warmup and st["iters"] >= cfg.field_occupancy.min_iters:
            frac = oracle.update(st["field"], placed)
        t3 = time.perf_counter()
        free = ~oracle.occ & inner
        false_free = float((truth & free).sum() / max(free.sum(), 1))  # free nodes that are solid
        for k, v in zip(("render_s", "train_s", "occupancy_s", "occupied_fraction", "iters", "false_free"),
                        (t1 - t0, t2 - t1, t3 - t2, frac, st["iters"], false_free)):
            loop[k].append(v)

    cams, trace = progressive_placement(nodes, box, scene.free_box, pc, oracle.occupied, oracle.min_depth,
                                        on_add=on_add)
    trace.field_loop = {**loop, "occupancy_updates": oracle.updates}
    return cams, trace


def run_simulation(cfg: SimulateConfig, out_dir: str | Path, train_fn=None, progress: bool = True) -> dict:
    """Place, render, train and evaluate every method; writes ``out_dir/report.json`` and returns it.

    ``train_fn(cams, images, test_sets: dict name -> (cams, images), out_dir, seed) -> dict``
    trains a field and returns ``{test_set: {"psnr": [...per view], "ssim": [...]}}``;
    the default trains :func:`curate.field.train.train_field` for ``cfg.train_seconds``.
    """
    from curate.simulate.synthetic import make_scene
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    scene = make_scene(cfg.scene, cfg.scene_seed)
    grid = surface_nodes(scene, cfg.node_res)
    nodes = grid.nodes()
    timings: dict = {}

    t0 = time.perf_counter()
    tests = {name: place(name, scene, cfg, nodes, cfg.seed + 1000 + i, cfg.n_test)[0]
             for i, name in enumerate(TEST_SETS)}
    timings["test_sets_s"] = time.perf_counter() - t0
    trains, traces = {}, {}
    for m in cfg.methods:
        t0 = time.perf_counter()
        trains[m], traces[m] = place(m, scene, cfg, nodes, cfg.seed, cfg.budget, cfg.occupancy)
        timings[f"place_{m}_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    test_imgs = {k: scene.render(c)[0] for k, c in tests.items()}
    train_imgs = {m: scene.render(c)[0] for m, c in trains.items()}
    n_imgs = sum(len(c) for c in tests.values()) + sum(len(c) for c in trains.values())
    timings["render_s"] = time.perf_counter() - t0
    timings["render_s_per_image"] = timings["render_s"] / max(n_imgs, 1)

    train_fn = train_fn or _default_train(cfg)
    results = {}
    for m in cfg.methods:
        t0 = time.perf_counter()
        results[m] = train_fn(trains[m], train_imgs[m], {k: (tests[k], test_imgs[k]) for k in TEST_SETS},
                              out / m, cfg.seed)
        timings[f"train_eval_{m}_s"] = time.perf_counter() - t0
    table = {m: {t: float(np.mean(results[m][t]["psnr"])) for t in TEST_SETS} for m in cfg.methods}
    for m in table:
        table[m]["average"] = float(np.mean([table[m][t] for t in TEST_SETS]))
    ours_trace = traces.get("ours")
    report = {
        "scene": cfg.scene, "scene_seed": cfg.scene_seed, "seed": cfg.seed, "budget": cfg.budget,
        "table": table,
        "ssim": {m: {t: float(np.mean(results[m][t]["ssim"])) for t in TEST_SETS} for m in cfg.methods},
        "per_view": results,
        "occupancy": cfg.occupancy,
        "occupancy_note": {"oracle": "ours rejects candidates with the scene's exact occupancy",
                           "field": "ours rejects candidates with occupancy from the field trained as cameras "
                                    "are added (Algorithm 1)"}[cfg.occupancy] + "; baselines and test sets: scene",
        "propose_seconds_per_camera": float(np.median(ours_trace.propose_seconds)) if ours_trace else None,
        "field_loop": _field_loop_summary(cfg, ours_trace),
        "energy_curve": ours_trace.energy if ours_trace else [],
        "cameras": {m: c.to_dict() for m, c in trains.items()},
        "test_cameras": {k: c.to_dict() for k, c in tests.items()},
        "n_nodes": int(len(nodes)), "timings": timings, "wall_seconds": time.perf_counter() - t_start,
    }
    (out / "report.json").write_text(json.dumps(report, indent=1, default=float))
    from curate.simulate.report import write_simulate_html
    write_simulate_html(out)
    return report


def _field_loop_summary(cfg: SimulateConfig, trace) -> dict | None:
    """The field-driven loop's settings and per-camera timings (None for the oracle variant)."""
    fl = getattr(trace, "field_loop", None)
    if fl is None:
        return None
    from dataclasses import asdict
    med = lambda v: float(np.median(v)) if len(v) else None  # noqa: E731
    return {"train_between": cfg.train_between, "settings": asdict(cfg.field_occupancy),
            "propose_s_per_camera": med(trace.propose_seconds), "render_s_per_camera": med(fl["render_s"]),
            "train_s_per_camera": med(fl["train_s"]), "occupancy_s_per_camera": med(fl["occupancy_s"]),
            "total_propose_s": float(np.sum(trace.propose_seconds)), "total_train_s": float(np.sum(fl["train_s"])),
            "total_occupancy_s": float(np.sum(fl["occupancy_s"])), "field_iters": fl["iters"][-1] if fl["iters"] else 0,
            "occupancy_updates": fl["occupancy_updates"], "occupied_fraction": fl["occupied_fraction"],
            "false_free_fraction": fl["false_free"],
            "per_camera": {k: fl[k] for k in ("render_s", "train_s", "occupancy_s")}}


def _default_train(cfg: SimulateConfig):
    def train(cams, images, tests, out, seed):
        from curate.field.model import FieldConfig
        from curate.field.metrics import evaluate
        from curate.field.train import train_field
        imgs = [np.asarray(i, np.float32) / 255.0 for i in images]
        field_, _ = train_field(FieldConfig(), cams, imgs, run_dir=out, seed=seed,
                                time_budget_s=None if cfg.train_iters else cfg.train_seconds, iters=cfg.train_iters)
        res = {}
        for name, (tc, ti) in tests.items():
            ev = evaluate(field_, tc, [np.asarray(i, np.float32) / 255.0 for i in ti])
            res[name] = {"psnr": [v["psnr"] for v in ev["per_view"]], "ssim": [v["ssim"] for v in ev["per_view"]]}
        return res
    return train
