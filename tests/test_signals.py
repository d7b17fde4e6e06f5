"""SIGTERM and SIGHUP, what schedulers send, stop curate as Ctrl-C does (issue 49): one line, no native stack
dump, the run folder's lock released, the workers gone, exit status 143, and a re-run that resumes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from curate.core import runfolder as rf
from curate.core import signals

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "room_walk"


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}


def test_the_words_and_exit_statuses_of_each_signal():
    assert issubclass(signals.Terminated, KeyboardInterrupt)
    assert signals.said(KeyboardInterrupt()) == ("interrupted", 130)
    assert signals.said(signals.Terminated(signal.SIGTERM)) == ("terminated", 143)
    assert signals.said(signals.Terminated(signal.SIGHUP))[1] == 129


def _after_pycolmap(body: list[str], first: str = "") -> str:
    """A program that installs curate's handlers, imports pycolmap through curate's loader, prints 'ready', runs
    ``body`` (lines) and ends as curate's commands do on a signal: the one line and the signal's exit status."""
    return ("import signal, sys, time\n" + (first + "\n" if first else "")
            + "from curate.core import signals\n"
            "from curate.sfm.native import load\n"
            "signals.install('curate test')\n"
            "load()\n"
            "try:\n"
            "    print('ready', flush=True)\n"
            + "".join(f"    {line}\n" for line in body)
            + "except KeyboardInterrupt as e:\n"
            "    w, c = signals.said(e)\n"
            "    if signals.unwound(): print(f'curate test: {w}', file=sys.stderr)\n"
            "    sys.exit(c)\n")


@pytest.mark.parametrize("sig, word, code", [(signal.SIGTERM, "terminated", 143),
                                           (signal.SIGHUP, "terminated (hang-up)", 129)])
def test_pycolmaps_own_handler_does_not_replace_curates(tmp_path, sig, word, code):
    """pycolmap's import installs glog's failure handler (a native stack dump on SIGTERM): after curate's
    loader, the signal ends the process with curate's one line."""
    # started as from a terminal: SIGHUP not ignored, whatever the test runner was started with (under nohup
    # the child would inherit SIGHUP ignored, which curate keeps: the next test)
    prog = _after_pycolmap(["time.sleep(60)"], first="signal.signal(signal.SIGHUP, signal.SIG_DFL)")
    p = subprocess.Popen([sys.executable, "-c", prog], env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    assert p.stdout.readline().strip() == "ready"
    p.send_signal(sig)
    out, err = p.communicate(timeout=30)
    assert p.returncode == code and err.strip() == f"curate test: {word}", err


def test_a_signal_ignored_at_start_stays_ignored(tmp_path):
    """`nohup curate run ...`: SIGHUP is ignored when curate starts, and closing the terminal must not stop the
    run, before or after pycolmap's import replaced the handlers; SIGTERM still stops it."""
    prog = _after_pycolmap(["sys.stdin.readline()", "print('still running', flush=True)", "time.sleep(60)"],
                           first="signal.signal(signal.SIGHUP, signal.SIG_IGN)")   # what nohup does before exec
    p = subprocess.Popen([sys.executable, "-c", prog], env=_env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "ready"
    p.send_signal(signal.SIGHUP)
    time.sleep(0.5)
    p.stdin.write("\n")
    p.stdin.flush()
    assert p.stdout.readline().strip() == "still running"
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=30)
    assert p.returncode == 143 and err.strip() == "curate test: terminated", err


def test_a_forked_workers_signal_does_not_end_the_parent():
    """A worker forked from curate's process (multiprocessing's default on Linux) inherited the pipe of curate's
    watcher: a SIGTERM the worker got (a pool's terminate) reached the parent's watcher, which ended the parent
    after the grace (the CI run that stopped at 143 half-way through the tests)."""
    prog = ("import multiprocessing as mp, os, signal, sys, time\n"
            "from curate.core import signals\n"
            "signals.install('curate test')\n"
            "def child():\n"
            "    try:\n"
            "        os.kill(os.getpid(), signal.SIGTERM)\n"
            "        time.sleep(5)\n"
            "    except KeyboardInterrupt:\n"
            "        pass\n"
            "p = mp.get_context('fork').Process(target=child)\n"
            "p.start(); p.join()\n"
            "time.sleep(signals.GRACE_S + 1.5)\n"
            "print('alive', flush=True)\n")
    res = subprocess.run([sys.executable, "-c", prog], env=_env(), capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and res.stdout.strip() == "alive", (res.returncode, res.stderr)


def test_a_signal_during_native_work_ends_the_process_after_the_grace(tmp_path):
    """The main thread stuck in a call that does not return (as COLMAP's mapping): the watcher ends the
    process within the grace, with the line, and the run folder's lock released."""
    run = tmp_path / "run"
    prog = ("import os, signal, sys\n"
            "from curate.core import runfolder, signals\n"
            "signals.install('curate test')\n"
            "r, w = os.pipe()\n"
            "try:\n"
            f"    with runfolder.claimed({str(run)!r}):\n"
            "        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})\n"   # as in a native call that does
            "        print('ready', flush=True)\n"                                   # not return: Python's handler
            "        os.read(r, 1)\n"                                                # never gets to run
            "except KeyboardInterrupt as e:\n"      # the signal caught the main thread before it blocked: the same
            "    c = signals.said(e)\n"
            "    if signals.unwound(): print(f'curate test: {c[0]}', file=sys.stderr)\n"
            "    sys.exit(c[1])\n")
    p = subprocess.Popen([sys.executable, "-c", prog], env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    assert p.stdout.readline().strip() == "ready"
    t0 = time.time()
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=30)
    assert p.returncode == 143 and err.strip() == "curate test: terminated"
    assert time.time() - t0 < signals.GRACE_S + 10
    with rf.claimed(run):          # free again, and no "taking over" of a stale holder is needed
        pass
    assert rf.read_lock(run) == {}


def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, ValueError, IndexError):
                pass
    return out


def _alive(pid: int) -> bool:
    try:
        st = (Path("/proc") / str(pid) / "stat").read_text()
    except OSError:
        return False
    return st.rsplit(")", 1)[1].split()[0] != "Z"


def _first_frames(dst: Path, n: int) -> Path:
    """The sample walk's first ``n`` photos (links) and their poses in ``dst``."""
    meta = json.loads((SAMPLE / "transforms.json").read_text())
    meta["frames"] = meta["frames"][:n]
    (dst / "images").mkdir(parents=True)
    for f in meta["frames"]:
        (dst / f["file_path"]).symlink_to(SAMPLE / f["file_path"])
    (dst / "transforms.json").write_text(json.dumps(meta))
    return dst


def test_the_last_line_is_said_once_when_the_main_thread_unwinds_just_after_the_grace():
    """The main thread unwinds just after the grace ran out (killing the training workers on a loaded machine):
    the watcher is ending the process and says the line; the main thread does not say it again (before, both
    did)."""
    prog = ("import sys, time\n"
            "from curate.core import pools, signals\n"
            f"pools.end_all = lambda: time.sleep({signals.GRACE_S})\n"       # the watcher's end takes a while
            "signals.install('curate test')\n"
            "try:\n"
            "    print('ready', flush=True)\n"
            "    time.sleep(60)\n"
            "except KeyboardInterrupt as e:\n"
            f"    time.sleep({signals.GRACE_S} + 1)\n"          # unwinding: past the grace, within the watcher's end
            "    c = signals.said(e)\n"
            "    if signals.unwound() is not False:\n"           # as the command does (before, unwound said nothing)
            "        print(f'curate test: {c[0]}', file=sys.stderr, flush=True)\n"
            "    time.sleep(60)\n"                                # the watcher's os._exit ends it
            "    sys.exit(c[1])\n")
    p = subprocess.Popen([sys.executable, "-c", prog], env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    assert p.stdout.readline().strip() == "ready"
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 143 and err.splitlines() == ["curate test: terminated"], err


@pytest.mark.slow
@pytest.mark.parametrize("when", ["sfm", "evaluate"])
def test_sigterm_during_a_run_stops_it_cleanly_and_the_rerun_resumes(tmp_path, when):
    run = tmp_path / "run"
    cap = _first_frames(tmp_path / "cap", 48) if when == "sfm" else SAMPLE    # the points' matching: fewer photos
    cmd = [sys.executable, "-m", "curate", "run", str(cap / "images"), "--poses", str(cap / "transforms.json"),
           "--out", str(run), "--budget", "8", "--iters", "60", "--eval-size", "32", "--res", "12", "--folds", "2",
           "--workers", "2", "--refine-iters", "40", "--refine-size", "32",
           *([] if when == "sfm" else ["--triangulate", "off"])]   # points only where killed
    p = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    ready = (lambda: (run / "sfm" / "database.db").is_file()) if when == "sfm" else \
        (lambda: any((run / "evaluate").glob("f00_*/.progress")))
    while not ready():
        assert p.poll() is None, p.communicate()
        assert time.time() - t0 < 600
        time.sleep(0.1)
    workers = _children(p.pid)
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 143, err
    assert err.strip().splitlines()[-1] == "curate run: terminated"
    assert "Aborted" not in err and "stack trace" not in err and "Traceback" not in err
    deadline = time.time() + 10
    while any(_alive(w) for w in workers) and time.time() < deadline:
        time.sleep(0.2)
    assert not [w for w in workers if _alive(w)]
    with rf.claimed(run):
        pass
    res = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr
    rep = json.loads((run / "report.json").read_text())
    assert rep["evaluation"]["status"] == "current" and len(rep["selection"]["chosen"]) == 8
