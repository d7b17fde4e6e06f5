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
5. the case's expectation: ``error`` (exit != 0), ``ok`` (exit 0) or ``any`` (only the invariants);
6. nothing of the command's session is left once it exited (a worker, multiprocessing's resource tracker, a
   process not yet reaped), plus the case's own checks (a deleted output written again, the user's file kept,
   no file from outside the capture exported, the error of a full disk naming a file of the run folder).

Issue 61's cases (families uptodate, userfiles, workers, cameras, colmapfiles, names, unreadable, disk) run a
mode-000 case as a user would (as root: ``capsh`` drops the power to read any file) and a full disk on a tmpfs of
its own (root only; elsewhere that case is a setup failure). A failed case is counted by kind
(:func:`kind_of`: security, data loss, silent wrong, hang, unclear); the summary gives the clean share.

Signal cases interrupt a pose import with triangulation (or a short COLMAP SfM run) with SIGTERM / SIGHUP (to
the PID) or SIGINT (to the process group, as Ctrl-C does) after 1, 3 or 6 s and expect: exit != 0, exactly one
``curate run:`` line, no traceback, the run lock released (flock-able, emptied) and no process left; the same
command again exits 0 and its export (every file but export.json, stage.json, .curate-stage; symlink targets)
is identical to an uninterrupted run's in another folder (for SfM: the same file names only, as multi-threaded
COLMAP gives other bytes on every clean run).

Run from the project root (at most 2 cases at a time; results in OUT/results.jsonl, summary last on stdout)::

    .venv/bin/python -m research.adversarial --out /tmp/adv
    .venv/bin/python -m research.adversarial --out /tmp/adv --only pose-   # rerun the cases whose name has it
    .venv/bin/python -m research.adversarial --out /tmp/adv --families disk,workers --src /tmp/frozen  # a copy
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
        self.cwd: Path | None = None              # where the command runs (default: the sandbox)
        self.unprivileged = False                 # run it as a user would: mode 000 means unreadable (unpriv_prefix)
        self.after: list[Callable[[], None]] = []  # clean-up once the case is checked (unmount a full disk)
        self.sig: tuple | None = None             # (signum, delay): stop the command so (no export compared)
        self.last: dict = {}                      # the command's result, for the checks
        self.full_disk = False                    # its error must say the disk is full

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


def unpriv_prefix() -> list[str]:
    """A prefix that runs a command as a user would as far as file modes go: as root (this project's machines),
    root's power to read and search any file dropped (``capsh``), so that ``chmod 000`` means unreadable; [] as a
    user. SetupError where root cannot drop it."""
    if os.geteuid() != 0:
        return []
    if not shutil.which("capsh"):
        raise SetupError("running as root without capsh: a mode-000 file cannot be made unreadable")
    return ["capsh", "--drop=cap_dac_override,cap_dac_read_search", "--", "-c", 'exec "$0" "$@"']


def session_left(sid: int) -> list[str]:
    """The processes of session ``sid`` still in the process table (a zombie counts: nothing reaped it)."""
    out = []
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            try:
                if os.getsid(int(pid)) == sid:
                    out.append(Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:80]
                               or f"{pid} (exited, not reaped)")
            except OSError:
                continue
    return out


def exec_curate(argv, cwd: Path, tmp: Path, timeout: float = TIMEOUT, sig: tuple | None = None,
                prefix: list[str] = ()) -> dict:
    """Run ``python -m curate ARGV``; sig=(signum, delay): send it after delay s. Returns rc, stdout, stderr and
    ``left``: the processes of its session still there once it exited (each then killed: this call started them)."""
    cmd = [*prefix, "nice", "-n", "10", PY, "-m", "curate", *map(str, argv)]
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
               seconds=round(time.time() - t0, 1), left=session_left(p.pid))
    if res["left"]:
        try:
            os.killpg(p.pid, signal.SIGKILL)      # the session this call started
        except ProcessLookupError:
            pass
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


def unmount_under(d: Path) -> None:
    """Unmount what a case mounted under ``d`` (its full disk), deepest first."""
    try:
        mounts = [ln.split()[1] for ln in Path("/proc/mounts").read_text().splitlines()]
    except OSError:
        return
    for m in sorted((m for m in mounts if m == str(d) or m.startswith(str(d) + "/")), key=len, reverse=True):
        subprocess.run(["umount", "-l", m], check=False, capture_output=True)


def run_case(case: Case, out: Path) -> dict:
    """:func:`_run_case`, then the case's clean-up (``Ctx.after``) whatever happened."""
    unmount_under(out / "cases" / case.name)
    holder: list[Ctx] = []
    try:
        return _run_case(case, out, holder)
    finally:
        for undo in (holder[0].after if holder else []):
            try:
                undo()
            except Exception:  # noqa: BLE001 - a clean-up that fails leaves the rest to do
                pass


def _run_case(case: Case, out: Path, holder: list) -> dict:
    cdir, tmp = out / "cases" / case.name, out / "tmp" / case.name
    for d in (cdir, tmp):
        if d.exists():
            for sub in d.rglob("*"):                     # a case may chmod its files; make them removable
                if sub.is_dir() and not sub.is_symlink():
                    os.chmod(sub, 0o755)
            shutil.rmtree(d)
        d.mkdir(parents=True)
    ctx = Ctx(out / "base", cdir, tmp)
    holder.append(ctx)
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
        r = exec_curate(argv, ctx.cwd or cdir, tmp, prefix=unpriv_prefix() if ctx.unprivileged else [], sig=ctx.sig)
        v = scan_output(r)
        if ctx.sig and not r["signalled"]:
            v.append(f"finished (exit {r['rc']}) before the signal at {ctx.sig[1]}s: lengthen the command")
        if ctx.full_disk and r["rc"] != 0 and not any("the disk is full" in ln and ": error:" in ln and
                                                      any(str(d) in ln for d in ctx.runs) for ln in lines(r["stderr"])):
            v.append(f"unclear: the error does not say the disk is full, naming a file of the run folder: "
                     f"{tail(r['stderr'], 1)}")
        errs = sum(": error:" in ln for ln in lines(r["stderr"]))
        stopped = sum(ln.startswith("curate ") and ln.rstrip().endswith(("interrupted", "terminated",
                                                                          "terminated (hang-up)"))
                      for ln in lines(r["stderr"]))
        if ctx.sig and r["signalled"] and stopped != 1:
            v.append(f"{stopped} 'curate ...: interrupted/terminated' lines after the signal (expected 1)")
        if r["rc"] not in (0, None) and errs != 1 and not r["timed_out"] and not ctx.sig:
            v.append(f"failed (exit {r['rc']}) with {errs} ': error:' lines (expected 1)")
        if case.expect == E and r["rc"] == 0:
            v.append("expected an error, exited 0")
        if case.expect == O and r["rc"] != 0:
            v.append(f"expected success, exited {r['rc']}")
    if r.get("left"):
        v.append(f"processes left after it exited: {r['left'][:3]}")
    ctx.last = r
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


# ------------------------------------------------------------------ issue 61: hostile inputs and edits, round three
def _quick(c: Ctx, triangulate: bool = False, cap: Path | None = None, name: str = "run") -> tuple[Path, Path]:
    """(capture, finished run folder): a fast pose import (points triangulated when asked)."""
    cap = cap or c.cap()
    return cap, c.finished(cap, name, triangulate=triangulate)


def _evaluated(c: Ctx) -> tuple[Path, Path]:
    cap, run = _quick(c)
    c.curate("evaluate", run, *EVAL_FAST)
    return cap, run


def _restored(path_of, what: str):
    """A check: the output the user deleted is there again after the command."""
    def chk(p: Path) -> list[str]:
        return [] if p.exists() else [f"silent wrong: {what} ({p.name}) is still missing after the command"]
    return lambda: chk(path_of())


def _same_bytes(p: Path, what: str, kind: str = "data loss"):
    want = p.read_bytes()

    def chk() -> list[str]:
        try:
            return [] if p.read_bytes() == want else [f"{kind}: {what} was changed"]
        except FileNotFoundError:
            return [f"{kind}: {what} was removed"]
    return chk


def _deleted(where: str, rel: str, argv_of, triangulate: bool = False, evaluated: bool = False):
    """A finished run folder whose RUN/<where>/<rel> (a glob: its first match) the user deleted; then
    ``argv_of(c, cap, run)``: the file must be there again."""
    def build(c: Ctx):
        cap, run = _evaluated(c) if evaluated else _quick(c, triangulate)
        victim = sorted((run / where).glob(rel))[0]
        if victim.is_dir():
            shutil.rmtree(victim)
        else:
            victim.unlink()
        c.checks.append(_restored(lambda: victim, f"the deleted {where}/{rel}"))
        return argv_of(c, cap, run)
    return build


def _input_deleted(c: Ctx):
    """The selection the export reads was deleted: `curate export RUN --mode copy` must name it and what writes it."""
    _, run = _quick(c)
    p = run / "select" / "selection.json"
    p.unlink()
    c.checks.append(lambda: [] if f"{p} is missing" in c.last.get("stderr", "") and "curate select" in
                    c.last.get("stderr", "") else ["unclear: the error does not name the missing selection.json"])
    return ["export", run, "--mode", "copy"]


def _export_cmd(*extra):
    return lambda c, cap, run: ["export", run, *extra]


def _rerun(c: Ctx, cap: Path, run: Path) -> list:
    return c.fast(cap, run)


def _edited_same(rel: str):
    """The user edits RUN/export/<rel>; `curate export RUN` with the same options keeps the edit and names it."""
    def build(c: Ctx):
        _, run = _quick(c)
        p = sorted((run / "export").glob(rel))[0]
        if p.is_symlink() or p.stat().st_nlink > 1:
            p.unlink()
            p.write_bytes(jpeg_bytes(7))
        else:
            p.write_text(p.read_text().replace("{", "{ ", 1))
        c.checks.append(_same_bytes(p, f"the user's edited export/{p.relative_to(run / 'export')}"))
        return ["export", run]
    return build


def _users_file(where: str, argv_of, name: str = "notes.txt", evaluated: bool = False):
    """The user's own file in a finished stage folder; then a re-run of that stage: it must survive."""
    def build(c: Ctx):
        cap, run = _evaluated(c) if evaluated else _quick(c)
        p = run / where / name
        p.write_text("the user's own notes\n")
        c.checks.append(_same_bytes(p, f"the user's {where}/{name}"))
        return argv_of(c, cap, run)
    return build


def _after_kill(stages: tuple[str, ...], name: str):
    """What a SIGKILL half-way through ``stages`` leaves (their folders with curate's files, no record), and a file
    the user put there afterwards; then the same `curate run`: it resumes, the user's file stays."""
    def build(c: Ctx):
        cap, run = _quick(c)
        for s in stages:
            (run / s / "stage.json").unlink()
            if s == "export":
                (run / s / "export.json").unlink()
                (run / s / "transforms.json").write_text("{half")
        p = run / stages[-1] / name
        p.write_text("mine\n")
        c.checks.append(_same_bytes(p, f"the user's {stages[-1]}/{name}"))
        c.checks.append(lambda: [] if json.loads((run / "export" / "transforms.json").read_text()).get("frames")
                        else ["silent wrong: the resumed export's transforms.json has no frames"])
        return c.fast(cap, run)
    return build


def _export_json_edited(*extra):
    def build(c: Ctx):
        _, run = _quick(c)
        p = run / "export" / "export.json"
        p.write_text(p.read_text().replace("{", "{\n ", 1))
        c.checks.append(_same_bytes(p, "the user's edit of export/export.json"))
        return ["export", run, *extra]
    return build


def _unreadable_edit(c: Ctx):
    """The user edits the export's transforms.json, then makes it unreadable (chmod 000); a re-export in copy mode
    must not replace it (curate cannot prove it is its own)."""
    unpriv_prefix()
    _, run = _quick(c)
    p = run / "export" / "transforms.json"
    p.write_text(p.read_text().replace("{", "{ ", 1))
    want = p.read_bytes()
    os.chmod(p, 0)
    c.unprivileged = True
    c.checks.append(lambda: [] if p.exists() and (os.chmod(p, 0o644) or p.read_bytes() == want)
                    else ["data loss: the user's unreadable edited transforms.json was replaced"])
    return ["export", run, "--mode", "copy"]


def _unreadable_folder(rel: str, cmd_of):
    def build(c: Ctx):
        unpriv_prefix()
        cap, run = _quick(c)
        d = (run / rel) if not rel.startswith("@") else None
        if d is None:                                   # --poses MODEL whose sparse/0 the user cannot read
            model = c.dir / "scene"
            (model / "sparse").mkdir(parents=True)
            shutil.copytree(c.base / "colmap", model / "sparse" / "0")
            shutil.copytree(cap / "images", model / "images")
            d = model / "sparse" / "0"
            argv = ["run", "--poses", model, *FAST, "--out", c.out("run2")]
        else:
            argv = cmd_of(run)
        os.chmod(d, 0)
        c.unprivileged = True
        c.after.append(lambda: os.chmod(d, 0o755))
        return argv
    return build


def _eval_cmd(*extra):
    return lambda c, cap, run: ["evaluate", run, *EVAL_FAST[:-2], "--workers", "2", *extra]


def _evaluate_after(setup):
    """An evaluation with two workers after ``setup(c, run)``; the generic check: nothing of it left running."""
    def build(c: Ctx):
        _, run = _quick(c)
        setup(c, run)
        return ["evaluate", run, *EVAL_FAST[:-2], "--workers", "2"]
    return build


def _interrupted(sig):
    def setup(c: Ctx, run: Path) -> None:
        r = exec_curate(["evaluate", run, "--iters", "400", "--folds", "2", "--eval-size", "32", "--workers", "2"],
                        c.dir, c.tmp, sig=(sig, 6))
        left = r.get("left") or []
        c.checks.append(lambda: [f"processes of the interrupted evaluation left: {left[:3]}"] if left else [])
        if r["rc"] == 0:
            raise SetupError("the evaluation to interrupt finished before the signal")
    return setup


def _signalled_evaluation(sig, delay=6.0, run_whole=False):
    """The evaluation (or a whole evaluated `curate run`) stopped by ``sig``: exit != 0 and nothing left running."""
    def build(c: Ctx):
        cap, run = _quick(c)
        c.sig = (sig, delay)
        if run_whole:
            return ["run", cap / "images", "--poses", cap / "transforms.json", "--triangulate", "off", "--budget", "4",
                    "--iters", "400", "--folds", "2", "--eval-size", "32", "--workers", "2", "--out", c.out("run2")]
        return ["evaluate", run, "--iters", "400", "--folds", "2", "--eval-size", "32", "--workers", "2"]
    return build


def _angle(a):
    def m(d):
        d.pop("fl_x", None)
        d.pop("fl_y", None)
        d.pop("camera_angle_y", None)
        d["camera_angle_x"] = a
        return d
    return m


def _centre_of(k, x):
    def m(d):
        d["frames"][k]["transform_matrix"][0][3] = x
        return d
    return m


def _camjson(mutate):
    """A cameras.json of the capture (a finished import's sfm/cameras.json beside the photos) with one value no
    camera has."""
    def build(c: Ctx):
        cap, run = _quick(c, name="src")
        d = json.loads((run / "sfm" / "cameras.json").read_text())
        mutate(d["cameras"][3])
        (cap / "cameras.json").write_text(json.dumps(d))
        return ["run", cap / "images", "--poses", cap / "cameras.json", *FAST, "--out", c.out()]
    return build


def _binary_model(mutate):
    """The capture's COLMAP model written in binary (with points) and broken by ``mutate(model)``."""
    def build(c: Ctx):
        cap = c.cap()
        model = c.dir / "model"
        model.mkdir()
        import pycolmap
        pycolmap.Reconstruction(str(c.base / "colmap")).write(str(model))
        mutate(model)
        return ["run", cap / "images", "--poses", model, *FAST, "--out", c.out()]
    return build


def _cut(name, keep):
    def m(model: Path):
        data = (model / name).read_bytes()
        (model / name).write_bytes(data[:keep(len(data))])
    return m


def _latin1(c: Ctx, cap: Path):
    os.link(cap / "images" / "frame_0003.jpg", os.path.join(os.fsencode(cap / "images"), b"caf\xe9.jpg"))

    def chk() -> list[str]:
        run = c.runs[0]
        try:
            recs = json.loads((run / "sfm" / "images.json").read_text())["photos"]
        except (OSError, ValueError):
            return []
        return [] if any(r["rel"] == "caf\\xe9.jpg" and r["status"] == "skipped" for r in recs) \
            else ["silent wrong: the photo named in Latin-1 is not listed as skipped"]
    c.checks.append(chk)


def _full_disk(argv_of, fresh_run: bool = False, triangulate: bool = False, room: int = 16384):
    """The run folder on a small file system (tmpfs; root only) filled before the command but for ``room`` bytes
    (the lock and the small records fit; the stage's outputs do not): one line saying the disk is full and naming
    the file; once space is freed the same command succeeds."""
    def build(c: Ctx):
        if os.geteuid() != 0 or not shutil.which("mount"):
            raise SetupError("a full disk needs root (a tmpfs of its own)")
        disk = c.dir / "disk"
        disk.mkdir()
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=48m", "tmpfs", str(disk)], capture_output=True)
        if r.returncode != 0:
            raise SetupError(f"cannot mount a tmpfs: {r.stderr.decode()[-200:]}")
        c.after.append(lambda: subprocess.run(["umount", "-l", str(disk)], check=False, capture_output=True))
        cap = c.cap()
        run = disk / "run"
        if not fresh_run:
            c.runs.append(run)
            argv = c.fast(cap, run)
            if triangulate:
                argv[argv.index("off")] = "auto"
            c.curate(*argv)
        else:
            c.runs.append(run)
        filler = disk / "filler"
        c.runs.append(filler)                # freed by the check below: not compared as the user's
        with open(filler, "wb") as f:
            try:
                while True:
                    f.write(b"\0" * (1 << 16))
                    f.flush()
            except OSError:
                pass
        os.truncate(filler, max(filler.stat().st_size - room, 0))
        argv = argv_of(c, cap, run)

        def then() -> list[str]:
            filler.unlink()
            again = exec_curate(argv, c.dir, c.tmp)
            return [] if again["rc"] == 0 else [f"once space was freed the same command exited {again['rc']}: "
                                                f"{tail(again['stderr'], 1)}"]
        c.checks.append(then)
        c.full_disk = True
        return argv
    return build


ISSUE61 = [  # (name, family, expect, build)
    # a pose file that reaches outside the capture (item 1): run from the photo folder, without a photo folder
    ("pose-colmap-etc-passwd-from-photo-folder", "poses", E, None),
    # up to date means the files are there (item 2)
    ("export-deleted-image", "uptodate", O, _deleted("export", "images/*", _export_cmd())),
    ("export-deleted-transforms", "uptodate", O, _deleted("export", "transforms.json", _export_cmd())),
    ("export-deleted-model-images-bin", "uptodate", O, _deleted("export", "sparse/0/images.bin", _export_cmd())),
    ("export-deleted-ply", "uptodate", O, _deleted("export", "sparse_pc.ply", _export_cmd(), triangulate=True)),
    ("export-deleted-images-folder", "uptodate", O, _deleted("export", "images", _export_cmd())),
    ("export-deleted-images-txt-rerun", "uptodate", O, _deleted("export", "images.txt", _rerun)),
    ("export-deleted-image-copy-mode", "uptodate", O, _deleted("export", "images/*", _export_cmd("--mode", "copy"))),
    ("select-deleted-selection", "uptodate", O, _deleted("select", "selection.json",
                                                         lambda c, cap, run: ["select", run])),
    ("select-deleted-nodes-rerun", "uptodate", O, _deleted("select", "nodes.npz", _rerun)),
    ("occupancy-deleted-grid-rerun", "uptodate", O, _deleted("occupancy", "occupancy.npz", _rerun)),
    ("sfm-deleted-cameras-rerun", "uptodate", O, _deleted("sfm", "cameras.json", _rerun)),
    ("sfm-deleted-model-rerun", "uptodate", O, _deleted("sfm", "sparse/0", _rerun)),
    ("sfm-deleted-points-rerun", "uptodate", O, _deleted("sfm", "points.npy", _rerun)),
    ("evaluate-deleted-metrics", "uptodate", O, _deleted("evaluate", "f00_selection/metrics.json",
                                                         lambda c, cap, run: ["evaluate", run, *EVAL_FAST],
                                                         evaluated=True)),
    ("evaluate-deleted-summary", "uptodate", O, _deleted("evaluate", "summary.json",
                                                         lambda c, cap, run: ["evaluate", run, *EVAL_FAST],
                                                         evaluated=True)),
    ("select-deleted-selection-then-export", "uptodate", E, _input_deleted),
    ("export-edited-image-same-options", "uptodate", O, _edited_same("images/*")),
    ("export-edited-transforms-same-options", "uptodate", O, _edited_same("transforms.json")),
    # the user's files in a stage folder (item 3)
    ("export-notes-force", "userfiles", O, _users_file("export", _export_cmd("--force"))),
    ("export-notes-mode-change", "userfiles", O, _users_file("export", _export_cmd("--mode", "copy"))),
    ("export-readme-downscale", "userfiles", O, _users_file("export", _export_cmd("--downscale", "2"),
                                                            "README-mine.txt")),
    ("select-notes-rebudget", "userfiles", O,
     _users_file("select", lambda c, cap, run: ["select", run, "--budget", "5"], "my-selection-notes.txt")),
    ("occupancy-notes-force", "userfiles", O, _users_file("occupancy", lambda c, cap, run: ["occupancy", run,
                                                                                            "--force"])),
    ("sfm-notes-run-force", "userfiles", O, _users_file("sfm", lambda c, cap, run: [*c.fast(cap, run), "--force"])),
    ("evaluate-notes-force", "userfiles", O, _users_file("evaluate", lambda c, cap, run: ["evaluate", run, *EVAL_FAST,
                                                                                          "--force"], evaluated=True)),
    ("export-readme-after-kill", "userfiles", O, _after_kill(("select", "export"), "README-mine.txt")),
    ("select-notes-after-kill", "userfiles", O, _after_kill(("select",), "my-selection-notes.txt")),
    ("export-json-edited-mode-change", "userfiles", E, _export_json_edited("--mode", "copy")),
    ("export-json-edited-same-options", "userfiles", O, _export_json_edited()),
    ("export-transforms-edited-unreadable", "userfiles", E, _unreadable_edit),
    # no worker outlives the command (item 4): every case checks that nothing of its session is left
    ("evaluate-folds-1-two-workers", "workers", O, lambda c: ["evaluate", _quick(c)[1], *EVAL_FAST[:-2],
                                                               "--workers", "2"]),
    ("evaluate-tiny-minutes-two-workers", "workers", O,
     lambda c: ["evaluate", _quick(c)[1], "--iters", "20", "--eval-size", "32", "--workers", "2", "--eval-minutes",
                "0.01"]),
    ("evaluate-after-select-redone", "workers", O, _evaluate_after(lambda c, run: c.curate("select", run, "--budget",
                                                                                          "5"))),
    ("evaluate-resumed-after-sigint", "workers", O, _evaluate_after(_interrupted(signal.SIGINT))),
    ("evaluate-resumed-after-sighup", "workers", O, _evaluate_after(_interrupted(signal.SIGHUP))),
    ("evaluate-sigterm", "workers", E, _signalled_evaluation(signal.SIGTERM)),
    ("evaluate-sigint", "workers", E, _signalled_evaluation(signal.SIGINT)),
    ("evaluate-sighup", "workers", E, _signalled_evaluation(signal.SIGHUP)),
    ("run-sighup-during-evaluation", "workers", E, _signalled_evaluation(signal.SIGHUP, 12, run_whole=True)),
    # poses checked as cameras (item 5)
    ("pose-camera-angle-pi", "cameras", E, pose_dict_case(_angle(3.141592653589793))),
    ("pose-camera-angle-zero", "cameras", E, pose_dict_case(_angle(0.0))),
    ("pose-flx-tiny", "cameras", E, pose_dict_case(_set(fl_x=1e-3, fl_y=1e-3))),
    ("pose-k1-1e10", "cameras", E, pose_dict_case(_set(k1=1e10, camera_model="OPENCV"))),
    ("pose-k1-nan", "cameras", E, pose_dict_case(_set(k1=float("nan"), camera_model="OPENCV"))),
    ("pose-k1-folding", "cameras", E, pose_dict_case(_set(k1=-3.0, camera_model="OPENCV"))),
    ("pose-p1-huge", "cameras", E, pose_dict_case(_set(p1=5.0, camera_model="OPENCV"))),
    ("pose-centre-1e300-one", "cameras", E, pose_dict_case(_centre_of(4, 1e300))),
    ("pose-centre-far-one", "cameras", E, pose_dict_case(_centre_of(4, 1e9))),
    ("pose-c2w-nan-one", "cameras", E, pose_dict_case(_first(lambda f: _mat(f, lambda m: [[float("nan")] + r[1:]
                                                                                         for r in m[:3]] + [m[3]])))),
    ("camjson-fx-zero", "cameras", E, _camjson(lambda cam: cam.update(fx=0.0))),
    ("camjson-c2w-nan", "cameras", E, _camjson(lambda cam: cam["c2w"][0].__setitem__(0, float("nan")))),
    ("camjson-width-negative", "cameras", E, _camjson(lambda cam: cam.update(width=-320))),
    ("camjson-k1-1e10", "cameras", E, _camjson(lambda cam: cam.update(dist=[1e10, 0, 0, 0]))),
    ("colmap-fx-zero", "cameras", E, _colmap(_edit_line("cameras.txt", lambda w: w[:4] + ["0"] + w[5:]))),
    ("colmap-centre-1e300", "cameras", E, _colmap(_edit_line("images.txt", lambda w: w[:5] + ["1e300"] + w[6:]))),
    ("colmap-radial-1e10", "cameras", E, _colmap(_edit_line("cameras.txt", lambda w: w[:1] + ["SIMPLE_RADIAL"] + w[2:5]
                                                            + w[6:8] + ["1e10"]))),
    # COLMAP's reader (item 6)
    ("colmap-bin-ok", "colmapfiles", O, _binary_model(lambda m: None)),
    ("colmap-bin-empty-points3d", "colmapfiles", E, _binary_model(lambda m: (m / "points3D.bin").write_bytes(b""))),
    ("colmap-bin-truncated-images", "colmapfiles", E, _binary_model(_cut("images.bin", lambda n: n // 2))),
    ("colmap-bin-truncated-cameras", "colmapfiles", E, _binary_model(_cut("cameras.bin", lambda n: 10))),
    ("colmap-bin-truncated-points3d", "colmapfiles", E, _binary_model(_cut("points3D.bin", lambda n: n // 3))),
    ("colmap-bin-trailing-bytes", "colmapfiles", E,
     _binary_model(lambda m: (m / "images.bin").write_bytes((m / "images.bin").read_bytes() + b"\0" * 7))),
    ("colmap-bin-huge-count", "colmapfiles", E,
     _binary_model(lambda m: (m / "points3D.bin").write_bytes(b"\xff" * 8 + (m / "points3D.bin").read_bytes()[8:]))),
    ("colmap-text-nan-translation", "colmapfiles", E,
     _colmap(_edit_line("images.txt", lambda w: w[:5] + ["nan"] + w[6:]))),
    ("colmap-text-duplicate-names", "colmapfiles", E, _colmap(lambda m: _dup_name(m))),
    # file names that are not UTF-8 (item 6)
    ("photos-latin1-name-import", "names", O, _pose_run(_latin1)),
    ("photos-latin1-name-sfm", "names", O, _sfm_run(lambda c, cap: _latin1(c, cap))),
    # unreadable folders (item 6)
    ("export-folder-unreadable", "unreadable", E, _unreadable_folder("export", lambda run: ["export", run, "--mode",
                                                                                          "copy"])),
    ("export-sparse0-unreadable", "unreadable", E, _unreadable_folder("export/sparse/0", lambda run: [
        "export", run, "--mode", "copy"])),
    ("select-folder-unreadable", "unreadable", E, _unreadable_folder("select", lambda run: ["select", run, "--budget",
                                                                                          "5"])),
    ("poses-model-sparse0-unreadable", "unreadable", E, _unreadable_folder("@model", None)),
    # a full disk in any stage (item 6)
    ("disk-full-export-copy", "disk", E, _full_disk(lambda c, cap, run: ["export", run, "--mode", "copy", "--force"])),
    ("disk-full-to-the-last-byte", "disk", E, _full_disk(lambda c, cap, run: ["select", run, "--budget", "5"], room=0)),
    ("disk-full-export-downscale", "disk", E, _full_disk(lambda c, cap, run: ["export", run, "--downscale", "2,4",
                                                                             "--force"])),
    ("disk-full-select", "disk", E, _full_disk(lambda c, cap, run: ["select", run, "--budget", "5"])),
    ("disk-full-occupancy", "disk", E, _full_disk(lambda c, cap, run: ["occupancy", run, "--force"])),
    ("disk-full-evaluate", "disk", E, _full_disk(lambda c, cap, run: ["evaluate", run, *EVAL_FAST])),
    ("disk-full-report", "disk", E, _full_disk(lambda c, cap, run: ["report", run, "--force"])),
    ("disk-full-suggest", "disk", E, _full_disk(lambda c, cap, run: ["suggest", run, *SUGGEST_FAST],
                                                triangulate=True)),
    ("disk-full-run-import", "disk", E, _full_disk(lambda c, cap, run: c.fast(cap, run), fresh_run=True)),
    ("disk-full-run-triangulate", "disk", E, _full_disk(
        lambda c, cap, run: [*c.fast(cap, run)[:c.fast(cap, run).index("off")], "auto",
                             *c.fast(cap, run)[c.fast(cap, run).index("off") + 1:]], fresh_run=True)),
]


def _dup_name(model: Path) -> None:
    """images.txt with the second image renamed as the first."""
    ls = (model / "images.txt").read_text().splitlines()
    rows = [k for k, ln in enumerate(ls) if ln and not ln.startswith("#")]
    first = ls[rows[0]].split()[-1]
    w = ls[rows[2]].split()
    ls[rows[2]] = " ".join(w[:-1] + [first])
    (model / "images.txt").write_text("\n".join(ls) + "\n")


def _passwd_from_photo_folder(c: Ctx):
    """The sweep's security finding: images.txt names ../../../../../etc/passwd; `cd photos && curate run --poses
    ../model ... --export-mode copy --out ../run` copied /etc/passwd into the export."""
    cap = c.cap()
    model = c.dir / "model"
    shutil.copytree(c.base / "colmap", model)
    _edit_line("images.txt", lambda w: w[:-1] + ["../../../../../etc/passwd"])(model)
    c.cwd = cap / "images"
    run = c.out()
    c.checks.append(lambda: [f"security: {p} was exported" for p in run.rglob("*passwd*")] if run.exists() else [])
    return ["run", "--poses", "../../model", "--budget", "11", "--no-evaluate", "--undistort", "off", "--export-mode",
            "copy", "--triangulate", "off", "--out", "../../run"]


ISSUE61[0] = (ISSUE61[0][0], ISSUE61[0][1], ISSUE61[0][2], _passwd_from_photo_folder)


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
    cs += [Case(n, fam, e, b) for n, fam, e, b in ISSUE61]
    names = [c.name for c in cs]
    assert len(names) == len(set(names)), "duplicate case names"
    return cs


KINDS = ("security", "data loss", "silent wrong", "hang", "unclear")
"""How a failed case is counted, the worst first (:func:`kind_of`)."""


def kind_of(r: dict) -> str | None:
    """What a failed case is (None: clean): ``security`` (a file from outside the capture exported, markup in a
    page), ``data loss`` (a file of the user's changed or removed, anything written outside the run folder),
    ``silent wrong`` (exit 0 where an error was due, a result missing or wrong after a success), ``hang`` (timed
    out, a process or the lock left behind), else ``unclear`` (a trace, an internal error, no one-line error)."""
    if r["ok"]:
        return None
    v = " | ".join(r["violations"])
    if "security:" in v or "raw markup" in v:
        return "security"
    if "data loss:" in v or "sandbox:" in v or "user's --out file" in v or "was replaced or removed" in v:
        return "data loss"
    if "silent wrong:" in v or "expected an error, exited 0" in v or "differs from an uninterrupted" in v:
        return "silent wrong"
    if "timed out" in v or "processes" in v or "lock is still held" in v or "lock was not emptied" in v:
        return "hang"
    return "unclear"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/adv"))
    ap.add_argument("--only", default=None, help="run the cases whose name contains SUBSTRING")
    ap.add_argument("--families", default=None, help="run the cases of these families (comma-separated)")
    ap.add_argument("--jobs", type=int, default=2, choices=(1, 2))
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument("--src", type=Path, default=None,
                    help="run the curate package in SRC/curate (e.g. a frozen copy of a tree being edited)")
    args = ap.parse_args(argv)
    if args.src:
        SRC.append(str(args.src.resolve()))
    fams = set(args.families.split(",")) if args.families else None
    cases = [c for c in all_cases() if (not args.only or args.only in c.name) and (fams is None or c.family in fams)]
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
    if (args.only or fams) and path.exists():     # a partial rerun replaces its cases' lines, keeps the others
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
            r["kind"] = kind_of(r)
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
    kinds = {k: sum(kind_of(r) == k for r in results) for k in KINDS}
    print(json.dumps({"cases": len(results), "passed": sum(r["ok"] for r in results),
                      "failed": sum(not r["ok"] for r in results), "kinds": kinds,
                      "clean_pct": round(100 * sum(r["ok"] for r in results) / max(len(results), 1), 1),
                      "families": fam,
                      "failed_cases": sorted(r["case"] for r in results if not r["ok"]),
                      "wall_s": round(time.time() - t0), "curate": SRC[0] if SRC else str(ROOT)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
