"""Train the folds' units as the folds are added, and stop when the folds have decided or the time is spent.

:func:`run_folds` keeps every worker busy: a fold's units go to the workers as they free up, and a new fold
is started as soon as the previous one has no unit left to hand out, while it is expected to finish within
the time given (the first :data:`MIN_FOLDS` always run). When the finished folds reach a planned look
(:func:`curate.evaluate.folds.looks`), ``stop_at`` decides whether to stop; the units still training then
finish (they are kept for a later evaluation) and nothing more is started.

A unit whose stage key equals another's (the same subset: "auto" chose exactly the FVS subset) trains once
and is copied. A unit finished by an earlier evaluation is reused. Ctrl-C stops the workers at once: the
units finished so far stay, and a re-run resumes from them.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from concurrent.futures import FIRST_COMPLETED, Future, wait
from pathlib import Path
from typing import Callable

import numpy as np

from curate.core.paths import RunPaths

log = logging.getLogger(__name__)

MIN_FOLDS = 2
"""Folds that always run (an interval over folds needs two)."""


class _Inline:
    """An executor that runs each call at once in this process (one worker)."""

    def submit(self, fn, /, *args) -> Future:
        f: Future = Future()
        f.set_result(fn(*args))
        return f


@dataclass
class Look:
    """What a look at the finished folds decided (``stop_at``'s answer; a plain bool means ``Look(stop=it)``)."""

    stop: bool = False
    """Start nothing more: every rival decided, or nothing left that the time given would decide."""
    skip: frozenset = frozenset()
    """Unit methods ('random', 'fvs', ...) not to train from now on (their rivals are decided, or not worth the
    time); units of theirs not yet handed out are dropped, and a fold is finished without them."""
    next_look: int | None = None
    """The finished-fold count of the next look (None: at the end); no fold beyond it is started before it."""
    until: dict = field(default_factory=dict)
    """{unit method: the folds, counted from the first in the order trained, in which it is trained}: its units of
    later folds are not trained (each rival only as far as its own comparison is projected to need; the selection
    as far as any rival). A method not named keeps its earlier limit (none: every fold)."""
    also: tuple = ()
    """More finished-fold counts at which to look (each rival's own planned look), besides ``next_look``."""
    why: str = "decided"
    """Why it stopped, when ``stop``: 'decided', or 'needs time' (what is undecided would not be decided within
    the time given)."""


def run_folds(run_dir: Path, cfg, make_fold: Callable, order: list[int], look_at: list[int],
              stop_at: Callable[[list, dict], "bool | Look"], cams, paths, box, unit_key: Callable, adaptive: bool,
              executor=None, progress: bool = True, train: Callable | None = None,
              on_trained: Callable[[float, int], None] | None = None,
              on_fold: Callable[[list, dict], None] | None = None) -> tuple[list, dict, str]:
    """Train folds ``make_fold(offset)`` for the offsets of ``order`` until one of: the finished folds decide
    at a look (``stop_at(folds, results)`` at each count of ``look_at``, and at the counts the looks plan: a
    :class:`Look`), every fold is done, or (``adaptive``) the next fold is not expected to end within
    ``cfg.minutes``.

    ``unit_key(unit, fold)``: a unit's stage key. ``cams``: every registered camera at evaluation size,
    ``paths`` their images, ``box`` the field's scene box. ``executor``: a ``concurrent.futures.Executor``
    (e.g. Ray's) for the trainings; None: local processes (:func:`curate.evaluate.units.auto_workers`).
    ``train``: what trains a unit, given :func:`curate.evaluate.units.train_unit`'s arguments and the log level
    as one tuple (default :func:`curate.evaluate.units._unit_entry`; a test passes its own).
    ``on_trained(seconds, workers)``: called as each training of this call finishes, with its wall seconds and
    the trainings run at a time (what a fold costs on this machine). ``on_fold(folds, results)``: called as each
    fold finishes that is not a look (to forecast, not to decide).
    Returns (the finished folds in order, each listing the units it trained or reused (those a look closed left
    out), {unit key: metrics}, why it stopped: 'decided', 'needs time', 'all folds' or 'time'). When it stopped at
    a look, the folds are those of that look.
    """
    from curate.core.pools import end_pool
    from curate.core.runfolder import held_token
    from curate.core.stage import is_fresh
    from curate.evaluate.units import (PROGRESS_FILE, _copy_unit, _unit_entry, auto_workers, read_metrics,
                                       save_ground_truth)
    from tqdm import tqdm
    ev_dir = RunPaths(run_dir).evaluate
    train = train or _unit_entry
    t0 = time.monotonic()
    budget_s = 60.0 * cfg.minutes
    token = held_token(run_dir)
    level = logging.getLogger("curate").getEffectiveLevel()
    started: list = []          # folds begun, in order
    finished: list = []         # folds whose every unit is done, in order
    results: dict[str, dict] = {}
    queue: deque = deque()      # units to hand out
    inflight: dict[Future, object] = {}
    by_key: dict[str, str] = {}  # stage key -> the unit that trains it
    dups: list = []             # (unit, the unit whose result it copies)
    durations: list[float] = []  # seconds of each unit trained now
    began: dict[str, float] = {}
    trained_now: list = []       # units handed to a worker now (the bar's total)
    owned: list = []             # the local pool this call started
    decided_now = False
    n_decided = 0                # the finished folds when they decided
    why_stopped = "decided"
    skip: set = set()            # unit methods not to train any more
    dropped: set = set()         # unit keys not trained because of it
    until: dict[str, int] = {}   # unit method -> the folds (from the first) it is trained in
    looks_at = sorted(set(look_at))

    if executor is not None:
        workers, ex = (cfg.workers or 8), executor
    else:
        workers, ex = 1, None

    def closed(u, pos: int) -> bool:
        """Unit ``u`` of the ``pos``-th fold (from 0) is not to be trained: its method is closed, or past its
        folds."""
        return u.method in skip or pos >= until.get(u.method, len(order))

    def start_fold() -> None:
        nonlocal workers, ex
        f = make_fold(order[len(started)])
        pos = len(started)
        started.append(f)
        save_ground_truth(run_dir, cams, paths, f.holdout)
        for u in f.units:
            k = unit_key(u, f)
            if closed(u, pos) and u.key not in results:
                dropped.add(u.key)
                continue
            if is_fresh(ev_dir / u.key, k):
                results[u.key] = read_metrics(ev_dir / u.key)
                by_key.setdefault(k, u.key)
            elif k in by_key:
                dups.append((u, by_key[k]))
            else:
                by_key[k] = u.key
                queue.append((u, f, k))
        if ex is None and queue:           # the first training to do: a local pool sized for it
            u0 = queue[0][0]
            pix = int(np.sum(cams.width[u0.subset] * cams.height[u0.subset]))
            workers = auto_workers(cfg, 2 * len(f.units), pix)
            if workers <= 1:
                ex = _Inline()
            else:
                import os
                from curate.core.pools import local_pool
                from curate.evaluate.units import worker_start
                ex = local_pool(workers, worker_start, (os.getpid(),))
                owned.append(ex)

    def may_start() -> bool:
        if decided_now or len(started) >= len(order):
            return False
        pending = [n for n in looks_at if n > len(finished)]
        if pending and len(started) >= pending[0] and adaptive:
            return False                 # no fold beyond a look not yet made
        if until and len(started) >= max(until.values()):
            return False                 # no method is trained in a fold this far
        if len(started) < MIN_FOLDS or not adaptive:
            return True
        if not durations:
            return True
        per = float(np.median(durations)) / max(workers, 1)
        nxt = sum(1 for u in started[-1].units if not closed(u, len(started)))
        left = len(queue) + len(inflight) + nxt
        return time.monotonic() - t0 + left * per <= budget_s

    def done(u) -> bool:
        return u.key in results or u.key in dropped

    def resolve() -> None:
        """Copy the duplicates whose source is done; move finished folds to ``finished``; look."""
        nonlocal decided_now, n_decided, why_stopped, looks_at
        for u, src in list(dups):
            if closed(u, order.index(u.fold) if u.fold in order else 0) and src not in results:
                dups.remove((u, src))
                dropped.add(u.key)
            elif src in results:
                results[u.key] = _copy_unit(ev_dir, src, u, results[src])
                dups.remove((u, src))
        while len(finished) < len(started) and all(done(u) for u in started[len(finished)].units):
            finished.append(started[len(finished)])
            if on_fold is not None and len(finished) not in looks_at and not decided_now:
                on_fold(finished, results)
            if len(finished) in looks_at and not decided_now:
                lk = stop_at(finished, results)
                lk = lk if isinstance(lk, Look) else Look(stop=bool(lk))
                if lk.stop:
                    decided_now, n_decided, why_stopped = True, len(finished), lk.why
                    queue.clear()
                    break
                skip.update(lk.skip)
                until.update({m: int(n) for m, n in lk.until.items()})
                for item in [q for q in queue if closed(q[0], started.index(q[1]))]:
                    queue.remove(item)
                    dropped.add(item[0].key)
                for n in (lk.next_look, *lk.also):
                    if n is not None and n > len(finished):
                        looks_at = sorted(set(looks_at) | {int(n)})

    def iters_done() -> int:
        n = 0
        for u, _, _ in trained_now:
            if u.key in results:
                n += cfg.train_steps()
                continue
            try:
                n += min(int((ev_dir / u.key / PROGRESS_FILE).read_text()), cfg.train_steps())
            except (OSError, ValueError):
                pass
        return n

    bar = tqdm(total=0, desc="evaluate", unit="it", disable=not progress, smoothing=0.05)
    stop_bar = threading.Event()

    def show() -> None:
        bar.total = len(trained_now) * cfg.train_steps() + len(queue) * cfg.train_steps()
        bar.n = iters_done()
        done = sum(u.key in results for u, _, _ in trained_now)
        bar.set_description_str(f"evaluate: fold {min(len(finished) + 1, len(order))} of up to {len(order)}")
        bar.set_postfix_str(f"{done} of {len(trained_now) + len(queue)} trainings", refresh=False)
        bar.refresh()

    def poll() -> None:
        while not stop_bar.wait(1.0):
            show()
    poller = threading.Thread(target=poll, daemon=True)
    poller.start()
    try:
        while True:
            while len(inflight) < workers:
                if not queue:
                    if may_start():
                        start_fold()
                        resolve()
                        continue
                    break
                u, f, k = queue.popleft()
                trained_now.append((u, f, k))
                began[u.key] = time.monotonic()
                fut = ex.submit(train, (str(run_dir), u, cfg, cams, list(paths), list(f.holdout), box, k, None,
                                              token, level))
                inflight[fut] = u
                if fut.done():          # inline: ran already
                    break
            if not inflight:
                resolve()
                if not queue and not may_start():
                    break
                continue
            ready, _ = wait(list(inflight), timeout=1.0, return_when=FIRST_COMPLETED)
            for fut in ready:
                u = inflight.pop(fut)
                results[u.key] = fut.result()
                durations.append(time.monotonic() - began[u.key])
                if on_trained is not None:
                    on_trained(durations[-1], workers)
            resolve()
    except BaseException:
        for e in owned:        # killed and reaped: no training outlives the command
            end_pool(e, kill=True)
        if executor is not None:
            for fut in inflight:
                fut.cancel()
        raise
    finally:
        stop_bar.set()
        poller.join()
        show()
        bar.close()
    for e in owned:            # decided, out of time or done: the trainings in flight finish, then the pool ends
        end_pool(e)
    owned.clear()
    resolve()
    for f in finished:         # a fold lists the units it trained (or reused), not those its plan closed
        f.units = [u for u in f.units if u.key not in dropped]
    if decided_now:   # the verdict is the look's: a fold the trainings still running completed is kept for later
        return finished[:n_decided], results, why_stopped
    return finished, results, "all folds" if len(finished) == len(order) else "time"
