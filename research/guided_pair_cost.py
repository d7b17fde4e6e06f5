"""What guided matching costs a pair: a sample of a capture's own pairs matched on one thread, guided and unguided.

Each setting matches the same pairs in a copy of the capture's database (its matches removed; features kept), by
:func:`curate.sfm.matching._match_file`. Prints JSON: CPU seconds a pair, mean verified matches, and how many of
the pairs that fail verification unguided have the same rows guided (COLMAP guides only along a verified
geometry). With ``--below N`` also auto's two passes (every pair unguided, then guided where fewer than N verified):
its CPU seconds a pair and how many it guided. docs/investigations/sfm.md#guided-where-weak.

    python -m research.guided_pair_cost RUN/sfm/database.db PAIRS.txt --out W [--n 40] [--below 300]
"""

from __future__ import annotations

import argparse
import json
import resource
import sqlite3
from pathlib import Path


def _cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("db", type=Path, help="a run's sfm/database.db (its features are used)")
    ap.add_argument("pairs", type=Path, help="a pair list (NAME NAME a line), e.g. RUN/sfm/sequential_pairs.txt")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--n", type=int, default=40, help="pairs taken evenly from the list")
    ap.add_argument("--below", type=int, default=0, help="also auto's two passes, guided under this many (0: not run)")
    a = ap.parse_args(argv)
    from curate.sfm.matching import _match_file
    from curate.sfm.matching import copy_database
    lines = a.pairs.read_text().splitlines()
    sample = lines[::max(1, len(lines) // a.n)][:a.n]
    a.out.mkdir(parents=True, exist_ok=True)
    listed = a.out / "pairs.txt"
    listed.write_text("".join(f"{ln}\n" for ln in sample))
    res, rows = {}, {}
    settings = [("guided", True, 0), ("unguided", False, 0)] + ([("two_pass", True, a.below)] if a.below else [])
    for name, guided, below in settings:
        db = a.out / f"{name}.db"
        copy_database(a.db, db)
        with sqlite3.connect(db) as con:
            con.execute("DELETE FROM matches")
            con.execute("DELETE FROM two_view_geometries")
        c0 = _cpu()
        n_guided = _match_file(db, listed, 0, 15, guided, below)
        cpu = _cpu() - c0
        con = sqlite3.connect(db)
        rows[name] = {r[0]: r for r in con.execute("SELECT * FROM two_view_geometries")}
        con.close()
        inl = [r[1] for r in rows[name].values()]
        res[name] = {"cpu_s_per_pair": round(cpu / len(sample), 3), "mean_matches": round(sum(inl) / len(inl), 1),
                     "pairs_guided": n_guided}
        db.unlink()
    failing = [p for p, r in rows["unguided"].items() if r[1] < 15]
    res["pairs"] = len(sample)
    res["failing_unguided"] = len(failing)
    res["failing_same_rows_guided"] = sum(rows["guided"].get(p) == rows["unguided"][p] for p in failing)
    print(json.dumps(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
