"""The choices of ``curate simulate``'s options, apart from :mod:`curate.simulate.experiment` so that the command
line reads them without importing numpy (``curate --help`` stays instant)."""

from typing import Literal

Scene = Literal["livingroom", "office", "kitchen"]
"""``SimulateConfig.scene`` choices: the synthetic rooms (:mod:`curate.simulate.synthetic`)."""
SimOccupancy = Literal["oracle", "field"]
"""``SimulateConfig.occupancy`` choices."""
