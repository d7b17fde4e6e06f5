"""``curate suggest``: where to shoot next. The paper's progressive placement (Algorithm 1) on the user's own capture.

One module per step: :mod:`~curate.suggest.config` (options), :mod:`~curate.suggest.freespace` (the space the
capture observed as free), :mod:`~curate.suggest.candidates` (feasible hand-held poses),
:mod:`~curate.suggest.place` (the greedy placement by the energy), :mod:`~curate.suggest.guide` (walking
instructions from the nearest frame), :mod:`~curate.suggest.outputs` (suggestions.json, transforms.json,
COLMAP text), :mod:`~curate.suggest.page` (suggest.html) and :mod:`~curate.suggest.stage` (the run-folder
stage, ``RUN/suggest``).
"""
