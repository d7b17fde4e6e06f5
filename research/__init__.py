"""Experiments, harnesses and measured-but-not-adopted variants (imports curate; never the reverse)."""
