"""The evaluate stage: the same field trained on every subset, scored on the held-out views."""
