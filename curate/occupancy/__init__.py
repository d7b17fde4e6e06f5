"""The occupancy stage: hold-out split, pool field when needed, occupancy grid and selection nodes."""
