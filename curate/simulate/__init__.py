"""`curate simulate`: the paper's synthetic experiment in procedural rooms, and camera trajectories."""
