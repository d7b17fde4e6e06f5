"""What ``--budget default`` keeps on finished run folders, beside the old default (15% of every capture).

    python -m research.budget_by_kind RUN [RUN ...] > docs/evidence/budget_by_kind.jsonl

One JSON line per run: registered photos, the kind of capture and its median angle, what ``default``
meant and how many photos it keeps (the law's advice at 0.5 dB on an object capture, as the select stage
computes it without the measured check), and 15% of the pool.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from curate.core.budget import AUTO, parse_budget, resolve_budget
from curate.core.run import load_node_grid
from curate.select.auto_budget import choose_for_pool
from curate.select.config import SelectConfig
from curate.select.methods import capture_kind
from curate.core.budget import budget_of_pool
from curate.select.visibility import build_pair_index
from curate.sfm.io import load_sfm


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    args = ap.parse_args()
    for rd in args.runs:
        cams = load_sfm(rd).cameras
        text, said = budget_of_pool("default", cams)
        kind, ang = capture_kind(cams)
        if parse_budget(text) == AUTO:
            nodes = load_node_grid(rd).nodes()
            n = choose_for_pool(cams, nodes, build_pair_index(cams, nodes, SelectConfig().energy.bins), 0.5).budget
        else:
            n = resolve_budget(parse_budget(text), len(cams))
        print(json.dumps({"run": rd.name, "registered": len(cams), "kind": kind, "angle_deg": round(ang, 1),
                          "budget": said, "kept": n, "kept_by_15pct": resolve_budget(0.15, len(cams))}), flush=True)


if __name__ == "__main__":
    main()
