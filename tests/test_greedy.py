"""Greedy selection: the incremental fast path against brute force, exactness after every step, ties."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from curate.core.cameras import Cameras
from curate.select.config import EnergyConfig
from curate.select.energy import compute_energy, energy_of_subset
from curate.core.grid import NodeGrid
from curate.select.greedy import GreedyState, bruteforce_scores, greedy_select, greedy_select_bruteforce, trace_energy
from curate.select.visibility import build_pair_index
from conftest import random_pool


def make_index(n=60, res=7, seed=0, cfg=EnergyConfig()):
    cams = random_pool(n, seed=seed)
    nodes = NodeGrid([-1, -1, -1], [1, 1, 1], res).nodes()
    return cams, nodes, build_pair_index(cams, nodes, cfg.bins)


BACKENDS = ["numpy", "numba"]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("cfg", [EnergyConfig(), EnergyConfig(gamma=0.5, binning="equal-area"),
                                 EnergyConfig(gamma=0.0, n_theta=3, n_phi=4), EnergyConfig(gamma=2.0)])
def test_same_choices_as_bruteforce(cfg, backend):
    _, _, idx = make_index(cfg=cfg)
    fast = greedy_select(idx, 12, cfg, backend=backend)
    slow = greedy_select_bruteforce(idx, 12, cfg)
    assert fast.chosen == slow.chosen
    assert np.allclose(fast.energy, slow.energy, rtol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_scores_equal_from_scratch_every_step_and_energy_exact(backend):
    cfg = EnergyConfig()
    cams, nodes, idx = make_index(n=40, res=6, seed=3)
    st_ = GreedyState(idx, cfg, backend=backend)
    chosen = []
    for step in range(15):
        ref = bruteforce_scores(idx, chosen, cfg)
        inc = st_.scores()
        avail = ~st_.taken
        assert np.allclose(inc[avail], ref[avail], rtol=1e-10, atol=0)
        k = int(np.argmax(np.where(avail, inc, -np.inf)))
        st_.add(k)
        chosen.append(k)
        e, a, f = st_.energy()
        scratch = compute_energy(cams[chosen], nodes, cfg)
        assert abs(e - scratch.energy) <= 1e-9 * scratch.energy
        assert abs(a - scratch.angular) <= 1e-9 * max(scratch.angular, 1)
        assert abs(f - scratch.frequency) <= 1e-9 * max(scratch.frequency, 1)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 40), res=st.integers(1, 6),
       gamma=st.sampled_from([0.0, 0.05, 0.3, 1.0]), budget=st.integers(1, 12),
       n_init=st.integers(0, 3), binning=st.sampled_from(["paper", "equal-area"]),
       backend=st.sampled_from(BACKENDS))
def test_incremental_equals_scratch_property(seed, n, res, gamma, budget, n_init, binning, backend):
    cfg = EnergyConfig(gamma=gamma, binning=binning)
    cams, nodes, idx = make_index(n=n, res=res, seed=seed, cfg=cfg)
    initial = list(range(min(n_init, n)))
    tr = greedy_select(idx, budget, cfg, initial, backend=backend)
    assert len(tr.chosen) == min(budget, n - len(initial))
    assert len(set(tr.chosen) | set(initial)) == len(tr.chosen) + len(initial)
    for i in range(len(tr.chosen)):
        ref = energy_of_subset(idx, initial + tr.chosen[:i + 1], cfg)
        assert np.isfinite(tr.energy[i])
        assert abs(tr.energy[i] - ref.energy) <= 1e-9 * max(abs(ref.energy), 1e-300)
    assert tr.chosen == greedy_select_bruteforce(idx, budget, cfg, initial).chosen


def test_initial_cameras_are_kept_and_not_rechosen():
    cfg = EnergyConfig()
    _, _, idx = make_index()
    tr = greedy_select(idx, 5, cfg, initial=[3, 9])
    assert 3 not in tr.chosen and 9 not in tr.chosen and tr.initial == [3, 9]
    assert tr.chosen == greedy_select_bruteforce(idx, 5, cfg, initial=[3, 9]).chosen


def test_budget_larger_than_pool_and_blind_candidates():
    cfg = EnergyConfig()
    cams = random_pool(6, seed=1)
    # Two cameras far outside, looking away: they see no node.
    blind = random_pool(2, seed=2).transformed(1.0, None, np.array([100.0, 0, 0]))
    pool = Cameras.concat([cams, blind])
    idx = build_pair_index(pool, NodeGrid([-1, -1, -1], [1, 1, 1], 5).nodes(), cfg.bins)
    tr = greedy_select(idx, 100, cfg)
    assert sorted(tr.chosen) == list(range(8))
    assert set(tr.chosen[-2:]) == {6, 7}  # adding a blind camera only dilutes O_f: chosen last
    assert np.all(np.isfinite(tr.energy))


def test_ties_go_to_lowest_index():
    cfg = EnergyConfig()
    cams = random_pool(5, seed=4)
    pool = Cameras.concat([cams[[2]], cams, cams[[2]]])  # index 0, 3 and 6 are the same camera
    idx = build_pair_index(pool, NodeGrid([-1, -1, -1], [1, 1, 1], 6).nodes(), cfg.bins)
    first = greedy_select(idx, 1, cfg).chosen[0]
    twins = {0, 3, 6}
    if first in twins:
        assert first == 0
    tr = greedy_select(idx, 7, cfg)
    order = [k for k in tr.chosen if k in twins]
    assert order == sorted(order)


def test_trace_energy_matches_subsets():
    cfg = EnergyConfig()
    _, _, idx = make_index(n=30, res=5)
    order = [5, 1, 20, 7]
    e, a, f = trace_energy(idx, cfg, [2], order)
    for i in range(len(order)):
        ref = energy_of_subset(idx, [2] + order[:i + 1], cfg)
        assert np.isclose(e[i], ref.energy, rtol=1e-12) and np.isclose(a[i] + f[i], e[i])


def test_greedy_empty_pool_and_zero_budget():
    cfg = EnergyConfig()
    idx = build_pair_index(Cameras.empty(), np.zeros((8, 3)), cfg.bins)
    assert greedy_select(idx, 5, cfg).chosen == []
    _, _, idx = make_index(n=5, res=3)
    assert greedy_select(idx, 0, cfg).chosen == []


def test_chunked_step_updates_match(monkeypatch):
    import curate.select.greedy as greedy
    cfg = EnergyConfig()
    _, _, idx = make_index(n=80, res=8, seed=1)
    whole = greedy_select(idx, 15, cfg, backend="numpy")
    monkeypatch.setattr(greedy, "PAIR_CHUNK", 37)  # many small chunks per step
    chunked = greedy_select(idx, 15, cfg, backend="numpy")
    assert chunked.chosen == whole.chosen == greedy_select_bruteforce(idx, 15, cfg).chosen
    assert np.allclose(chunked.energy, whole.energy, rtol=1e-12)


def test_node_state_scores_fresh_candidates_exactly():
    """Progressive placement scores a fresh batch of candidates against a fixed set."""
    from curate.select.greedy import NodeState
    cfg = EnergyConfig()
    for backend in BACKENDS:
        check_fresh_candidates(NodeState, cfg, backend)


def check_fresh_candidates(NodeState, cfg, backend):
    cams = random_pool(50, seed=6)
    nodes = NodeGrid([-1, -1, -1], [1, 1, 1], 6).nodes()
    chosen, fresh = cams[:10], cams[10:]
    st_ = NodeState(len(nodes), cfg, backend)
    ci = build_pair_index(chosen, nodes, cfg.bins)
    for k in range(len(chosen)):
        st_.add(*ci.camera_pairs(k))
    fi = build_pair_index(fresh, nodes, cfg.bins)
    s = st_.scores_of(fi)
    for j in (0, 7, 39):
        ref = compute_energy(cams[list(range(10)) + [10 + j]], nodes, cfg).energy
        assert abs(s[j] - ref) <= 1e-9 * ref
    # one step of the placement: the best fresh candidate is added and the state's energy becomes its score
    k = st_.add_best_of(fi)
    assert s[k] == s.max() and k == int(np.flatnonzero(s == s.max())[0])
    assert abs(st_.energy()[0] - s[k]) <= 1e-9 * s[k]


def test_compiled_and_numpy_steps_agree_on_a_larger_pool():
    cfg = EnergyConfig()
    _, _, idx = make_index(n=300, res=12, seed=9)
    a = greedy_select(idx, 40, cfg, backend="numpy")
    b = greedy_select(idx, 40, cfg, backend="numba")
    assert a.chosen == b.chosen
    assert np.allclose(a.energy, b.energy, rtol=1e-12)
    with pytest.raises(ValueError):
        greedy_select(idx, 1, cfg, backend="fortran")
