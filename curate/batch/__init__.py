"""`curate batch`: many folders, locally or on a Ray cluster, with a summary."""
