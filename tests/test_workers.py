"""Issue 61, item 4: no training process outlives the command, on any way out of the evaluation.

The evaluation's scheduler (:func:`curate.evaluate.schedule.run_folds`) runs in a child process of the test, in a
session of its own, with a pool of two spawned workers whose "training" only sleeps; each way out is taken:
every fold done, one fold (``--folds 1``), decided early with a training still in flight, out of time
(``--eval-minutes``), a training that fails, and Ctrl-C, SIGTERM and SIGHUP while the trainings run. After each,
the process has no child left but multiprocessing's resource tracker; when it exits, nothing of its session is
left, not even a process waiting to be reaped (before, the resource tracker was). The real command is checked
once (slow)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = r'''
import json, os, sys, time
from pathlib import Path
import numpy as np

if __name__ == "__mp_main__":        # a spawned worker, still starting (it re-runs this file before its initializer)
    try:
        if float(os.environ.get("WORKER_START", "0")):
            Path(f"{os.getpid()}.starting").touch()          # in the test's folder (the cwd)
        time.sleep(float(os.environ.get("WORKER_START", "0")))
    except KeyboardInterrupt:        # the start of Python's traceback, as a worker killed while printing it leaves it
        sys.stderr.write("Traceback (most recent call last):\n  File ")
        sys.stderr.flush()
        raise


def train(args):
    """A training that only sleeps (run_folds' ``train``): its unit key says how long, and whether it fails."""
    key = args[1].key
    if key.endswith("boom"):
        raise RuntimeError("this training fails")
    time.sleep(float(os.environ.get("SLEEP", "0.4")) * (4 if key.endswith("slow") else 1))
    return {"psnr": 20.0, "ssim": 0.5, "per_view": []}


def children():
    """PIDs of this process's children still in the process table."""
    out = []
    for pid in os.listdir("/proc"):
        try:
            stat = open(f"/proc/{pid}/stat").read() if pid.isdigit() else ""
            if stat and int(stat[stat.rindex(")") + 2:].split()[1]) == os.getpid():
                out.append(int(pid))
        except (OSError, ValueError):
            continue
    return out


def main():
    from multiprocessing import resource_tracker
    from curate.core import runfolder, signals
    from curate.core.cameras import Cameras, look_at
    from curate.evaluate.config import EvalConfig
    from curate.evaluate.schedule import run_folds
    from curate.evaluate.units import Unit

    signals.install("curate evaluate")
    n = 6
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    cams = Cameras(look_at(np.stack([np.cos(a), np.sin(a), 0 * a], 1), np.zeros((n, 3))), 30.0, 30.0, 16, 12, 32, 24)

    class Fold:
        def __init__(self, o, tail=""):
            self.holdout = []
            self.units = [Unit(f"f{o}_{m}{tail if m == 'b' else ''}", m, None, [0, 1, 2]) for m in ("a", "b")]

    def go(run, order, look_at=(), stop=False, adaptive=False, minutes=10.0, tail=""):
        cfg = EvalConfig(workers=2, minutes=minutes, iters=10)
        return run_folds(run, cfg, lambda o: Fold(o, tail if o == order[-1] else ""), list(order), list(look_at),
                         lambda f, r: stop, cams, ["x"] * n, None, lambda u, f: u.key + str(f.units), adaptive,
                         progress=False, train=train)

    out = {}
    with runfolder.claimed(sys.argv[1]) as run:
        for name, kw in json.loads(sys.argv[2]).items():
            sub = run / name
            sub.mkdir()
            try:
                folds, _, why = go(sub, **kw)
                out[name] = why
            except RuntimeError as e:
                out[name] = f"failed: {e}"
            tracker = getattr(resource_tracker._resource_tracker, "_pid", None)
            out[name + " children"] = [c for c in children() if c != tracker]
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt as e:
        from curate.core import signals
        word, code = signals.said(e)
        if signals.unwound():
            print(f"curate evaluate: {word}", file=sys.stderr, flush=True)
        sys.exit(code)
'''


def session_left(sid: int) -> list[str]:
    """The processes of session ``sid`` still in the process table (a zombie counts: nothing reaped it)."""
    out = []
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            try:
                if os.getsid(int(pid)) == sid:
                    out.append(Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:100]
                               or f"{pid} (exited, not reaped)")
            except OSError:
                continue
    return out


def _as_from_a_terminal() -> None:
    """The child starts with SIGINT and SIGHUP as a command typed at a terminal has them: a test suite started in
    the background (``nohup pytest &``) ignores both, its children inherit that, and curate rightly keeps a signal
    ignored that was ignored when it started (``curate.core.signals.install``)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGHUP, signal.SIG_DFL)


def run_script(tmp_path: Path, paths: dict, sig: int | None = None, sleep: float = 0.4,
               worker_start: float = 0.0) -> tuple:
    """Run SCRIPT over ``paths``; with ``sig``, send it once both workers are in the process table (SIGINT to the
    process group, as Ctrl-C at a terminal does). ``worker_start``: seconds each worker spends starting."""
    script = tmp_path / "evaluate_paths.py"
    script.write_text(SCRIPT)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "SLEEP": str(sleep), "OMP_NUM_THREADS": "1",
           "WORKER_START": str(worker_start)}
    p = subprocess.Popen([sys.executable, str(script), str(tmp_path / "run"), json.dumps(paths)], env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True, cwd=tmp_path,
                         preexec_fn=_as_from_a_terminal)
    if sig is not None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(session_left(p.pid)) < 4:   # curate, its tracker, two workers
            time.sleep(0.1)
        while worker_start and time.monotonic() < deadline and len(list(tmp_path.glob("*.starting"))) < 2:
            time.sleep(0.1)
        time.sleep(0.5)
        (os.killpg if sig == signal.SIGINT else os.kill)(p.pid, sig)
    try:
        out, err = p.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        raise
    left = session_left(p.pid)
    for pid in os.listdir("/proc"):            # what this test started, ended before it fails
        if pid.isdigit():
            try:
                if os.getsid(int(pid)) == p.pid:
                    os.kill(int(pid), signal.SIGKILL)
            except OSError:
                pass
    return p.returncode, out.decode(), err.decode(), left


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_no_worker_outlives_any_normal_way_out_of_the_evaluation(tmp_path):
    paths = {"done": {"order": [0, 1]},
             "folds-1": {"order": [0]},
             "decided": {"order": [0, 1, 2], "look_at": [2], "stop": True, "tail": "slow"},
             "out-of-time": {"order": [0, 1, 2, 3], "adaptive": True, "minutes": 0.001},
             "failed": {"order": [0, 1], "tail": "boom"}}
    rc, out, err, left = run_script(tmp_path, paths)
    assert rc == 0, err
    got = json.loads(out.strip().splitlines()[-1])
    assert got["done"] == "all folds" and got["folds-1"] == "all folds" and got["decided"] == "decided"
    assert got["out-of-time"] == "time" and got["failed"].startswith("failed")
    assert all(got[f"{k} children"] == [] for k in paths), got
    assert left == [], left
    assert "leaked" not in err and "Traceback" not in err, err


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
@pytest.mark.parametrize("starting", [False, True], ids=["training", "starting"])
def test_no_worker_outlives_a_signal_during_the_evaluation(tmp_path, sig, starting):
    """Ctrl-C, SIGTERM or SIGHUP while the workers train, or while they are still starting: the command exits
    with 128 + the signal, its stderr is its one line (no worker's traceback, which a worker killed while it
    printed left broken, glued to curate's line: a CI failure), and nothing is left."""
    rc, out, err, left = run_script(tmp_path, {"signalled": {"order": [0, 1, 2, 3]}}, sig=sig, sleep=30,
                                    worker_start=30 if starting else 0)
    assert rc == 128 + sig, err
    word = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated", signal.SIGHUP: "terminated (hang-up)"}[sig]
    assert err.splitlines() == [f"curate evaluate: {word}"], err
    assert left == [], left


@pytest.mark.slow
def test_curate_evaluate_leaves_no_process_one_fold_and_after_the_selection_was_redone(tmp_path):
    """The command itself: `curate evaluate RUN --folds 1` with two workers, then again after `curate select RUN
    --budget 5` redid the selection; nothing of either command is left when it exits."""
    from test_export import ring, write_photos
    from curate.core.transforms_json import write_transforms
    cams = ring(12)
    write_photos(tmp_path / "cap", cams)
    write_transforms(tmp_path / "cap" / "transforms.json", cams)
    run = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    ev = ["--folds", "1", "--workers", "2", "--iters", "10", "--eval-size", "16", "--random-seeds", "1"]
    for argv in (["run", str(tmp_path / "cap" / "photos"), "--poses", str(tmp_path / "cap" / "transforms.json"),
                  "--out", str(run), "--no-evaluate", "--budget", "4", "--res", "8", "--triangulate", "off",
                  "--refine-iters", "40", "--refine-size", "32"],      # the refining field: not what is tested
                 ["evaluate", str(run), *ev], ["select", str(run), "--budget", "5"], ["evaluate", str(run), *ev]):
        p = subprocess.Popen([sys.executable, "-m", "curate", *argv], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, start_new_session=True)
        _, err = p.communicate(timeout=600)
        assert p.returncode == 0, err.decode()[-2000:]
        assert session_left(p.pid) == [], argv
    assert json.loads((run / "evaluate" / "summary.json").read_text())["protocol"]["exported_budget"] == 5
