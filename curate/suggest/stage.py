"""The suggest stage: K new camera poses for a run folder -> ``RUN/suggest``.

Reads the run folder through its documented files only: ``sfm/cameras.json`` (every registered camera: the
capture), ``sfm/stage.json`` (``mode``: an import's poses are taken to be in metres, SfM's scale is arbitrary),
``sfm/images.json`` (photo files, video times), ``occupancy/occupancy.npz`` (box, resolution, ``refined_mask``:
the occupied nodes, ``nodes_mask``: the selection's surface nodes), ``select/selection.json`` (the chosen subset,
drawn on the page) and a trained field when there is one (``occupancy/field.pt``, ``evaluate/all/field.pt``).

When the run's occupancy cannot place cameras (imported poses without points and no field: every node counts as
occupied), or previews are asked for (``--field train``) and the run has no field, a field is trained on every
registered frame into ``RUN/suggest_field`` (its own stage: a re-run with another ``--add`` reuses it), and without a
usable occupancy the occupancy and surface nodes are taken from its density as the occupancy stage does
(:func:`field_occupancy_grid`). A field trained briefly on few frames leaves floaters (haze in front of the
cameras) that this marks as occupied: the suggestions then keep away from them, and look at them.

Writes ``suggestions.json`` (the poses, per suggestion its walking instruction from the nearest frame, the
energy gain, preview file; the envelope, timings), ``transforms.json``, ``images.txt`` + ``cameras.txt``,
``coverage.npz`` (per node: ``flat`` grid index, ``score_before`` / ``score_after`` = angular + frequency term,
``views_before`` / ``views_after``, ``frontier``; ``res``, ``box_min``, ``box_max``), ``preview_XX.png`` (with a
field) and ``suggest.html``.
"""

from __future__ import annotations

import json
import logging
import time
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from curate.core.paths import RunPaths
from curate.core.cameras import Cameras
from curate.core.stage import StageResult
from curate.suggest.config import SuggestConfig

log = logging.getLogger(__name__)

STAGE = "suggest"
FIELD_STAGE = "suggest_field"
UNANSWERED = "unanswered.json"
OWNS = ("suggestions.json", "transforms.json", "images.txt", "cameras.txt", "coverage.npz", "preview_*.png",
        "suggest.html", UNANSWERED)
"""What ``curate suggest`` writes in ``RUN/suggest`` (:attr:`curate.core.graph.Stage.owns`)."""
FIELD_OWNS = ("field.pt", "train.json")
"""What it writes in ``RUN/suggest_field``."""
"""Written in ``RUN/suggest`` when the capture leaves nothing to suggest: ``reason`` (what it lacks), ``key``, and
``inputs`` (the keys of the sfm and occupancy stages it read: the report says the reason while they hold)."""
RUN_FIELDS = ("occupancy/field.pt", "evaluate/all/field.pt")
"""Fields a run may hold, in the order they are preferred for previews."""


# ------------------------------------------------------------------ reading the run folder
@dataclass
class RunInputs:
    """What the suggest stage reads from a run folder."""

    cams: Cameras
    """Every registered camera (the capture), in ``cameras.json`` order."""
    paths: list[str]
    """Image file of each camera."""
    labels: list[str]
    """How each frame is named for a person (video and time, or the file name)."""
    units: str
    """'m' (imported poses) or 'units' (SfM)."""
    occ: np.ndarray
    """[R, R, R] bool occupied nodes (``refined_mask``)."""
    nodes_mask: np.ndarray
    """[R, R, R] bool the selection's nodes."""
    box_min: np.ndarray
    box_max: np.ndarray
    chosen: list[int]
    """The run's chosen subset (camera indices), [] without a selection."""
    keys: list[str]
    """Stage keys of what was read (the suggest stage's key depends on them)."""

    @property
    def res(self) -> int:
        return int(self.occ.shape[0])

    def occupancy_usable(self) -> bool:
        """False when the occupancy says nothing (no occupied node, every node occupied, no surface node)."""
        return bool(self.occ.any() and not self.occ.all() and self.nodes_mask.any())


def _key(d: Path) -> str:
    from curate.core.stage import read_stage
    rec = read_stage(d)
    return rec["key"] if rec and "key" in rec else ""


def frame_labels(names: list[str], records: dict) -> list[str]:
    """A person's name for each frame: 'office.mp4 at 12.3 s' for a video frame, else the file name."""
    by = {}
    for r in records.get("photos", []):
        ex = r.get("extra") or {}
        if ex.get("video_rel") is not None and ex.get("time") is not None:
            lab = f"{ex['video_rel']} at {float(ex['time']):.1f} s"
            for k in ("working", "rel"):
                if r.get(k):
                    by.setdefault(r[k], lab)
    return [by.get(n, Path(n).name or f"frame {i}") for i, n in enumerate(names)]


def read_run(run_dir: Path) -> RunInputs:
    """The run folder's inputs (module docstring); FileNotFoundError naming the missing file."""
    from curate.sfm.io import image_paths
    run_dir = Path(run_dir)
    need = {"sfm/cameras.json": "run the sfm stage first", "sfm/images.json": "run the sfm stage first",
            "occupancy/occupancy.npz": "run the occupancy stage first (`curate occupancy RUN`)"}
    for rel, what in need.items():
        if not (run_dir / rel).is_file():
            raise FileNotFoundError(f"{run_dir / rel}: missing ({what})")
    cams = Cameras.load(RunPaths(run_dir).cameras)
    if len(cams) < 2:
        raise ValueError(f"{run_dir / 'sfm' / 'cameras.json'}: {len(cams)} registered camera(s); need at least 2")
    records = json.loads(RunPaths(run_dir).images_json.read_text())
    try:
        z = np.load(RunPaths(run_dir).occupancy_npz)
        occ, nodes = np.asarray(z["refined_mask"], bool), np.asarray(z["nodes_mask"], bool)
        lo, hi = np.asarray(z["box_min"], float), np.asarray(z["box_max"], float)
    except (KeyError, ValueError, OSError, EOFError, zipfile.BadZipFile) as e:
        raise ValueError(f"{run_dir / 'occupancy' / 'occupancy.npz'}: not an occupancy grid of curate ({e}); "
                         f"`curate occupancy {run_dir} --force` writes it again") from None
    if occ.ndim != 3 or occ.shape != nodes.shape or len(set(occ.shape)) != 1:
        raise ValueError(f"{run_dir / 'occupancy' / 'occupancy.npz'}: masks of shape {occ.shape} / {nodes.shape}")
    chosen: list[int] = []
    sel = RunPaths(run_dir).selection
    if sel.is_file():
        chosen = [int(i) for i in json.loads(sel.read_text()).get("chosen", []) if 0 <= int(i) < len(cams)]
    try:
        paths = image_paths(run_dir, list(cams.names), records)
    except FileNotFoundError:
        paths = [""] * len(cams)
    keys = [_key(run_dir / s) for s in ("sfm", "occupancy", "select", "evaluate")]
    return RunInputs(cams, paths, frame_labels(list(cams.names), records),
                     "units", occ, nodes, lo, hi, chosen, keys)


def surface_band(mask: np.ndarray, k: int = 1) -> np.ndarray:
    """[R,R,R] bool: occupied nodes next to free space, widened by ``k`` voxels each side (the occupancy stage's
    selection nodes)."""
    from curate.occupancy.masks import dilate
    if not mask.any():
        return mask
    shell = mask & dilate(~mask, 1)
    return dilate(shell, k) if k > 0 else shell


def frontier(free: np.ndarray, occ: np.ndarray) -> np.ndarray:
    """[R,R,R] bool: voxels neither observed free nor occupied that touch observed free space (6-neighbourhood):
    the edges of what the capture has seen."""
    from scipy import ndimage
    unknown = ~free & ~occ
    return unknown & ndimage.binary_dilation(free)


# ------------------------------------------------------------------ the field
def find_field(run_dir: Path) -> Path | None:
    """The run's trained field (:data:`RUN_FIELDS`, then ``RUN/suggest_field/field.pt``), or None."""
    for rel in RUN_FIELDS + (f"{FIELD_STAGE}/field.pt",):
        if (Path(run_dir) / rel).is_file():
            return Path(run_dir) / rel
    return None


def field_settings(cfg: SuggestConfig) -> dict:
    """The settings of the field ``curate suggest`` trains (its stage's key)."""
    from curate.field.model import FieldConfig
    return {"iters": cfg.field_iters, "side": cfg.field_side, "seed": cfg.seed, "field": FieldConfig()}


def field_key(cfg: SuggestConfig, inp: RunInputs) -> str:
    """The key of ``RUN/suggest_field`` for these settings and this capture."""
    from curate.core.stage import stage_key
    return stage_key(field_settings(cfg), inp.keys[:1])


def train_suggest_field(cfg: SuggestConfig, run_dir: Path, inp: RunInputs, force: bool = False) -> Path:
    """Train a field on every registered frame into ``RUN/suggest_field`` (skipped when already trained with the
    same settings); returns ``field.pt``."""
    from curate.core.stage import begin_stage, finish_stage, write_json_atomic
    from curate.field.model import FieldConfig
    from curate.field.train import default_box, train_field
    t0 = time.perf_counter()
    d = Path(run_dir) / FIELD_STAGE
    settings = field_settings(cfg)
    key = field_key(cfg, inp)
    if begin_stage(d, key, force, owns=FIELD_OWNS):
        return d / "field.pt"
    if any(not p or not Path(p).is_file() for p in inp.paths):
        raise FileNotFoundError(f"{run_dir}: the photos of the capture are not all readable: a field for the "
                                "previews / occupancy needs them")
    f = np.minimum(1.0, cfg.field_side / np.maximum(inp.cams.width, inp.cams.height))
    cams = inp.cams.scaled_images(f)
    log.info("suggest: training a field on %d frames (%d iterations at %d px)", len(cams), cfg.field_iters,
             cfg.field_side)
    _, st = train_field(FieldConfig(), cams, inp.paths, d, iters=cfg.field_iters, seed=cfg.seed,
                        box=default_box(inp.cams))
    write_json_atomic(d / "train.json", {"iters": st.iters, "train_seconds": st.train_seconds, "n_train": len(cams)})
    finish_stage(d, key, settings, t0, outputs={"field": "field.pt"}, seed=cfg.seed, owns=FIELD_OWNS)
    return d / "field.pt"


def field_occupancy_grid(field_path: Path, inp: RunInputs) -> RunInputs:
    """The run's inputs with the occupancy of a field's density on the run's grid (as the occupancy stage refines
    it: :func:`curate.occupancy.masks.refine_occupancy`, mode 'field') and its surface band as nodes."""
    from dataclasses import replace
    from curate.core.grid import NodeGrid
    from curate.field.model import RadianceField
    from curate.occupancy.masks import RefineConfig, refine_occupancy
    fld = RadianceField.load(field_path)
    occ = refine_occupancy(fld, NodeGrid(inp.box_min, inp.box_max, inp.res), cfg=RefineConfig(mode="field")).mask
    if not occ.any():
        raise ValueError(f"{field_path}: the field's density marks no occupied node; nothing to place cameras by")
    return replace(inp, occ=occ, nodes_mask=surface_band(occ, 1))


# ------------------------------------------------------------------ the stage
def suggest(cfg: SuggestConfig, inp: RunInputs, progress: bool = False):
    """(placement, feasibility, free space, node mask used, frontier mask) for a capture and its occupancy
    (``inp.occ``, ``inp.nodes_mask``): the stage's computation without its files (the validation harness's too).

    A walk-through gets poses where the capture saw empty space (:class:`curate.suggest.candidates.Feasibility`);
    an object capture (:func:`curate.select.methods.capture_kind`) gets poses on its own view sphere
    (:class:`curate.suggest.orbit.OrbitFeasibility`). ValueError saying what the capture lacks when nothing is
    feasible."""
    occ, nodes_mask = inp.occ, inp.nodes_mask
    from curate.select.methods import capture_kind
    from curate.suggest.candidates import Feasibility, capture_envelope
    from curate.suggest.freespace import cast_free_space
    from curate.suggest.orbit import OrbitFeasibility, capture_orbit
    from curate.suggest.place import place_cameras
    fs = cast_free_space(inp.cams, occ, inp.box_min, inp.box_max, probe=tuple(cfg.probe))
    env = capture_envelope(inp.cams, fs, occ, inp.box_min, inp.box_max, cfg.clearance_percentile,
                           cfg.view_percentile, cfg.height_percentiles, cfg.pitch_percentiles)
    kind = capture_kind(inp.cams)[0]
    orbit = capture_orbit(inp.cams, env.up) if kind == "object" else None
    if orbit is not None:
        feas = OrbitFeasibility(occ, inp.box_min, inp.box_max, env, orbit)
        if len(feas.cells) == 0:
            raise ValueError("no feasible place for a camera around the object: every view of it at the capture's "
                             f"distances ({orbit.radii[0]:.3g}-{orbit.radii[1]:.3g}) comes nearer than the capture's "
                             f"clearance ({env.clearance:.3g}) to something occupied")
    else:
        if not fs.free.any():
            raise ValueError("the capture saw no empty space to stand in: none of its rays reaches a surface it "
                             "has points on (plain walls and floors give SfM no points); film the room with its "
                             "furniture and textured surfaces in view, then run curate again")
        feas = Feasibility(occ, inp.box_min, inp.box_max, fs.free, env)
        if len(feas.cells) == 0:
            raise ValueError("no feasible place for a camera: no space the capture saw to be empty keeps the "
                             f"capture's own clearance ({env.clearance:.3g}) from surfaces and from what it did not "
                             "see, at the heights it was filmed at (a capture from one spot, one that only looks "
                             "down, as a mapping flight does, or one of plain walls sees too little of the space "
                             "around it; film that space, walking through it once, then run curate again)")
    front = frontier(fs.free, occ) if cfg.nodes == "surface+frontier" else np.zeros_like(occ)
    used = nodes_mask | front
    from curate.core.grid import NodeGrid
    nodes = NodeGrid(inp.box_min, inp.box_max, inp.res, used).nodes()
    pl = place_cameras(inp.cams, nodes, feas, cfg.add, cfg.n_candidates, cfg.energy, cfg.seed, progress)
    return pl, feas, fs, used, front


def run(cfg: SuggestConfig, run_dir: Path, force: bool = False, progress: bool = True) -> StageResult:
    """K suggested poses for the run folder -> ``RUN/suggest`` (module docstring)."""
    from curate.core.stage import begin_stage, finish_stage, stage_key, write_json_atomic, writing
    from curate.suggest import outputs
    from curate.suggest.guide import instruction, nearest_frames
    from curate.suggest.page import write_page
    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    d = run_dir / STAGE
    inp = read_run(run_dir)
    if cfg.metres:
        inp = replace(inp, units="m")
    usable = inp.occupancy_usable()
    field = find_field(run_dir)
    if field is not None and field.parent.name == FIELD_STAGE and _key(field.parent) != field_key(cfg, inp):
        field = None                                       # trained with other settings: retrain
    if field is None and (not usable and cfg.field != "none" or cfg.field == "train"):
        field = train_suggest_field(cfg, run_dir, inp, force)
    if not usable and field is None:
        raise ValueError(f"{run_dir / 'occupancy' / 'occupancy.npz'}: the occupancy is unknown (imported poses "
                         "without points and no field) and --field none forbids training one")
    key = stage_key({"suggest": cfg, "field": field.relative_to(run_dir).as_posix() if field else None},
                    inp.keys + ([_key(field.parent)] if field is not None else []))
    if begin_stage(d, key, force, owns=OWNS):
        return StageResult(STAGE, d, False, time.perf_counter() - t0)
    occ_source = "occupancy/occupancy.npz"
    if not usable:
        inp = field_occupancy_grid(field, inp)
        occ_source = f"the density of {field.relative_to(run_dir).as_posix()}"
    t1 = time.perf_counter()
    try:
        pl, feas, fs, used, front = suggest(cfg, inp, progress)
        if len(pl.cams) == 0:
            raise ValueError("no feasible candidate could be drawn: nothing to suggest")
    except ValueError as e:     # the report says why instead of recommending the command
        write_json_atomic(d / UNANSWERED, {"reason": str(e), "key": key, "inputs": inp.keys[:2]})
        if RunPaths(run_dir).report_json.is_file():
            from curate.report.run_report import write_html
            write_html(run_dir)
        raise
    place_s = time.perf_counter() - t1
    sugg = pl.cams
    names = outputs.suggestion_names(len(sugg))
    sugg = Cameras(sugg.c2w, sugg.fx, sugg.fy, sugg.cx, sugg.cy, sugg.width, sugg.height, names=tuple(names))
    env = feas.env
    near = nearest_frames(inp.cams, sugg, env.look_depth)
    instr = [instruction(inp.cams, int(near[s]), sugg, s, env.up, inp.units, env.look_depth,
                         label=inp.labels[int(near[s])]) for s in range(len(sugg))]
    previews = render_previews(field, sugg, cfg.preview_side, d) if field is not None else [None] * len(sugg)
    outputs.write_transforms_json(d / "transforms.json", sugg, names)
    outputs.write_colmap_text(d, sugg, names)
    flat = np.flatnonzero(used.ravel())
    with writing(d / "coverage.npz"):
        np.savez_compressed(d / "coverage.npz", flat=flat, res=inp.res, box_min=inp.box_min, box_max=inp.box_max,
                            score_before=pl.before.angular_per_node + pl.before.frequency_per_node,
                            score_after=pl.after.angular_per_node + pl.after.frequency_per_node,
                            views_before=pl.before.views_per_node, views_after=pl.after.views_per_node,
                            frontier=front.ravel()[flat])
    timing = pl.timing()
    gains = pl.gains
    from curate.core.stage import config_dict
    rec = {"run": str(run_dir), "config": config_dict(cfg), "add": cfg.add, "placed": len(sugg), "units": inp.units,
           "occupancy": occ_source, "nodes": cfg.nodes, "n_nodes": int(len(flat)),
           "n_frontier": int(front.sum()), "n_capture": len(inp.cams), "chosen": inp.chosen,
           "field": str(field.relative_to(run_dir)) if field is not None else None,
           "envelope": env.to_dict(), "kind": feas.kind,
           **({"orbit": feas.orbit.to_dict(), "feasible_share": len(feas.cells) / feas.probe}
              if feas.kind == "object" else {"feasible_voxels": int(len(feas.cells))}),
           "free_voxels": int(fs.free.sum()), "energy_before": pl.energy_before, "energy": pl.energy,
           "timing": {**timing, "place_seconds": place_s}, "n_candidates": pl.n_candidates,
           "suggestions": [{"index": s + 1, "name": names[s], "c2w": sugg.c2w[s].tolist(),
                            "centre": sugg.centres[s].tolist(), "view_dir": sugg.view_dirs[s].tolist(),
                            "height": float(sugg.centres[s] @ env.up),
                            "pitch_deg": float(np.degrees(np.arcsin(np.clip(sugg.view_dirs[s] @ env.up, -1, 1)))),
                            "energy_gain": gains[s], "nearest": instr[s].to_dict(),
                            "nearest_label": inp.labels[int(near[s])],
                            "preview": previews[s]} for s in range(len(sugg))]}
    write_json_atomic(d / "suggestions.json", rec)
    write_page(run_dir, d, rec, inp, pl, used)
    finish_stage(d, key, {"suggest": cfg}, t0, outputs={"suggestions": "suggestions.json", "page": "suggest.html",
                                                        "transforms": "transforms.json", "colmap": "images.txt"},
                 seed=cfg.seed, owns=OWNS)
    if RunPaths(run_dir).report_json.is_file():   # the run's report links the page
        from curate.report.run_report import write_html
        write_html(run_dir)
    return StageResult(STAGE, d, True, time.perf_counter() - t0,
                       f"{len(sugg)} poses suggested (energy {pl.energy_before:.1f} -> {pl.energy[-1]:.1f}, "
                       f"{timing['ms_per_camera']:.0f} ms per placed camera, {timing['ms_per_candidate']:.2f} ms per "
                       f"candidate) -> {d / 'suggest.html'}")


def render_previews(field_path: Path, sugg: Cameras, side: int, d: Path) -> list[str | None]:
    """Render each suggestion with the field at ``side`` px into ``d/preview_XX.png``; the file names."""
    from curate.field.metrics import render_image, save_png
    from curate.field.model import RadianceField
    fld = RadianceField.load(field_path)
    f = np.minimum(1.0, side / np.maximum(sugg.width, sugg.height))
    small = sugg.scaled_images(f)
    out = []
    for s in range(len(sugg)):
        name = f"preview_{s + 1:02d}.png"
        save_png(render_image(fld, small, s), d / name)
        out.append(name)
    return out
