"""research.walk_kinds: per kind of walk, pooled over its scenes, with Holm's correction."""

import numpy as np

from research.walk_kinds import holm, kind_table, cells, main
from research.tests.conftest import harness_unit


def test_holm_rejects_in_step_down_order():
    assert holm([0.001, 0.04, 0.2]) == [True, False, False]        # 0.04 > 0.05 / 2
    assert holm([0.01, 0.02, 0.03]) == [True, True, True]          # 0.01 < .05/3, 0.02 < .05/2, 0.03 < .05
    assert holm([0.5, 0.001]) == [False, True]
    assert holm([]) == []


def test_kinds_pool_their_rooms_and_report_the_worst(tmp_path):
    rng = np.random.default_rng(0)
    for scene, shift in (("walk-loop", -0.4), ("walk-loop-kitchen", 0.0), ("walk-turn", 0.3)):
        ev = tmp_path / scene / "evaluate"
        base = 30 + rng.normal(0, 1, 20)
        off = 20 + rng.normal(0, 1, 10)
        harness_unit(ev, "all", base + 1, off + 0.5)
        harness_unit(ev, "q_random_s0_b42_t0", base - 1, off - 0.5)
        harness_unit(ev, "q_stride_b42_t0", base, off)
        harness_unit(ev, "q_default-abc123_b42_t0", base + shift + rng.normal(0, 0.01, 20), off + shift)
    harness_unit(tmp_path / "office" / "evaluate", "all", [1, 2], [])     # not a walk: ignored
    recs = cells(sorted(tmp_path.iterdir()), "default", ["stride", "random"])
    assert {r["scene"] for r in recs} == {"walk-loop", "walk-loop-kitchen", "walk-turn"}
    rows = {(r["kind"], r["part"]): r for r in kind_table(recs, "default", ["stride", "random"])}
    loop = rows[("loop", "path")]
    assert loop["views"] == 40 and len(loop["scenes"]) == 2
    assert abs(loop["vs_stride"]["mean"] + 0.2) < 0.01                 # the two rooms pooled
    assert abs(loop["vs_stride"]["worst_scene"] + 0.4) < 0.01          # the worse room
    assert loop["vs_stride"]["hi"] < 0 and loop["vs_stride"]["holm"]
    assert rows[("turn", "off")]["vs_stride"]["lo"] > 0
    assert abs(rows[("loop", "path")]["gap_closed"] - 0.4) < 0.01      # (-0.2 + 1) / 2
    assert main(["--out", str(tmp_path), "--rivals", "stride,random", "--all-kinds"]) == 0
    pooled = kind_table([dict(r, kind="all kinds") for r in recs], "default", ["stride", "random"])
    assert {r["views"] for r in pooled if r["part"] == "path"} == {60}          # three scenes, 20 views each


def test_the_walk_rule_choice_ranks_by_cells_behind_then_worst_case(tmp_path):
    from research.choose_walk_rule import rank, score
    rng = np.random.default_rng(1)
    for scene in ("walk-loop", "walk-loop-kitchen", "walk-turn", "walk-turn-kitchen"):
        ev = tmp_path / scene / "evaluate"
        base = 30 + rng.normal(0, 1, 20)
        off = 20 + rng.normal(0, 1, 10)
        harness_unit(ev, "all", base + 1, off + 0.5)
        harness_unit(ev, "q_fvs_b42_t0", base - 0.5, off - 0.3)
        harness_unit(ev, "q_stride_b42_t0", base, off)
        harness_unit(ev, "q_default-abc123_b42_t0", base - 0.2 + rng.normal(0, 0.01, 20), off - 0.2)   # behind stride
        lose = -0.5 if "turn" in scene else 0.1                     # ahead on loops, far behind on turns
        harness_unit(ev, "q_bold_b42_t0", base + lose + rng.normal(0, 0.01, 20), off + lose)
        harness_unit(ev, "q_even_b42_t0", base + 0.05 + rng.normal(0, 0.01, 20), off + 0.05)   # a little ahead
    runs = sorted(tmp_path.iterdir())
    s = {c: score(runs, c, ["default", "stride", "fvs"]) for c in ("default", "stride", "bold", "even")}
    assert s["default"]["cells_behind"] == 4 and s["default"]["worst"] < -0.15
    assert s["bold"]["cells_behind"] == 2 and s["bold"]["worst_cell"].startswith("turn")
    assert s["even"]["cells_behind"] == 0 and s["stride"]["cells_behind"] == 0
    # stride: +0.20 over auto at worst
    assert [r["candidate"] for r in rank(list(s.values()))] == ["stride", "even", "bold", "default"]
