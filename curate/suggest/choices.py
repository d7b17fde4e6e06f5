"""The choices of ``curate suggest``'s options, apart from :mod:`curate.suggest.config` so that the command line
reads them without importing numpy (``curate --help`` stays instant)."""

from typing import Literal, get_args

FieldMode = Literal["auto", "train", "none"]
FIELD_MODES = get_args(FieldMode)
"""``SuggestConfig.field`` choices."""
NodeMode = Literal["surface", "surface+frontier"]
NODE_MODES = get_args(NodeMode)
"""``SuggestConfig.nodes`` choices."""
