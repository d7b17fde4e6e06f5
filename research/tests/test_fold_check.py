"""research.fold_check: a fold is one step where the model's turn between neighbours differs from the truth's."""
import numpy as np

from curate.core.cameras import look_at
from research.fold_check import relative_turns, relative_turns_to


def test_a_part_turned_as_a_whole_shows_at_its_seam_only():
    c = np.stack([np.linspace(0, 10, 50), np.zeros(50), np.ones(50)], 1)
    truth = look_at(c, c + [0.0, 1.0, 0.0])
    model = truth.copy()
    t = np.radians(37.0)
    Rz = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    model[20:, :3, :3] = Rz @ model[20:, :3, :3]                  # photos 20.. turned by 37 deg together
    d = relative_turns(model, truth)
    assert np.flatnonzero(d > 1.0).tolist() == [19] and abs(d[19] - 37.0) < 1e-6
    assert np.allclose(relative_turns(truth, truth), 0.0, atol=1e-5)
    assert np.all(np.isfinite(relative_turns(model[:2], truth[:2])))
    f = relative_turns_to(model, truth)
    assert np.allclose(f[:20], 0.0, atol=1e-5) and np.allclose(f[20:], 37.0, atol=1e-5)
