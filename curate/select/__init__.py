"""Selection: the paper's energy and its exact greedy, path spacing, view medoids, baselines, the select stage."""
