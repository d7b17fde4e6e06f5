"""Markdown tables from the harness's JSON summary (its last stdout line starting ``{"settings"``).

For every scene and budget: held-out PSNR of all frames, the candidate (``default``), FVS,
every n-th frame, random; the candidate's paired differences (95% CI) with each; the share of
the gap from random to all frames it closes. Then the frames-saved table: per scene, the
smallest measured budget at which each method comes within ``--within`` dB of all frames.

    python3 -m research.harness ... > LOG;  python3 -m research.harness_tables LOG [--within 0.3]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def load(log: Path) -> dict:
    """The harness summary: the last line of ``log`` that starts with ``{"settings"``."""
    lines = [ln for ln in Path(log).read_text().splitlines() if ln.startswith('{"settings"')]
    if not lines:
        raise SystemExit(f"{log}: no harness summary line")
    return json.loads(lines[-1])


def ci(p: dict | None) -> str:
    if not p:
        return "-"
    s = f"{p['mean']:+.2f} ({p['lo']:+.2f} to {p['hi']:+.2f})"
    return f"**{s}**" if p["lo"] > 0 or p["hi"] < 0 else s


def tables(d: dict, cand: str = "default", within: float = 0.3) -> str:
    rows, paired = d["rows"], d["paired"]
    psnr = {(r["scene"], r["budget"], r["method"]): r for r in rows}
    pr = {(p["scene"], p["budget"], p["pair"]): p for p in paired}
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    c = "`auto`" if cand == "default" else f"`{cand}`"                  # the candidate's column name
    out = [f"| scene (test views) | budget of pool | all | {c} | FVS | stride | random | {c} - random | "
           f"{c} - FVS | {c} - stride | gap closed |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    saved = {}
    for s in scenes:
        budgets = sorted({r["budget"] for r in rows if r["scene"] == s and r["method"] != "all"})
        for b in budgets:
            g = lambda m: psnr.get((s, b, m), {}).get("psnr")          # noqa: E731
            all_ = next((r["psnr"] for r in rows if r["scene"] == s and r["method"] == "all"), None)
            a, rnd = g(cand), g("random")
            gap = (f"{100 * (a - rnd) / (all_ - rnd):.0f}%" if None not in (a, rnd, all_) and all_ - rnd > 0.05
                   else "-")
            pool = next(r["pool"] for r in rows if r["scene"] == s and r["budget"] == b)
            f = lambda v: "-" if v is None else f"{v:.2f}"              # noqa: E731
            out.append(f"| {s} | {b} of {pool} | {f(all_)} | {f(a)} | {f(g('fvs'))} | {f(g('stride'))} | {f(rnd)} | "
                       f"{ci(pr.get((s, b, f'{cand}-random')))} | {ci(pr.get((s, b, f'{cand}-fvs')))} | "
                       f"{ci(pr.get((s, b, f'{cand}-stride')))} | {gap} |")
            for m in (cand, "fvs", "stride", "random"):
                v = g(m)
                if v is not None and all_ is not None:
                    saved.setdefault((s, m), []).append((b, all_ - v, pool))
    out += ["", f"Frames saved: the smallest measured budget within {within} dB of all frames "
            "('> k': none of the measured budgets, the largest being k).", "",
            f"| scene (test views) | {c} | FVS | stride | random |", "|---|---|---|---|---|"]
    for s in scenes:
        cells = []
        for m in (cand, "fvs", "stride", "random"):
            pts = sorted(saved.get((s, m), []))
            if not pts:
                cells.append("-")
                continue
            hit = [b for b, loss, _ in pts if loss <= within]
            cells.append(f"{hit[0]}" if hit else f"> {pts[-1][0]}")
        out.append(f"| {s} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--candidate", default="default")
    ap.add_argument("--within", type=float, default=0.3)
    a = ap.parse_args(argv)
    print(tables(load(a.log), a.candidate, a.within))
    return 0


if __name__ == "__main__":
    sys.exit(main())
