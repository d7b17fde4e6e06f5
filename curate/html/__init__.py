"""Self-contained HTML pages: shared styling and escaping (:mod:`curate.html.parts`), matplotlib charts as inline
SVG (:mod:`curate.html.charts`) and plots as SVG or data-URI images (:mod:`curate.html.plots`). Used by the run
report, the suggestion page, the simulation report and the batch summary; it imports nothing of theirs."""
