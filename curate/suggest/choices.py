"""The choices of ``curate suggest``'s options, apart from :mod:`curate.suggest.config` so that the command line
reads them without importing numpy (``curate --help`` stays instant)."""

FIELD_MODES = ("auto", "train", "none")
"""``SuggestConfig.field`` choices."""
NODE_MODES = ("surface", "surface+frontier")
"""``SuggestConfig.nodes`` choices."""
