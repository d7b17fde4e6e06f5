"""Selection: the paper's energy and its exact greedy, view medoids, baselines, the select stage."""
