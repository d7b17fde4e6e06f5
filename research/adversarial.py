"""Adversarial sweep of the ``curate`` CLI: hostile flags, photo folders, pose files, run folders, videos, signals.

Every case builds its own sandbox (``OUT/cases/<case>/``, copies of ``data_samples/room_walk``; the sample and
``../shared/data`` are only read), runs ``python -m curate ...`` in a niced subprocess (timeout 300 s, ``TMPDIR``
= ``OUT/tmp/<case>``, so a crash log is caught and attached) and checks, on every case:

1. no ``Traceback``, ``Fatal Python error``, ``terminate called``, ``Check failed`` or native stack dump in
   stdout/stderr, and no death by a signal;
2. failure: exit status != 0 and exactly one line containing ``: error:`` (an ``internal error`` line is a
   violation too); success: exit status 0;
3. the user's files are intact: the sandbox tree outside the declared run folder(s) (file bytes, modes, symlink
   targets and the bytes they point to) is identical afterwards, so inputs are unchanged and nothing was
   written outside the run folder; a run folder that held the user's files before (no curate marker) still
   holds them unchanged. An --out that curate must refuse (an input folder, a user's folder) is not declared:
   anything left there is a violation;
4. no ``.html`` file in the sandbox contains the raw markup ``<script>alert(1)</script>`` or
   ``"><img src=x onerror=alert(1)>`` (cases put them in file and folder names);
5. the case's expectation: ``error`` (exit != 0), ``ok`` (exit 0) or ``any`` (only the invariants).

Signal cases interrupt a pose import with triangulation (or a short COLMAP SfM run) with SIGTERM / SIGHUP (to
the PID) or SIGINT (to the process group, as Ctrl-C does) after 1, 3 or 6 s and expect: exit != 0, exactly one
``curate run:`` line, no traceback, the run lock released (flock-able, emptied) and no process left; the same
command again exits 0 and its export (every file but export.json, stage.json, .curate-stage; symlink targets)
is identical to an uninterrupted run's in another folder (for SfM: the same file names only, as multi-threaded
COLMAP gives other bytes on every clean run).

Run from the project root (at most 2 cases at a time; results in OUT/results.jsonl, summary last on stdout)::

    .venv/bin/python -m research.adversarial --out /tmp/adv
    .venv/bin/python -m research.adversarial --out /tmp/adv --only pose-   # rerun the cases whose name has it
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import fcntl
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "room_walk"
OFFICE_MP4 = ROOT.parent / "shared" / "data" / "office" / "office.mp4"
PY = str(ROOT / ".venv" / "bin" / "python") if (ROOT / ".venv" / "bin" / "python").exists() else sys.executable
TIMEOUT = 300
SRC: list[str] = []      # --src: the folder whose curate/ package the cases run (a snapshot of the working tree)
XSS = ("<script>alert(1)</script>", '"><img src=x onerror=alert(1)>')
BAD_OUTPUT = [re.compile(p, re.MULTILINE) for p in (
    r"Traceback \(most recent call last\)", r"Fatal Python error", r"terminate called", r"Check failed",
    r"Check failure stack trace", r"\*\*\* Aborted at", r"\*\*\* SIG[A-Z]+", r"^\s*@\s+0x[0-9a-f]+",
    r"Segmentation fault", r"core dumped", r"^\s*PC: @")]
FAST = ["--no-evaluate", "--triangulate", "off", "--budget", "4",   # pose import: no COLMAP, no evaluation,
        "--refine-iters", "100"]                                      # a short field where occupancy wants one
EVAL_FAST = ["--iters", "20", "--folds", "1", "--eval-size", "32", "--workers", "1"]
SUGGEST_FAST = ["--add", "2", "--candidates", "20", "--field", "none"]
E, O, A = "error", "ok", "any"


class SetupError(RuntimeError):
    pass


# ------------------------------------------------------------------ the sandbox of one case
class Ctx:
    """A case's sandbox: ``dir`` (snapshotted), ``tmp`` (TMPDIR), the run folders it declares, extra checks."""

    def __init__(self, base: Path, dir: Path, tmp: Path):
        self.base, self.dir, self.tmp = base, dir, tmp
        self.runs: list[Path] = []
        self.checks: list[Callable[[], list[str]]] = []
        self.signal: tuple | None = None          # (signum, delay_s) for a signal case
        self.exact = True                         # a signal case compares export bytes (else names only)

    def cap(self, n: int = 12, name: str = "cap", start: int = 0) -> Path:
        """A copy of n sample frames in DIR/name/images and a matching DIR/name/transforms.json."""
        d = json.loads((SAMPLE / "transforms.json").read_text())
        d["frames"] = d["frames"][start:start + n]
        cap = self.dir / name
        (cap / "images").mkdir(parents=True, exist_ok=True)
        for f in d["frames"]:
            shutil.copy(SAMPLE / f["file_path"], cap / f["file_path"])
        self.write_tf(cap, d)
        return cap

    @staticmethod
    def tf(cap: Path) -> dict:
        return json.loads((cap / "transforms.json").read_text())

    @staticmethod
    def write_tf(cap: Path, d, name: str = "transforms.json") -> Path:
        p = cap / name
        p.write_text(d if isinstance(d, str) else json.dumps(d, indent=1))
        return p

    def out(self, name: str = "run", declare: bool = True) -> Path:
        p = self.dir / name
        if declare:
            self.runs.append(p)
        return p

    def curate(self, *argv) -> None:
        """Run curate while building the case; it must succeed."""
        r = exec_curate(argv, self.dir, self.tmp)
        if r["rc"] != 0:
            raise SetupError(f"setup `curate {' '.join(map(str, argv))[:120]}` exited {r['rc']}: {tail(r['stderr'])}")

    def fast(self, cap: Path, out: Path, *extra) -> list:
        return ["run", cap / "images", "--poses", cap / "transforms.json", *FAST, "--out", out, *extra]

    def finished(self, cap: Path | None = None, name: str = "run", triangulate: bool = True) -> Path:
        """A finished run folder (fast pose import; with points when triangulate, so that suggest works)."""
        cap = cap or self.cap()
        run = self.out(name)
        argv = self.fast(cap, run)
        if triangulate:
            argv[argv.index("off")] = "auto"
        self.curate(*argv)
        return run


# ------------------------------------------------------------------ running and checking
def _unignore_signals() -> None:
    """A harness started in the background may ignore SIGINT (or SIGHUP under nohup); children inherit that,
    and curate keeps a signal ignored at its start. Handled (not ignored) here, default in the children."""
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(s) == signal.SIG_IGN:
            signal.signal(s, signal.default_int_handler if s == signal.SIGINT else signal.SIG_DFL)


def exec_curate(argv, cwd: Path, tmp: Path, timeout: float = TIMEOUT, sig: tuple | None = None) -> dict:
    """Run ``python -m curate ARGV``; sig=(signum, delay): send it after delay s. Returns rc, stdout, stderr."""
    cmd = ["nice", "-n", "10", PY, "-m", "curate", *map(str, argv)]
    tmp.mkdir(parents=True, exist_ok=True)
    cwd.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, TMPDIR=str(tmp), PYTHONUNBUFFERED="1", **({"PYTHONPATH": SRC[0]} if SRC else {}))
    t0 = time.time()
    p = subprocess.Popen(cmd, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, start_new_session=True)
    res = {"cmd": cmd, "timed_out": False, "signalled": False, "pid": p.pid}
    try:
        if sig:
            try:
                out, err = p.communicate(timeout=sig[1])
            except subprocess.TimeoutExpired:
                (os.killpg if sig[0] == signal.SIGINT else os.kill)(p.pid, sig[0])
                res["signalled"] = True
                out, err = p.communicate(timeout=60)
        else:
            out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)       # the process group this call started
        out, err = p.communicate()
        res["timed_out"] = True
    res.update(rc=p.returncode, stdout=out.decode("utf-8", "replace"), stderr=err.decode("utf-8", "replace"),
               seconds=round(time.time() - t0, 1))
    return res


def lines(text: str) -> list[str]:
    return [ln.split("\r")[-1] if ln.split("\r")[-1].strip() else ln for ln in text.splitlines()]


def tail(text: str, n: int = 4) -> str:
    return "\n".join([ln for ln in lines(text) if ln.strip()][-n:])[-1200:]


def _sha(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def snapshot(top: Path, exclude=()) -> dict[str, tuple]:
    """rel path -> (kind, ...) of every entry under top except the excluded folders (symlinks not followed,
    but a symlink's target string and the bytes it leads to are recorded)."""
    excl = {Path(os.path.abspath(e)) for e in exclude}
    snap: dict[str, tuple] = {}
    if not top.exists():
        return snap
    for dirpath, dirnames, filenames in os.walk(top):
        d = Path(dirpath)
        dirnames[:] = [n for n in dirnames if d / n not in excl]
        for n in dirnames + filenames:
            p = d / n
            if p in excl:
                continue
            st = os.lstat(p)
            rel = str(p.relative_to(top))
            if os.path.islink(p):
                target = os.readlink(p)
                try:
                    snap[rel] = ("link", target, _sha(p) if p.is_file() else None)
                except OSError:
                    snap[rel] = ("link", target, None)
            elif p.is_dir():
                snap[rel] = ("dir", st.st_mode & 0o7777)
            elif p.is_file():
                snap[rel] = ("file", st.st_mode & 0o7777, _sha(p))
            else:
                snap[rel] = ("other", st.st_mode)
    return snap


def diff_snapshots(before: dict, after: dict, runs_rel: list[str], what: str) -> list[str]:
    out = []
    for k in sorted(set(before) | set(after)):
        b, a = before.get(k), after.get(k)
        if b == a:
            continue
        if b is None:
            if a[0] == "dir" and any(r == k or r.startswith(k + os.sep) for r in runs_rel):
                continue                                   # a parent curate made for the run folder
            out.append(f"{what}: new {a[0]} {k!r} outside the run folder")
        elif a is None:
            out.append(f"{what}: {b[0]} {k!r} removed")
        else:
            out.append(f"{what}: {b[0]} {k!r} changed")
    return out[:8] + ([f"... {len(out) - 8} more"] if len(out) > 8 else [])


def scan_output(r: dict) -> list[str]:
    v = []
    for stream in ("stdout", "stderr"):
        for rx in BAD_OUTPUT:
            if rx.search(r[stream]):
                v.append(f"{stream} shows {rx.pattern!r}")
    if r["timed_out"]:
        v.append(f"timed out after {TIMEOUT}s")
    elif r["rc"] is not None and r["rc"] < 0:
        v.append(f"killed by signal {-r['rc']}")
    if "internal error:" in r["stderr"]:
        v.append("internal error (an unexpected exception)")
    return v


def check_html(top: Path) -> list[str]:
    v = []
    for p in top.rglob("*.html"):
        data = p.read_bytes()
        for s in XSS:
            if s.encode() in data:
                v.append(f"raw markup {s!r} in {p.relative_to(top)}")
    return v


def is_user_folder(p: Path) -> bool:
    return p.is_dir() and not p.is_symlink() and any(p.iterdir()) and not (p / ".curate-run.json").exists()


# ------------------------------------------------------------------ one case
@dataclass
class Case:
    name: str
    family: str
    expect: str
    build: Callable[[Ctx], list]      # builds the sandbox, returns curate's argv (may register checks)


def run_case(case: Case, out: Path) -> dict:
    cdir, tmp = out / "cases" / case.name, out / "tmp" / case.name
    for d in (cdir, tmp):
        if d.exists():
            for sub in d.rglob("*"):                     # a case may chmod its files; make them removable
                if sub.is_dir() and not sub.is_symlink():
                    os.chmod(sub, 0o755)
            shutil.rmtree(d)
        d.mkdir(parents=True)
    ctx = Ctx(out / "base", cdir, tmp)
    res = {"case": case.name, "family": case.family, "expect": case.expect, "rc": None, "ok": False,
           "violations": [], "stderr_tail": ""}
    t0 = time.time()
    try:
        argv = case.build(ctx)
    except SetupError as e:
        res["violations"] = [str(e)]
        return res
    runs_rel = [str(r.relative_to(cdir)) for r in ctx.runs]
    before = snapshot(cdir, ctx.runs)
    user_before = {str(r): snapshot(r) for r in ctx.runs if is_user_folder(r)}
    if ctx.signal:
        r, v = signal_case(ctx, argv)
    else:
        r = exec_curate(argv, cdir, tmp)
        v = scan_output(r)
        errs = sum(": error:" in ln for ln in lines(r["stderr"]))
        if r["rc"] not in (0, None) and errs != 1 and not r["timed_out"]:
            v.append(f"failed (exit {r['rc']}) with {errs} ': error:' lines (expected 1)")
        if case.expect == E and r["rc"] == 0:
            v.append("expected an error, exited 0")
        if case.expect == O and r["rc"] != 0:
            v.append(f"expected success, exited {r['rc']}")
    for chk in ctx.checks:
        v += chk()
    v += diff_snapshots(before, snapshot(cdir, ctx.runs), runs_rel, "sandbox")
    for rd, snap in user_before.items():
        after = snapshot(Path(rd))
        v += [f"user's --out file {k!r} changed or removed" for k in snap if after.get(k) != snap[k]][:5]
    v += check_html(cdir)
    crash = sorted(tmp.glob("curate-error-*.log"))
    if crash:
        res["crash_log_tail"] = tail(crash[-1].read_text(errors="replace"), 6)
    res.update(rc=r["rc"], ok=not v, violations=v, stderr_tail=tail(r["stderr"]), seconds=round(time.time() - t0, 1),
               cmd=" ".join(map(str, argv)))
    return res


def export_tree(run: Path) -> dict:
    skip = {"export.json", "stage.json", ".curate-stage"}
    return {k: val for k, val in snapshot(run / "export").items() if Path(k).name not in skip}


def signal_case(ctx: Ctx, argv: list) -> tuple[dict, list[str]]:
    """Interrupt ARGV, check the stop, re-run it and compare its export with an uninterrupted run's."""
    signum, delay = ctx.signal
    run = Path(argv[argv.index("--out") + 1])
    ref = ctx.dir / "ref"
    r = exec_curate(argv, ctx.dir, ctx.tmp, sig=(signum, delay))
    v = scan_output(r)
    if not r["signalled"]:
        v.append(f"finished (exit {r['rc']}) before the signal at {delay}s: lengthen the run")
    elif r["rc"] == 0:
        v.append("exited 0 after the signal")
    said = [ln for ln in lines(r["stderr"]) if "curate run:" in ln]
    if r["signalled"] and len(said) != 1:
        v.append(f"{len(said)} 'curate run:' lines after the signal (expected 1)")
    try:
        os.killpg(r["pid"], 0)
        v.append("processes of the interrupted run still alive")
        os.killpg(r["pid"], signal.SIGKILL)         # the group this harness started
    except ProcessLookupError:
        pass
    lock = run / ".curate-lock"
    if lock.exists():
        with open(lock, "rb+") as f:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.flock(f, fcntl.LOCK_UN)
            except OSError:
                v.append("the run lock is still held")
        if lock.read_bytes().strip():
            v.append("the run lock was not emptied (not released)")
    again = exec_curate(argv, ctx.dir, ctx.tmp)
    v += [f"re-run: {x}" for x in scan_output(again)]
    if again["rc"] != 0:
        v.append(f"re-run exited {again['rc']}: {tail(again['stderr'], 1)}")
    ref_argv = [ref if a == run else a for a in argv]
    clean = exec_curate(ref_argv, ctx.dir, ctx.tmp)
    if clean["rc"] != 0:
        v.append(f"the uninterrupted reference run exited {clean['rc']}")
    elif again["rc"] == 0:
        a, b = export_tree(run), export_tree(ref)
        if not ctx.exact:
            a, b = ({k: v[0] for k, v in t.items()} for t in (a, b))
        diff = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
        if diff:
            v.append(f"re-run's export differs from an uninterrupted run's: {diff[:5]}")
    return r, v


# ------------------------------------------------------------------ sandbox pieces shared by cases
def build_base(base: Path) -> None:
    """OUT/base: a 30-frame and a 1-frame H.264 video of the sample, and a COLMAP text model (legacy format)."""
    if (base / "done").exists():
        return
    shutil.rmtree(base, ignore_errors=True)
    base.mkdir(parents=True)
    frames = sorted((SAMPLE / "images").glob("*.jpg"))
    make_video(base / "walk30.mp4", frames[:30])
    make_video(base / "one.mp4", frames[:1])
    ctx = Ctx(base, base / "ref", base / "tmp")
    run = ctx.finished(ctx.cap())
    import pycolmap
    (base / "colmap").mkdir()
    pycolmap.Reconstruction(str(run / "sfm" / "sparse" / "0")).write_text(str(base / "colmap"))
    for f in ("rigs.txt", "frames.txt"):
        (base / "colmap" / f).unlink(missing_ok=True)
    (base / "done").write_text("ok")


def make_video(path: Path, frames: list[Path]) -> None:
    import av
    import numpy as np
    from PIL import Image
    with av.open(str(path), "w") as c:
        s = c.add_stream("libx264", rate=10)
        s.width, s.height, s.pix_fmt = 320, 240, "yuv420p"
        for f in frames:
            for pkt in s.encode(av.VideoFrame.from_ndarray(np.asarray(Image.open(f).convert("RGB")), format="rgb24")):
                c.mux(pkt)
        for pkt in s.encode():
            c.mux(pkt)


def add_frame(cap: Path, name: str, make: Callable[[Path], None], like: int = 11) -> None:
    """Put a file made by ``make`` at cap/images/NAME and a pose for it (frame ``like``'s) in transforms.json."""
    make(cap / "images" / name)
    d = Ctx.tf(cap)
    d["frames"].append({**d["frames"][like], "file_path": f"images/{name}"})
    Ctx.write_tf(cap, d)


def rename_frames(cap: Path, fmt: str, k: int | None = None) -> None:
    """Rename frames (all, or the first k) to fmt.format(i) and update transforms.json."""
    d = Ctx.tf(cap)
    for i, f in enumerate(d["frames"][:k] if k else d["frames"]):
        new = f"images/{fmt.format(i)}"
        os.rename(cap / f["file_path"], cap / new)
        f["file_path"] = new
    Ctx.write_tf(cap, d)


def jpeg_bytes(i: int = 0) -> bytes:
    return (SAMPLE / "images" / f"frame_{i:04d}.jpg").read_bytes()


def img(size=(1, 1), fmt="JPEG"):
    def make(p: Path) -> None:
        from PIL import Image
        Image.new("RGB", size, (200, 10, 10)).save(p, fmt)
    return make


def write(data: bytes):
    return lambda p: p.write_bytes(data)


def symlink(target: str):
    return lambda p: os.symlink(target, p)


def hostile_dir(parent: Path) -> Path:
    """parent/<script>alert(1)</script> (two folders: a name cannot hold '/')."""
    return parent / XSS[0]


# ------------------------------------------------------------------ flags
FLAG_RUN = [   # appended to a fast pose-import `curate run` (the last occurrence of a flag wins)
    ("budget-neg", ["--budget", "-1"], E), ("budget-zero", ["--budget", "0"], E),
    ("budget-nan", ["--budget", "nan"], E),
    ("budget-inf", ["--budget", "inf"], E), ("budget-1e309", ["--budget", "1e309"], E),
    ("budget-text", ["--budget", "abc"], E), ("budget-empty", ["--budget", ""], E),
    ("budget-huge-int", ["--budget", "9" * 30], A), ("budget-pct-neg", ["--budget", "-5%"], E),
    ("budget-pct-500", ["--budget", "500%"], E), ("budget-pct-0", ["--budget", "0%"], E),
    ("budget-pct-nan", ["--budget", "nan%"], E), ("budget-fraction", ["--budget", "2.5"], A),
    ("budget-pct-100", ["--budget", "100%"], A), ("budget-twice-last-bad", ["--budget", "3", "--budget", "-1"], E),
    ("budget-auto-nocheck", ["--budget", "auto", "--no-budget-check"], A),
    ("tolerance-neg", ["--budget", "auto", "--no-budget-check", "--budget-tolerance", "-1"], E),
    ("tolerance-nan", ["--budget", "auto", "--no-budget-check", "--budget-tolerance", "nan"], E),
    ("seed-text", ["--seed", "abc"], E), ("seed-neg", ["--method", "random", "--seed", "-1"], A),
    ("seed-huge", ["--method", "random", "--seed", "9" * 30], A),
    ("gamma-nan", ["--gamma", "nan"], E), ("gamma-inf", ["--gamma", "inf"], E),
    ("gamma-neg", ["--method", "energy", "--gamma", "-1"], A),
    ("bins-zero", ["--bins", "0x0"], E), ("bins-text", ["--bins", "abc"], E), ("bins-neg", ["--bins", "-5x10"], E),
    ("bins-huge", ["--bins", "99999999999x2"], A),
    ("res-zero", ["--res", "0"], E), ("res-neg", ["--res", "-1"], E), ("res-huge", ["--res", "9" * 30], E),
    ("res-nan", ["--res", "nan"], E),
    ("box-short", ["--box", "1,2,3"], E), ("box-nan", ["--box", "nan,0,0,1,1,1"], E),
    ("box-inverted", ["--box", "1,1,1,0,0,0"], E), ("box-flat", ["--box", "0,0,0,0,1,1"], E),
    ("box-inf", ["--box", "-inf,-1,-1,inf,1,1"], E), ("box-text", ["--box", "a,b,c,d,e,f"], E),
    ("refine-iters-neg", ["--refine-iters", "-1"], E), ("refine-size-zero", ["--refine-size", "0"], E),
    ("holdout-every-zero", ["--holdout-every", "0"], E), ("iters-neg", ["--iters", "-5"], E),
    ("eval-size-zero", ["--eval-size", "0"], E), ("eval-minutes-nan", ["--eval-minutes", "nan"], E),
    ("eval-minutes-neg", ["--eval-minutes", "-1"], E), ("folds-neg", ["--folds", "-1"], E),
    ("equivalence-nan", ["--equivalence-db", "nan"], E), ("random-seeds-neg", ["--random-seeds", "-1"], E),
    ("workers-neg", ["--workers", "-1"], E), ("workers-text", ["--workers", "two"], E),
    ("max-size-zero", ["--max-size", "0"], E), ("max-frames-1e309", ["--max-frames", "1e309"], E),
    ("sift-nan", ["--sift-peak-threshold", "nan"], E), ("sift-neg", ["--sift-peak-threshold", "-1"], E),
    ("method-bogus", ["--method", "bogus"], E), ("export-mode-bogus", ["--export-mode", "symlinks"], E),
    ("matcher-bogus", ["--matcher", "vocab"], E), ("camera-mode-bogus", ["--camera-mode", "multi"], E),
    ("mapper-bogus", ["--mapper", "hierarchical"], E), ("on-split-bogus", ["--on-split", "merge"], E),
    ("triangulate-bogus", ["--triangulate", "on"], E), ("device-bogus", ["--device", "toaster"], E),
    ("device-cuda9", ["--device", "cuda:9"], A), ("unknown-flag", ["--frobnicate"], E),
    ("conflict-recursive", ["--recursive", "--no-recursive"], O), ("conflict-noeval-folds", ["--folds", "3"], A),
    ("conflict-tolerance-with-count", ["--budget-tolerance", "1"], A),
    ("conflict-energy-no-path-weights", ["--method", "energy", "--no-path-weights"], O),
    ("conflict-adopt-force-new", ["--adopt", "--force"], O),
]

FLAG_STAGE = [  # (name, command, flags, expect): on a finished run folder RUN, or the pose file T (select/sfm)
    ("select-pose-budget-neg", "select-pose", ["--budget", "-1"], E),
    ("select-pose-budget-zero", "select-pose", ["--budget", "0"], E),
    ("select-pose-budget-text", "select-pose", ["--json", "--budget", "abc"], E),
    ("select-pose-budget-1e309", "select-pose", ["--budget", "1e309"], E),
    ("select-pose-method-bogus", "select-pose", ["--method", "bogus"], E),
    ("select-pose-res-zero", "select-pose", ["--res", "0"], E),
    ("select-pose-box-bad", "select-pose", ["--box", "0,0,0"], E),
    ("select-pose-ok", "select-pose", ["--budget", "3", "--json"], O),
    ("select-run-budget-pct-neg", "select", ["--budget", "-5%"], E),
    ("select-run-gamma-nan", "select", ["--gamma", "nan"], E),
    ("select-run-ok", "select", ["--budget", "3"], O),
    ("evaluate-iters-neg", "evaluate", ["--iters", "-1"], E),
    ("evaluate-holdout-zero", "evaluate", ["--holdout-every", "0"], E),
    ("evaluate-folds-neg", "evaluate", ["--folds", "-1"], E),
    ("evaluate-minutes-nan", "evaluate", ["--eval-minutes", "nan"], E),
    ("evaluate-workers-text", "evaluate", ["--workers", "abc"], E),
    ("evaluate-eval-size-zero", "evaluate", ["--eval-size", "0"], E),
    ("evaluate-equivalence-inf", "evaluate", ["--equivalence-db", "inf"], E),
    ("evaluate-random-seeds-zero", "evaluate", ["--random-seeds", "0"], A),
    ("export-mode-bogus", "export", ["--mode", "bogus"], E),
    ("export-mode-empty", "export", ["--mode", ""], E),
    ("export-copy-ok", "export", ["--mode", "copy"], O),
    ("export-downscale-3", "export", ["--downscale", "3"], E),
    ("export-downscale-zero", "export", ["--downscale", "0"], E),
    ("export-downscale-text", "export", ["--downscale", "2,x"], E),
    ("export-downscale-force-ok", "export", ["--downscale", "2,4", "--force"], O),
    ("export-undistort-bogus", "export", ["--undistort", "always"], E),
    ("suggest-add-zero", "suggest", ["--add", "0"], E),
    ("suggest-add-neg", "suggest", ["--add", "-1"], E),
    ("suggest-add-1e309", "suggest", ["--add", "1e309"], E),
    ("suggest-candidates-zero", "suggest", ["--candidates", "0"], E),
    ("suggest-candidates-nan", "suggest", ["--candidates", "nan"], E),
    ("suggest-nodes-bogus", "suggest", ["--nodes", "everything"], E),
    ("suggest-field-bogus", "suggest", ["--field", "nerf"], E),
    ("suggest-field-iters-neg", "suggest", ["--field-iters", "-1"], E),
    ("suggest-preview-size-zero", "suggest", ["--preview-size", "0"], E),
    ("suggest-seed-text", "suggest", ["--seed", "abc"], E),
    ("suggest-ok", "suggest", [], O),
    ("report-unknown-flag", "report", ["--bogus"], E),
    ("report-ok", "report", ["--force"], O),
    ("sfm-max-size-zero", "sfm", ["--max-size", "0"], E),
    ("sfm-max-size-neg", "sfm", ["--max-size", "-1"], E),
    ("sfm-sift-nan", "sfm", ["--sift-peak-threshold", "nan"], E),
    ("sfm-poses-ok", "sfm", [], O),
]


def flag_run_case(flags):
    def build(c: Ctx):
        return c.fast(c.cap(), c.out(), *flags)
    return build


def flag_stage_case(cmd, flags):
    def build(c: Ctx):
        cap = c.cap()
        if cmd == "select-pose":
            return ["select", cap / "transforms.json", "--out", c.out("chosen"), "--budget", "3", *flags]
        if cmd == "sfm":
            return ["sfm", cap / "images", "--poses", cap / "transforms.json", "--out", c.out(), *flags]
        run = c.finished(cap)
        base = {"evaluate": EVAL_FAST, "suggest": SUGGEST_FAST}.get(cmd, [])
        return [cmd, run, *base, *flags]
    return build


# ------------------------------------------------------------------ photo folders
def _pose_run(mutate, *extra):
    """A fast pose import of a capture that ``mutate(cap)`` changed (it may return another PHOTOS path)."""
    def build(c: Ctx):
        cap = c.cap()
        got = mutate(c, cap)
        src = got if isinstance(got, Path) else cap / "images"
        return ["run", src, "--poses", cap / "transforms.json", *FAST, "--out", c.out(), *extra]
    return build


def _sfm_run(mutate):
    """A COLMAP run (no poses) on the capture's photos after ``mutate(cap)`` (it may return another PHOTOS)."""
    def build(c: Ctx):
        cap = c.cap()
        (cap / "transforms.json").unlink()
        got = mutate(c, cap)
        return ["run", got if isinstance(got, Path) else cap / "images", "--no-evaluate", "--budget", "4",
                "--out", c.out()]
    return build


def _junk_all(c, cap):
    im = cap / "images"
    (im / "zero.jpg").write_bytes(b"")
    (im / "trunc.jpg").write_bytes(jpeg_bytes(3)[:700])
    (im / "text.jpg").write_text("not a photo\n")
    img((1, 1))(im / "one_px.jpg")
    (im / "dir.jpg").mkdir()
    os.symlink("missing.jpg", im / "dangling.jpg")
    os.symlink("loop_b.jpg", im / "loop_a.jpg")
    os.symlink("loop_a.jpg", im / "loop_b.jpg")


def _hostile_folder(c, cap):
    d = hostile_dir(c.dir)
    d.parent.mkdir(parents=True)
    os.rename(cap / "images", d)
    return d


def _identical(c, cap):
    for f in Ctx.tf(cap)["frames"]:
        (cap / f["file_path"]).write_bytes(jpeg_bytes(0))


def _keep(n):
    def m(c, cap):
        d = Ctx.tf(cap)
        for f in d["frames"][n:]:
            (cap / f["file_path"]).unlink()
        d["frames"] = d["frames"][:n]
        Ctx.write_tf(cap, d)
    return m


def _duplicates(c, cap):
    d = Ctx.tf(cap)
    for f in list(d["frames"]):
        new = f["file_path"].replace(".jpg", "_copy.jpg")
        shutil.copy(cap / f["file_path"], cap / new)
        d["frames"].append({**f, "file_path": new})
    Ctx.write_tf(cap, d)


def _png(c, cap):
    from PIL import Image
    d = Ctx.tf(cap)
    for f in d["frames"]:
        p = cap / f["file_path"]
        Image.open(p).save(p.with_suffix(".png"))
        p.unlink()
        f["file_path"] = f["file_path"].replace(".jpg", ".png")
    Ctx.write_tf(cap, d)


def _links_to_sample(c, cap):
    for f in Ctx.tf(cap)["frames"]:
        (cap / f["file_path"]).unlink()
        os.symlink(SAMPLE / f["file_path"], cap / f["file_path"])


def _folder_link(c, cap):
    os.symlink(cap / "images", c.dir / "photos_link")
    return c.dir / "photos_link"


def _emptied(c, cap):
    for p in (cap / "images").iterdir():
        p.unlink()


PHOTOS = [  # (name, builder, expect)
    ("photos-zero-byte-named", _pose_run(lambda c, cap: add_frame(cap, "zero.jpg", write(b""))), A),
    ("photos-zero-byte-unnamed", _pose_run(lambda c, cap: (cap / "images" / "zero.jpg").write_bytes(b"")), O),
    ("photos-truncated-jpeg-named",
     _pose_run(lambda c, cap: add_frame(cap, "trunc.jpg", write(jpeg_bytes(5)[:900]))), A),
    ("photos-truncated-png-named", _pose_run(lambda c, cap: add_frame(cap, "trunc.png", lambda p: (
        img((320, 240), "PNG")(p), p.write_bytes(p.read_bytes()[:200])))), A),
    ("photos-text-as-jpg-named",
     _pose_run(lambda c, cap: add_frame(cap, "text.jpg", write(b"hello, not a jpeg\n"))), A),
    ("photos-1x1-named", _pose_run(lambda c, cap: add_frame(cap, "px.jpg", img((1, 1)))), A),
    ("photos-big-frame-named", _pose_run(lambda c, cap: add_frame(cap, "big.jpg", img((640, 480)))), A),
    ("photos-dir-as-jpg-named", _pose_run(lambda c, cap: add_frame(cap, "x.jpg", lambda p: p.mkdir())), A),
    ("photos-dangling-link-named", _pose_run(lambda c, cap: add_frame(cap, "gone.jpg", symlink("nowhere.jpg"))), A),
    ("photos-link-loop-named", _pose_run(lambda c, cap: (os.symlink("b.jpg", cap / "images" / "a.jpg"),
                                                       add_frame(cap, "b.jpg", symlink("a.jpg")))), A),
    ("photos-dangling-link-unnamed", _pose_run(lambda c, cap: os.symlink("nowhere", cap / "images" / "gone.jpg")), O),
    ("photos-hostile-file-names", _pose_run(lambda c, cap: rename_frames(cap, XSS[1] + "{}.jpg")), O),
    ("photos-hostile-folder", _pose_run(_hostile_folder), O),
    ("photos-newline-names", _pose_run(lambda c, cap: rename_frames(cap, "line\nbreak_{}.jpg")), A),
    ("photos-leading-dash-names", _pose_run(lambda c, cap: rename_frames(cap, "-f{}.jpg")), O),
    ("photos-unicode-names", _pose_run(lambda c, cap: rename_frames(cap, "фото_ü_😀_{}.jpg")), O),
    ("photos-space-names", _pose_run(lambda c, cap: rename_frames(cap, "my photo {}.jpg")), O),
    ("photos-duplicated-frames", _pose_run(_duplicates), A),
    ("photos-all-identical", _pose_run(_identical), A),
    ("photos-one-frame", _pose_run(_keep(1)), A),
    ("photos-two-frames", _pose_run(_keep(2), "--budget", "1"), A),
    ("photos-png-frames", _pose_run(_png), O),
    ("photos-links-to-originals", _pose_run(_links_to_sample), O),
    ("photos-folder-is-symlink", _pose_run(_folder_link), O),
    ("photos-empty-folder", _pose_run(_emptied), E),
    ("photos-missing-folder", _pose_run(lambda c, cap: c.dir / "no_such_folder"), E),
    ("photos-photos-is-a-file", _pose_run(lambda c, cap: cap / "images" / "frame_0000.jpg"), A),
    ("photos-sfm-junk-files", _sfm_run(_junk_all), A),
    ("photos-sfm-hostile-names",
     _sfm_run(lambda c, cap: (rename_frames_plain(cap, XSS[1] + "{}.jpg"), _hostile_folder(c, cap))[1]), O),
    ("photos-sfm-unicode-newline-names", _sfm_run(lambda c, cap: rename_frames_plain(cap, "ü 😀\n{}.jpg")), A),
    ("photos-sfm-all-identical",
     _sfm_run(lambda c, cap: [p.write_bytes(jpeg_bytes(0)) for p in (cap / "images").iterdir()] and None), A),
    ("photos-sfm-two-frames",
     _sfm_run(lambda c, cap: [p.unlink() for p in sorted((cap / "images").iterdir())[2:]] and None), A),
    ("photos-sfm-empty-folder", _sfm_run(_emptied), E),
    ("photos-sfm-missing-folder", _sfm_run(lambda c, cap: c.dir / "nope"), E),
]


def rename_frames_plain(cap: Path, fmt: str) -> None:
    for i, p in enumerate(sorted((cap / "images").iterdir())):
        os.rename(p, p.with_name(fmt.format(i)))


# ------------------------------------------------------------------ pose files
def _frames(fn):
    """A mutation applied to every frame dict."""
    def m(d):
        for f in d["frames"]:
            fn(f)
        return d
    return m


def _first(fn):
    def m(d):
        fn(d["frames"][0])
        return d
    return m


def _set(**kw):
    def m(d):
        d.update(kw)
        return d
    return m


def _mat(f, fn):
    f["transform_matrix"] = fn(f["transform_matrix"])


def _drop(key):
    return lambda f: f.pop(key, None)


POSE_TEXT = [  # (name, text of transforms.json from the valid one, expect)
    ("pose-file-malformed", lambda t: t[: len(t) // 2], E),
    ("pose-file-empty", lambda t: "", E),
    ("pose-file-bom", lambda t: "\ufeff" + t, A),
    ("pose-file-top-list", lambda t: "[" + t + "]", E),
    ("pose-file-deep-nesting", lambda t: '{"frames": ' + "[" * 10000 + "]" * 10000 + "}", E),
    ("pose-file-nan-literals", lambda t: t.replace("277.0", "NaN"), E),
    ("pose-file-duplicate-keys", lambda t: t.replace('"fl_x": 277.0', '"fl_x": -1, "fl_x": 277.0'), A),
]
POSE_DICT = [  # (name, mutation of the parsed transforms.json, expect)
    ("pose-nan-matrix-all", _frames(lambda f: _mat(f, lambda m: [[float("nan")] * 4] * 3 + [[0, 0, 0, 1]])), E),
    ("pose-inf-matrix-one", _first(lambda f: _mat(f, lambda m: [m[0][:3] + [float("inf")]] + m[1:])), A),
    ("pose-3x3-matrix", _frames(lambda f: _mat(f, lambda m: [r[:3] for r in m[:3]])), E),
    ("pose-3x4-matrix", _frames(lambda f: _mat(f, lambda m: m[:3])), A),
    ("pose-singular-rotation", _frames(lambda f: _mat(f, lambda m: [[0, 0, 0, r[3]] for r in m[:3]] + [m[3]])), E),
    ("pose-sheared-rotation-one",
     _first(lambda f: _mat(f, lambda m: [[r[0], r[1] + 0.8 * r[0], r[2], r[3]] for r in m[:3]] + [m[3]])), A),
    ("pose-scale-1e12", _frames(lambda f: _mat(f, lambda m: [r[:3] + [r[3] * 1e12] for r in m[:3]] + [m[3]])), A),
    ("pose-rotation-scaled-1e12",
     _frames(lambda f: _mat(f, lambda m: [[x * 1e12 for x in r[:3]] + [r[3]] for r in m[:3]] + [m[3]])), A),
    ("pose-duplicate-frames", lambda d: {**d, "frames": d["frames"] + d["frames"]}, A),
    ("pose-missing-file-path-one", _first(_drop("file_path")), A),
    ("pose-missing-file-path-all", _frames(_drop("file_path")), E),
    ("pose-missing-matrix-all", _frames(_drop("transform_matrix")), E),
    ("pose-matrix-null", _frames(lambda f: f.update(transform_matrix=None)), E),
    ("pose-matrix-string", _frames(lambda f: f.update(transform_matrix="abc")), E),
    ("pose-w-zero", _set(w=0), E), ("pose-h-negative", _set(h=-240), E),
    ("pose-flx-zero", _set(fl_x=0.0), E), ("pose-flx-negative", _set(fl_x=-277.0), E),
    ("pose-flx-nan", _set(fl_x=float("nan")), E), ("pose-flx-huge", _set(fl_x=1e308, fl_y=1e308), A),
    ("pose-flx-string", _set(fl_x="abc"), E), ("pose-w-numeric-string", _set(w="320"), A),
    ("pose-camera-model-unknown", _set(camera_model="FISHEYE_9000"), E),
    ("pose-k1-absurd", _set(k1=1e9, camera_model="OPENCV"), A),
    ("pose-frames-empty", _set(frames=[]), E), ("pose-frames-not-list", _set(frames={"a": 1}), E),
    ("pose-frames-missing", lambda d: {k: v for k, v in d.items() if k != "frames"}, E),
    ("pose-one-frame", lambda d: {**d, "frames": d["frames"][:1]}, A),
    ("pose-frame-intrinsics-nan", _frames(lambda f: f.update(fl_x=float("nan"))), E),
]


def pose_text_case(mut):
    def build(c: Ctx):
        cap = c.cap()
        t = (cap / "transforms.json").read_text()
        (cap / "transforms.json").write_text(mut(t))
        return ["run", cap / "images", "--poses", cap / "transforms.json", *FAST, "--out", c.out()]
    return build


def pose_dict_case(mut):
    def build(c: Ctx):
        cap = c.cap()
        Ctx.write_tf(cap, mut(Ctx.tf(cap)))
        return ["run", cap / "images", "--poses", cap / "transforms.json", *FAST, "--out", c.out()]
    return build


def _outside_paths(kind):
    """file_path of frame 0 outside the capture: ../ traversal or absolute; or naming a directory."""
    def build(c: Ctx):
        cap = c.cap()
        outside = c.dir / "elsewhere"
        outside.mkdir()
        shutil.copy(cap / "images" / "frame_0000.jpg", outside / "secret.jpg")
        d = Ctx.tf(cap)
        d["frames"][0]["file_path"] = {"traversal": "../elsewhere/secret.jpg", "absolute": str(outside / "secret.jpg"),
                                       "directory": "images", "deep-traversal": "../" * 30 + "etc/passwd"}[kind]
        Ctx.write_tf(cap, d)
        return ["run", "--poses", cap / "transforms.json", *FAST, "--out", c.out()]   # the pose file's own paths
    return build


def _pose_path(what):
    def build(c: Ctx):
        cap = c.cap()
        p = {"missing": cap / "nope.json", "folder-without": c.dir / "empty_folder", "utf16": cap / "t16.json"}[what]
        if what == "folder-without":
            p.mkdir()
        if what == "utf16":
            p.write_text((cap / "transforms.json").read_text(), encoding="utf-16")
        return ["run", cap / "images", "--poses", p, *FAST, "--out", c.out()]
    return build


def _colmap(mutate):
    def build(c: Ctx):
        cap = c.cap()
        model = c.dir / "model"
        shutil.copytree(c.base / "colmap", model)
        mutate(model)
        return ["run", cap / "images", "--poses", model, *FAST, "--out", c.out()]
    return build


def _edit_line(fname, fn, comment="#"):
    """Apply fn to the first data line of model/fname (None: delete the line)."""
    def m(model: Path):
        ls = (model / fname).read_text().splitlines()
        i = next(k for k, ln in enumerate(ls) if ln and not ln.startswith(comment))
        new = fn(ls[i].split())
        ls[i:i + 1] = [] if new is None else [" ".join(new)]
        (model / fname).write_text("\n".join(ls) + "\n")
    return m


COLMAP = [
    ("colmap-legacy-ok", lambda m: None, O),
    ("colmap-no-points", lambda m: (m / "points3D.txt").unlink(), A),
    ("colmap-camera-unknown-model", _edit_line("cameras.txt", lambda w: w[:1] + ["BOGUS"] + w[2:]), E),
    ("colmap-camera-missing-params", _edit_line("cameras.txt", lambda w: w[:5]), E),
    ("colmap-camera-negative-size", _edit_line("cameras.txt", lambda w: w[:2] + ["-320"] + w[3:]), E),
    ("colmap-camera-nan-focal", _edit_line("cameras.txt", lambda w: w[:4] + ["nan", "nan"] + w[6:]), E),
    ("colmap-image-nan-quaternion", _edit_line("images.txt", lambda w: w[:1] + ["nan"] * 4 + w[5:]), E),
    ("colmap-image-zero-quaternion", _edit_line("images.txt", lambda w: w[:1] + ["0"] * 4 + w[5:]), E),
    ("colmap-image-unknown-camera", _edit_line("images.txt", lambda w: w[:8] + ["99"] + w[9:]), E),
    ("colmap-images-truncated", lambda m: (m / "images.txt").write_text((m / "images.txt").read_text()[:1500]), E),
    ("colmap-images-header-only", lambda m: (m / "images.txt").write_text("# nothing\n"), E),
    ("colmap-empty-folder", lambda m: [p.unlink() for p in m.iterdir()] and None, E),
    ("colmap-binary-garbage", lambda m: ([p.unlink() for p in m.iterdir()],
                                         [(m / f).write_bytes(os.urandom(64))
                                          for f in ("cameras.bin", "images.bin", "points3D.bin")]), E),
]


# ------------------------------------------------------------------ run folders
def _refused_out(make):
    """--out is something curate must refuse (not declared: anything it leaves there is a violation)."""
    def build(c: Ctx):
        cap = c.cap()
        return c.fast(cap, make(c, cap))
    return build


def _user_folder(c: Ctx, name="mystuff") -> Path:
    d = c.dir / name
    (d / "notes").mkdir(parents=True)
    (d / "notes" / "todo.txt").write_text("buy milk\n")
    (d / "thesis.tex").write_text("\\documentclass{article}\n")
    return d


def _stage_on(where, cmd):
    def build(c: Ctx):
        if where == "empty":
            (c.dir / "empty").mkdir()
            folder = c.dir / "empty"
        elif where == "user":
            folder = _user_folder(c)
        else:
            folder = c.dir / "does_not_exist"
        return [cmd, folder, *{"evaluate": EVAL_FAST, "suggest": SUGGEST_FAST}.get(cmd, [])]
    return build


def _corrupt(path, how, cmd, extra=()):
    """A finished run whose RUN/path is corrupted (how: garbage | truncate | empty), then `cmd RUN`."""
    def build(c: Ctx):
        run = c.finished()
        p = run / path
        data = p.read_bytes()
        p.write_bytes({"garbage": b"\x00{not json" + os.urandom(32), "truncate": data[: len(data) // 2],
                       "empty": b""}[how])
        return [cmd, run, *{"suggest": SUGGEST_FAST}.get(cmd, []), *extra]
    return build


def _photos_deleted(cmd, extra=()):
    def build(c: Ctx):
        cap = c.cap()
        run = c.finished(cap)
        shutil.rmtree(cap / "images")
        if cmd == "run":
            argv = c.fast(cap, run)
            return argv
        return [cmd, run, *extra]
    return build


def _edited_export(extra):
    """The user replaced an exported photo (a link) with an edited copy: it must survive `export RUN ...`."""
    def build(c: Ctx):
        run = c.finished()
        img_dir = run / "export" / "images"
        victim = min(img_dir.iterdir())
        victim.unlink()
        from PIL import Image
        Image.new("RGB", (320, 240), (0, 255, 0)).save(victim, "JPEG")
        want = _sha(victim)
        c.checks.append(lambda: [] if victim.is_file() and not victim.is_symlink() and _sha(victim) == want
                        else [f"the user's edited export/images/{victim.name} was replaced or removed"])
        return ["export", run, "--mode", "copy", *extra]
    return build


def _distorted_export(extra):
    """A capture with lens distortion (k1), exported (undistorted, hard-linked or copied) and re-exported:
    the originals the export hard-links must stay as they were."""
    def build(c: Ctx):
        cap = c.cap()
        d = Ctx.tf(cap)
        d.update(camera_model="OPENCV", k1=-0.12, k2=0.02, p1=0.0, p2=0.0)
        Ctx.write_tf(cap, d)
        run = c.finished(cap)
        return ["export", run, "--force", *extra]
    return build


def _second_capture(force):
    def build(c: Ctx):
        run = c.finished(c.cap(name="capA"))
        capb = c.cap(name="capB", start=40)
        return c.fast(capb, run, *(["--force"] if force else []))
    return build


def _rerun_same(c: Ctx):
    cap = c.cap()
    run = c.out()
    c.curate(*c.fast(cap, run))
    return c.fast(cap, run)


def _hostile_out(c: Ctx):
    cap = c.cap()
    run = hostile_dir(c.dir) / (XSS[1] + "run")
    c.runs.append(run)
    return ["run", cap / "images", "--poses", cap / "transforms.json", "--no-evaluate", "--budget", "4", "--out", run]


def _hostile_suggest(c: Ctx):
    cap = c.cap()
    rename_frames(cap, XSS[1] + "{}.jpg")
    d = hostile_dir(c.dir)
    d.parent.mkdir(parents=True)
    os.rename(cap / "images", d)
    run = c.out()
    c.curate("run", d, "--poses", cap / "transforms.json", "--no-evaluate", "--budget", "4", "--out", run)
    return ["suggest", run, *SUGGEST_FAST]


def _concurrent(c: Ctx):
    """A second command on a run folder that a running `curate run` holds must be refused."""
    cap = c.cap(n=40)
    (cap / "transforms.json").unlink()
    run = c.out()
    cmd = ["nice", "-n", "10", PY, "-m", "curate", "run", str(cap / "images"), "--no-evaluate", "--budget", "8",
           "--out", str(run)]
    env = dict(os.environ, TMPDIR=str(c.tmp), **({"PYTHONPATH": SRC[0]} if SRC else {}))
    bg = subprocess.Popen(cmd, cwd=c.dir, env=env, stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, start_new_session=True)
    time.sleep(3)

    def finish() -> list[str]:
        try:
            _, err = bg.communicate(timeout=TIMEOUT)
        except subprocess.TimeoutExpired:
            os.killpg(bg.pid, signal.SIGKILL)
            return ["the first run timed out"]
        return [] if bg.returncode == 0 else [f"the first run exited {bg.returncode}: {tail(err.decode(), 1)}"]
    c.checks.append(finish)
    return ["run", cap / "images", "--no-evaluate", "--budget", "8", "--out", run]


RUNDIRS = [
    ("out-is-a-file", _refused_out(lambda c, cap: (c.dir / "user.txt").write_text("mine\n") and c.dir / "user.txt"), E),
    ("out-is-the-photo-folder", _refused_out(lambda c, cap: cap / "images"), E),
    ("out-inside-photo-folder", _refused_out(lambda c, cap: cap / "images" / "run"), E),
    ("out-is-the-pose-folder", _refused_out(lambda c, cap: cap), E),
    ("out-symlink-to-photos", _refused_out(lambda c, cap: os.symlink(cap / "images", c.dir / "ln") or c.dir / "ln"), E),
    ("out-user-folder", _refused_out(lambda c, cap: _user_folder(c)), E),
    ("out-user-folder-adopt", lambda c: c.fast(c.cap(), (c.runs.append(_user_folder(c)), c.runs[-1])[1], "--adopt"), O),
    ("out-hostile-name", _hostile_out, O),
    ("suggest-hostile-names", _hostile_suggest, O),
    *[(f"{cmd}-on-{w}-folder", _stage_on(w, cmd), E) for w in ("empty", "user")
      for cmd in ("select", "export", "evaluate", "suggest", "report")],
    ("report-on-missing-folder", _stage_on("missing", "report"), E),
    ("export-after-select-stagejson-garbage", _corrupt("select/stage.json", "garbage", "export"), A),
    ("report-after-select-stagejson-garbage", _corrupt("select/stage.json", "garbage", "report"), A),
    ("select-after-sfm-cameras-truncated", _corrupt("sfm/cameras.json", "truncate", "select"), A),
    ("suggest-after-sfm-cameras-truncated", _corrupt("sfm/cameras.json", "truncate", "suggest"), A),
    ("select-after-occupancy-garbage", _corrupt("occupancy/occupancy.npz", "garbage", "select"), A),
    ("suggest-after-occupancy-truncated", _corrupt("occupancy/occupancy.npz", "truncate", "suggest"), A),
    ("select-after-sfm-stagejson-empty", _corrupt("sfm/stage.json", "empty", "select"), A),
    ("report-after-marker-garbage", _corrupt(".curate-run.json", "garbage", "report"), A),
    ("export-after-selection-truncated", _corrupt("select/selection.json", "truncate", "export", ["--force"]), A),
    ("export-copy-photos-deleted", _photos_deleted("export", ["--mode", "copy"]), E),
    ("report-photos-deleted", _photos_deleted("report", ["--force"]), A),
    ("rerun-photos-deleted", _photos_deleted("run"), E),
    ("export-copy-keeps-edited-file", _edited_export([]), A),
    ("export-copy-force-keeps-edited-file", _edited_export(["--force"]), A),
    ("export-distorted-undistort-off", _distorted_export(["--undistort", "off", "--downscale", "2"]), O),
    ("export-distorted-keep-distorted", _distorted_export(["--keep-distorted", "--downscale", "2,4"]), O),
    ("export-distorted-link-mode", _distorted_export(["--mode", "link", "--keep-distorted"]), O),
    ("second-capture-same-out", _second_capture(False), E),
    ("second-capture-same-out-force", _second_capture(True), A),
    ("rerun-unchanged", _rerun_same, O),
    ("concurrent-run-same-out", _concurrent, E),
]


# ------------------------------------------------------------------ videos
def _video(make, extra=(), poses=False):
    def build(c: Ctx):
        src = make(c)
        argv = ["run", src, "--no-evaluate", "--budget", "4", "--out", c.out(), *extra]
        if poses:
            argv += ["--poses", c.cap(name="posecap") / "transforms.json", "--triangulate", "off"]
        return argv
    return build


def _vfile(name, data=None, src=None):
    def make(c: Ctx):
        p = c.dir / "in" / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data if data is not None else Path(src(c)).read_bytes())
        return p
    return make


def _mixed(c: Ctx):
    cap = c.cap(n=10)
    shutil.copy(c.base / "walk30.mp4", cap / "images" / "walk.mp4")
    return cap / "images"


def _only_zero_mp4(c: Ctx):
    (c.dir / "vids").mkdir()
    (c.dir / "vids" / "clip.mp4").write_bytes(b"")
    return c.dir / "vids"


VIDEOS = [
    ("video-zero-byte", _video(_vfile("clip.mp4", b"")), E),
    ("video-truncated-office",
     _video(_vfile("office.mp4", OFFICE_MP4.read_bytes()[:20_000] if OFFICE_MP4.exists() else b"")), A),
    ("video-text-as-mp4", _video(_vfile("clip.mp4", b"this is not a video\n" * 10)), E),
    ("video-folder-only-zero-mp4", _video(_only_zero_mp4), E),
    ("video-short-valid", _video(_vfile("walk.mp4", src=lambda c: c.base / "walk30.mp4")), O),
    ("video-upper-ext", _video(_vfile("WALK.MP4", src=lambda c: c.base / "walk30.mp4")), A),
    ("video-one-frame", _video(_vfile("one.mp4", src=lambda c: c.base / "one.mp4")), A),
    ("video-max-frames-1", _video(_vfile("walk.mp4", src=lambda c: c.base / "walk30.mp4"), ["--max-frames", "1"]), E),
    ("video-max-frames-0", _video(_vfile("walk.mp4", src=lambda c: c.base / "walk30.mp4"), ["--max-frames", "0"]), E),
    ("video-max-frames-neg",
     _video(_vfile("walk.mp4", src=lambda c: c.base / "walk30.mp4"), ["--max-frames", "-5"]), E),
    ("video-and-photos-mixed", _video(_mixed), A),
    ("video-with-foreign-poses", _video(_vfile("walk.mp4", src=lambda c: c.base / "walk30.mp4"), poses=True), A),
    ("video-hostile-name", _video(_vfile(XSS[1] + ".mp4", src=lambda c: c.base / "walk30.mp4")), A),
]


# ------------------------------------------------------------------ signals
def _signal(signum, delay, poses=True):
    """Interrupt a fast pose import with triangulation (60 frames; single-threaded, so its export is the same
    bytes on every run), or a COLMAP SfM run (40 frames; multi-threaded COLMAP is not bit-reproducible
    between clean runs, so only the exported file names are compared)."""
    def build(c: Ctx):
        cap = c.cap(n=60 if poses else 40)
        c.signal, c.exact = (signum, delay), poses
        run, _ = c.out(), c.out("ref")
        if poses:
            return ["run", cap / "images", "--poses", cap / "transforms.json", "--no-evaluate", "--budget", "8",
                    "--out", run]
        (cap / "transforms.json").unlink()
        return ["run", cap / "images", "--no-evaluate", "--budget", "8", "--out", run]
    return build


SIGNALS = [(f"poses-{signal.Signals(s).name.lower()}-at-{t}s", _signal(s, t), E)
           for s in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP) for t in (1, 3, 6)] + [
    (f"sfm-{signal.Signals(s).name.lower()}-at-{t}s", _signal(s, t, poses=False), E)
    for s, t in ((signal.SIGTERM, 3), (signal.SIGINT, 6), (signal.SIGHUP, 4))]


# ------------------------------------------------------------------ all cases
def all_cases() -> list[Case]:
    cs = [Case(f"run-{n}", "flags", e, flag_run_case(f)) for n, f, e in FLAG_RUN]
    cs += [Case(n, "flags", e, flag_stage_case(cmd, f)) for n, cmd, f, e in FLAG_STAGE]
    cs += [Case(n, "photos", e, b) for n, b, e in PHOTOS]
    cs += [Case(n, "poses", e, pose_text_case(m)) for n, m, e in POSE_TEXT]
    cs += [Case(n, "poses", e, pose_dict_case(m)) for n, m, e in POSE_DICT]
    cs += [Case(f"pose-path-{k}", "poses", A, _outside_paths(k)) for k in ("traversal", "absolute", "directory",
                                                                           "deep-traversal")]
    cs += [Case("pose-file-missing", "poses", E, _pose_path("missing")),
           Case("pose-folder-without-poses", "poses", E, _pose_path("folder-without")),
           Case("pose-file-utf16", "poses", A, _pose_path("utf16"))]
    cs += [Case(n, "poses", e, _colmap(m)) for n, m, e in COLMAP]
    cs += [Case(n, "rundirs", e, b) for n, b, e in RUNDIRS]
    cs += [Case(n, "videos", e, b) for n, b, e in VIDEOS]
    cs += [Case(n, "signals", e, b) for n, b, e in SIGNALS]
    names = [c.name for c in cs]
    assert len(names) == len(set(names)), "duplicate case names"
    return cs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/adv"))
    ap.add_argument("--only", default=None, help="run the cases whose name contains SUBSTRING")
    ap.add_argument("--jobs", type=int, default=2, choices=(1, 2))
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument("--src", type=Path, default=None,
                    help="run the curate package in SRC/curate (e.g. a frozen copy of a tree being edited)")
    args = ap.parse_args(argv)
    if args.src:
        SRC.append(str(args.src.resolve()))
    cases = [c for c in all_cases() if not args.only or args.only in c.name]
    if args.list:
        for c in cases:
            print(c.family, c.expect, c.name)
        return 0
    _unignore_signals()
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    build_base(out / "base")
    path = out / "results.jsonl"
    kept = {}
    if args.only and path.exists():     # a partial rerun replaces its cases' lines, keeps the others
        for ln in path.read_text().splitlines():
            r = json.loads(ln)
            kept[r["case"]] = r
    results = []
    with cf.ThreadPoolExecutor(args.jobs) as pool:
        futs = {pool.submit(run_case, c, out): c for c in cases}
        for fut in cf.as_completed(futs):
            c = futs[fut]
            try:
                r = fut.result()
            except Exception as e:        # noqa: BLE001 - a harness bug in one case must not stop the sweep
                r = {"case": c.name, "family": c.family, "expect": c.expect, "rc": None, "ok": False,
                     "violations": [f"harness error: {type(e).__name__}: {e}"], "stderr_tail": ""}
            results.append(r)
            kept[r["case"]] = r
            print(("PASS " if r["ok"] else "FAIL ") + r["case"] + ("" if r["ok"] else f"  {r['violations']}"),
                  file=sys.stderr, flush=True)
    order = {c.name: i for i, c in enumerate(all_cases())}
    path.write_text("".join(json.dumps(r) + "\n"
                            for r in sorted(kept.values(), key=lambda r: order.get(r["case"], 1e9))))
    fam: dict[str, dict] = {}
    for r in results:
        f = fam.setdefault(r["family"], {"cases": 0, "passed": 0, "failed": 0})
        f["cases"] += 1
        f["passed" if r["ok"] else "failed"] += 1
    print(json.dumps({"cases": len(results), "passed": sum(r["ok"] for r in results),
                      "failed": sum(not r["ok"] for r in results), "families": fam,
                      "failed_cases": sorted(r["case"] for r in results if not r["ok"]),
                      "wall_s": round(time.time() - t0), "curate": SRC[0] if SRC else str(ROOT)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
