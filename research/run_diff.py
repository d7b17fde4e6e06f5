"""Two run folders of the same capture and options, file by file: what differs beyond the clock and the folder's name.

    python -m research.run_diff RUN_A RUN_B

Prints JSON: ``same`` (files equal), ``differ`` (each with the first JSON path that differs), ``only_a``, ``only_b``.
Binary files are compared byte for byte; JSON files (``stage.json``, ``selection.json``, ``report.json``, ...) after
the run folder's own path is replaced by ``RUN`` and the fields the clock writes are dropped (seconds, times,
inodes: :data:`VOLATILE`, and every ``*_seconds``); ``report.html`` with its path replaced and its time stamps and
random colour-bar ids dropped. What a refactoring
that keeps behaviour must leave the same (issue 60: "every output file byte-identical where behaviour did not
change").
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

VOLATILE = {"seconds", "finished_at", "mtime_ns", "inode", "wall_seconds", "written_at", "compute_seconds",
            "train_seconds", "t_vis", "pid", "started_at", "host", "created", "claimed_at", "begun",
            "copies_seconds"}
"""JSON fields the clock (or the process) writes: not compared."""

SKIP = {"colmap.log", ".lock", "database.db"}
"""Files of a run folder whose content is a log of the machine's work (COLMAP's log, its database of features and
matches, written with the clock): not compared."""


def _clean(x, a: str, b: str):
    if isinstance(x, dict):
        if "sha256" in x and "size" in x:    # a record's file entry: its checksum holds the clock of a JSON or a log
            x = {k: v for k, v in x.items() if k not in ("sha256", "size")}
        return {k: _clean(v, a, b) for k, v in x.items() if k not in VOLATILE and not k.endswith("_seconds")}
    if isinstance(x, list):
        return [_clean(v, a, b) for v in x]
    if isinstance(x, str):
        return _paths(x, a, b)
    if isinstance(x, float):
        return round(x, 9)
    return x


def _paths(t: str, a: str, b: str) -> str:
    for p in sorted((a, b), key=len, reverse=True):    # the longer first: /x/A2 is not /x/A followed by 2
        t = t.replace(p, "RUN")
    return t


def _first_diff(x, y, path="") -> str:
    if type(x) is not type(y):
        return path or "/"
    if isinstance(x, dict):
        for k in sorted(set(x) | set(y)):
            if k not in x or k not in y:
                return f"{path}/{k}"
            if x[k] != y[k]:
                return _first_diff(x[k], y[k], f"{path}/{k}")
    if isinstance(x, list):
        if len(x) != len(y):
            return f"{path}[len]"
        for i, (u, v) in enumerate(zip(x, y)):
            if u != v:
                return _first_diff(u, v, f"{path}[{i}]")
    return path or "/"


def compare(ra: Path, rb: Path) -> dict:
    a, b = str(ra.resolve()), str(rb.resolve())
    fa = {p.relative_to(ra).as_posix() for p in ra.rglob("*") if p.is_file()}
    fb = {p.relative_to(rb).as_posix() for p in rb.rglob("*") if p.is_file()}
    out: dict = {"same": 0, "differ": {}, "only_a": sorted(fa - fb), "only_b": sorted(fb - fa), "not_compared": []}
    for rel in sorted(fa & fb):
        pa, pb = ra / rel, rb / rel
        if Path(rel).name in SKIP:
            out["not_compared"].append(rel)
            continue
        if rel.endswith(".json") or Path(rel).name.startswith(".curate"):
            try:
                x = _clean(json.loads(pa.read_text()), a, b)
                y = _clean(json.loads(pb.read_text()), a, b)
            except ValueError:
                x, y = pa.read_bytes(), pb.read_bytes()
            if x == y:
                out["same"] += 1
            else:
                out["differ"][rel] = _first_diff(x, y) if isinstance(x, (dict, list)) else "bytes"
        elif rel.endswith(".html"):
            def norm(t: str) -> str:
                t = _paths(t, a, b)
                t = re.sub(r"#?cb\d+", "ID", t)            # a colour bar's gradient id (random)
                return re.sub(r"\d{4}-\d\d-\d\d[ T]\d\d:\d\d(:\d\d)?|\d+(\.\d+)? ?s\b", "T", t)
            same = norm(pa.read_text()) == norm(pb.read_text())
            out["same" if same else "differ"] = out["same"] + 1 if same else {**out["differ"], rel: "text"}
        elif pa.read_bytes() == pb.read_bytes():
            out["same"] += 1
        else:
            out["differ"][rel] = "bytes"
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_a", type=Path)
    ap.add_argument("run_b", type=Path)
    args = ap.parse_args(argv)
    print(json.dumps(compare(args.run_a, args.run_b), indent=1))


if __name__ == "__main__":
    main()
