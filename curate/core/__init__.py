"""The small core: cameras and their conversions, transforms.json, node grids, budgets, statistics, run-folder records,
options, executors."""
