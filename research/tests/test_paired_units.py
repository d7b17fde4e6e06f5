"""research.paired_units: two labels of one harness scene folder, paired per view over folds."""

import numpy as np
import pytest

from research.paired_units import main, paired
from research.tests.conftest import harness_unit


def test_folds_pair_by_view_and_pool(tmp_path):
    ev = tmp_path / "office" / "evaluate"
    rng = np.random.default_rng(0)
    for fold, shift in ((0, 0.2), (3, -0.1)):
        base = 20 + rng.normal(0, 1, 27)
        sfx = f"_o{fold}" if fold else ""
        harness_unit(ev, f"q_new_b59_t0{sfx}", base + shift)
        harness_unit(ev, f"q_default-abc_b59_t0{sfx}", base)
        harness_unit(ev, f"q_random_s0_b59_t0{sfx}", base - 1)              # a random draw: another label
    harness_unit(ev, "q_new_b35_t0", np.zeros(27))                        # no partner at this budget
    rows = paired(tmp_path / "office", "new", "default-abc")
    assert len(rows) == 1 and rows[0]["budget"] == 59 and rows[0]["views"] == 54
    assert [f["fold"] for f in rows[0]["folds"]] == [0, 3]
    assert rows[0]["diff"]["mean"] == pytest.approx(0.05, abs=1e-6)
    assert rows[0]["folds_ahead"] == 1
    assert rows[0]["a"] - rows[0]["b"] == pytest.approx(0.05, abs=2e-3)
    assert main(["--run", str(tmp_path / "office"), "--a", "new", "--b", "default-abc"]) == 0
    assert main(["--run", str(tmp_path / "office"), "--a", "new", "--b", "nothing"]) == 1
