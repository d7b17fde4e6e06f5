"""View medoids weighted along the capture path (MedoidsConfig.path_weights)."""

import warnings

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.select.config import MedoidsConfig
from curate.select.medoids import PATH_CAP, embed, medoids_select, path_weights


def walk(x, y=None, yaw=None):
    """Cameras at (x, y, 0) in the given (capture) order, looking along +y turned by ``yaw``."""
    x = np.asarray(x, np.float64)
    y = np.zeros_like(x) if y is None else np.asarray(y, np.float64)
    yaw = np.zeros_like(x) if yaw is None else np.asarray(yaw, np.float64)
    c = np.c_[x, y, np.zeros_like(x)]
    target = c + np.c_[np.sin(yaw), np.cos(yaw), np.zeros_like(x)]
    return Cameras(look_at(c, target), 300.0, 300.0, 160, 120, 320, 240)


def ref_path_weights(c, a):
    """Plain loops: half the steps to the previous and next view (ends: their one step),
    each step capped at PATH_CAP median steps, normalised to mean 1."""
    K = len(c)
    step = [np.linalg.norm(c[i + 1] - c[i]) + np.linalg.norm(a[i + 1] - a[i]) for i in range(K - 1)]
    cap = PATH_CAP * float(np.median(step))
    step = [min(s, cap) for s in step]
    w = [step[0]] + [0.5 * (step[i - 1] + step[i]) for i in range(1, K - 1)] + [step[-1]]
    return np.array(w) / np.mean(w)


def test_path_weights_against_reference_and_scale():
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.uniform(0.02, 0.3, 40))          # a walk at a varying pace, turning a little
    cams = walk(x, 0.1 * np.sin(x), 0.3 * np.sin(3 * x))
    c, a = embed(cams, np.full(len(cams), 2.0))
    w = path_weights(c, a)
    assert np.allclose(w, ref_path_weights(c, a), rtol=1e-12)
    assert np.isclose(w.mean(), 1.0) and np.all(w > 0)
    for s in (1e-6, 1e6):                              # scale-free: the same weights at any scene scale
        assert np.allclose(path_weights(c * s, a * s), w, rtol=1e-9)


def test_a_dropped_frame_and_a_cut():
    x = np.arange(30.0)
    x = np.delete(x, 10)                               # frame 10 dropped: its neighbours stand for more path
    x[20:] += 100.0                                    # and a cut: a second sequence far away
    c, a = embed(walk(x), np.ones(len(x)))
    w = path_weights(c, a)
    assert np.all(np.isfinite(w))
    base = w[5]
    assert np.isclose(w[9], 1.5 * base) and np.isclose(w[10], 1.5 * base)   # [9] and [10] border the hole
    assert w[19] <= (1 + PATH_CAP) / 2 * base + 1e-12 and w[20] <= (1 + PATH_CAP) / 2 * base + 1e-12


@pytest.mark.parametrize("k", [0, 1, 2])
def test_too_few_views_or_coincident_views_are_not_a_path(k):
    c, a = embed(walk(np.arange(float(k))), np.ones(k))
    assert path_weights(c, a) is None
    c, a = embed(walk(np.zeros(5)), np.ones(5))       # every view at one spot, one direction
    assert path_weights(c, a) is None


@pytest.mark.parametrize("n", [25, 60, 200])
def test_random_pools_are_not_a_path(n):
    from conftest import random_pool
    for seed in range(3):
        cams = random_pool(n, seed=seed)
        assert path_weights(*embed(cams, np.ones(n))) is None


def test_shuffled_photos_are_not_a_path():
    rng = np.random.default_rng(1)
    cams = walk(rng.permutation(np.linspace(0.0, 10.0, 60)))   # a walk in shuffled name order
    c, a = embed(cams, np.ones(len(cams)))
    assert path_weights(c, a) is None
    from curate.select.medoids import PathOrderWarning
    with pytest.warns(PathOrderWarning, match="capture order"):
        got, _ = medoids_select(cams, 6, MedoidsConfig(depth=1.0, path_weights=True))
    # falls back to plain medoids
    assert got == medoids_select(cams, 6, MedoidsConfig(depth=1.0, path_weights=False))[0]
    from curate.core.grid import NodeGrid
    from curate.select.config import SelectConfig
    from curate.select.select import select
    sel = select(cams, NodeGrid([-1, 0, -1], [11, 2, 1], 6), 6,
                 SelectConfig("medoids", medoids=MedoidsConfig(depth=1.0, path_weights=True)))
    assert sel.chosen == got and "path weights ignored" in sel.to_dict()["note"]   # said in selection.json


def walk_coverage(x_chosen, lo=0.0, hi=10.0):
    """Mean distance from a point of the continuous walk [lo, hi] to its nearest chosen view."""
    t = np.linspace(lo, hi, 2001)
    return float(np.abs(t[:, None] - np.asarray(x_chosen)[None]).min(1).mean())


@pytest.mark.parametrize("sparse,budget", [(2, 5), (3, 6), (3, 8), (4, 5), (4, 8), (2, 8)])
def test_a_sparsely_sampled_stretch_is_covered_by_distance_walked(sparse, budget):
    """A walk filmed at 10 frames a metre for 5 m, then at 10 / ``sparse`` (the walker sped
    up, frames were dropped): path-weighted medoids cover the walk itself (every metre
    alike) at least as well as plain medoids, which count frames."""
    x = np.r_[np.arange(0.0, 5.0, 0.1), np.arange(5.0, 10.0, 0.1 * sparse)]
    cams = walk(x)
    plain, _ = medoids_select(cams, budget, MedoidsConfig(depth=1.0, path_weights=False))
    with warnings.catch_warnings():
        warnings.simplefilter("error")                 # a path: no fallback warning
        path, cost = medoids_select(cams, budget, MedoidsConfig(depth=1.0, path_weights=True))
    assert len(set(path)) == budget
    assert walk_coverage(x[path]) <= walk_coverage(x[plain]) + 1e-12
    if (sparse, budget) in ((3, 6), (4, 5)):          # here plain medoids lean towards the dense half
        assert walk_coverage(x[path]) < walk_coverage(x[plain]) - 0.01
        assert np.mean(x[path]) > np.mean(x[plain])
    assert np.all(np.isfinite(cost)) and np.all(np.diff(cost) <= 1e-12 * cost[0])


@pytest.mark.parametrize("seed", range(3))
def test_weighted_voronoi_local_optimum_against_reference(seed):
    power = 1.0
    rng = np.random.default_rng(seed)
    K, budget = 24, 4
    x = np.cumsum(rng.uniform(0.05, 0.5, K))
    cams = walk(x, 0.2 * rng.standard_normal(K), 0.4 * rng.standard_normal(K))
    c, a = embed(cams, np.full(K, 1.5))
    w = ref_path_weights(c, a)
    D = np.array([[np.linalg.norm(c[i] - c[j]) + np.linalg.norm(a[i] - a[j]) for j in range(K)]
                  for i in range(K)]) ** power        # [view, medoid]
    chosen, cost = medoids_select(cams, budget, MedoidsConfig(depth=1.5, path_weights=True))
    assert len(set(chosen)) == budget
    assign = [min(chosen, key=lambda m: (D[i, m], chosen.index(m))) for i in range(K)]
    for m in chosen:                                   # no member is a cheaper medoid of its cluster
        members = [i for i in range(K) if assign[i] == m]
        cur = sum(w[i] * D[i, m] for i in members)
        assert all(sum(w[i] * D[i, y] for i in members) >= cur - 1e-9 * max(1.0, cur) for y in members)
    assert np.isclose(cost[-1], np.mean([w[i] * D[i, assign[i]] for i in range(K)]), rtol=1e-10)
    assert np.all(np.diff(cost) <= 1e-12 * max(1.0, cost[0]))


@pytest.mark.slow
def test_cli_path_weights_flag(tmp_path):
    """`curate select --path-weights` / `--no-path-weights` choose what the library chooses
    with ``MedoidsConfig(path_weights=True / False)`` (the two differ on this walk), and
    the choice is recorded in selection.json."""
    import json
    import subprocess
    import sys

    from curate.core.transforms_json import write_transforms
    x = np.r_[np.arange(0.0, 5.0, 0.1), np.arange(5.0, 10.0, 0.4)]
    files = [f"frame_{i:04d}.png" for i in range(len(x))]       # name order = capture order
    path = write_transforms(tmp_path / "transforms.json", walk(x), files)
    got = {}
    for flag in ("--path-weights", "--no-path-weights"):
        out = tmp_path / flag.strip("-")
        p = subprocess.run([sys.executable, "-m", "curate", "select", str(path), "--budget", "5", "--method",
                            "medoids", "--res", "8", "--box=-1,0.5,-1,11,2,1", flag, "--out", str(out), "--json"],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        got[flag] = json.loads(p.stdout)["chosen"]
        cfg = json.loads((out / "selection.json").read_text())["config"]["medoids"]
        assert cfg["path_weights"] is (flag == "--path-weights")
    from curate.core.grid import NodeGrid
    from curate.select.config import SelectConfig
    from curate.select.select import select
    grid = NodeGrid([-1, 0.5, -1], [11, 2, 1], 8)
    for flag, on in (("--path-weights", True), ("--no-path-weights", False)):
        ref = select(walk(x), grid, 5, SelectConfig("medoids", medoids=MedoidsConfig(path_weights=on))).chosen
        assert sorted(got[flag]) == sorted(ref)
    assert sorted(got["--path-weights"]) != sorted(got["--no-path-weights"])


@pytest.mark.parametrize("scene", ["office", "fox", "templering"])
def test_real_frame_sequences_are_paths_and_shuffled_ones_are_not(scene):
    """Path weights turn on for the real sets' frames in name order, and off once the
    same cameras are shuffled (photos from several sessions, renamed files)."""
    from conftest import shared_data
    from research.datasets import load_ground_truth
    cams = load_ground_truth(shared_data(scene))
    spread = float(np.median(np.linalg.norm(cams.centres - cams.centres.mean(0), axis=1)))
    c, a = embed(cams, np.full(len(cams), spread))              # look-at depth: the centres' spread
    w = path_weights(c, a)
    assert w is not None and np.all(np.isfinite(w)) and np.isclose(w.mean(), 1.0)
    order = np.random.default_rng(0).permutation(len(cams))
    assert path_weights(c[order], a[order]) is None
