"""The stage runner: the one place that keys, skips, begins and finishes a stage (:data:`curate.core.graph.STAGES`).

:func:`run_stage` runs a stage of the graph. A keyed stage (:attr:`curate.core.graph.Stage.key`) is run by
:func:`run_keyed`: its key function says what options its result depends on (:class:`Keyed`), the runner adds the
keys of the stages it is keyed on, skips it when its record has that key and its files are there
(:func:`curate.core.stage.begin_stage`), otherwise clears what curate wrote in its folder, calls its computation and
writes its record from what the computation returns (:class:`Done`). The stage's own code computes; it never keys,
skips or writes a record.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from curate.core.graph import _function
from curate.core.stage import StageResult, begin_stage, finish_stage, is_fresh, read_stage, required_key, stage_key

if TYPE_CHECKING:
    from curate.core.graph import RunContext, Stage


def run_stage(stage: "Stage", ctx: "RunContext") -> StageResult:
    """Run ``stage`` in ``ctx``'s run folder: a keyed stage through :func:`run_keyed`, another by its own function.
    An ``OSError`` that names no file (a full disk met by a library) is raised again naming the stage's folder."""
    try:
        if stage.key is not None:
            return run_keyed(stage, ctx)
        return _function(stage.runs)(ctx)
    except OSError as e:
        if e.filename is None and e.errno is not None:
            raise OSError(e.errno, e.strerror or str(e), str(Path(ctx.run_dir) / stage.writes[0])) from None
        raise


@dataclasses.dataclass
class Keyed:
    """What a keyed stage's key function (:attr:`curate.core.graph.Stage.key`) returns: the options its key hashes
    beside the keys of the stages it is keyed on (:attr:`curate.core.graph.Stage.keyed_on`)."""

    parts: Any
    """The options its result depends on (a config, or a dict of them), hashed into the key."""
    serves: Any = None
    """Other parts whose finished result serves as well (occupancy: a grid refined by a field serves a run that
    needs none); None: only its own."""
    state: Any = None
    """What the key function found that the computation needs again, handed to it as it is."""
    key: str = ""
    """The key (:func:`stage_key` of the parts and the keys of the stages it is keyed on), set by
    :func:`run_keyed`."""


@dataclasses.dataclass
class Done:
    """What a keyed stage's computation returns once every file it writes is in place: :func:`run_keyed` writes
    its record with it."""

    summary: str
    """The stage's line on the terminal."""
    outputs: dict
    """{what: file or folder relative to the stage's folder}: its record's ``outputs``."""
    config: Any = None
    """The options its record shows (None: the key's parts)."""
    seed: int | None = None
    """The seed it used, when one."""
    record: dict = dataclasses.field(default_factory=dict)
    """More fields of its record."""
    warning: str | None = None
    """What the user must know about the result (:attr:`StageResult.warning`)."""


def run_keyed(stage: "Stage", ctx: "RunContext", key_of: Callable[["RunContext"], Keyed] | None = None
              ) -> StageResult:
    """Run ``stage`` (a :class:`curate.core.graph.Stage` with a key function) in ``ctx``'s run folder: its key (its
    :class:`Keyed` parts and the keys of the stages it is keyed on), skipped when its record has that key
    and its files are there (:func:`begin_stage`), else its folder cleared of what curate wrote, its computation
    called, and its record written (:func:`finish_stage`). The one place that keys, skips, begins and finishes.
    ``key_of``: a key function of its own instead of the stage's (the occupancy trained on a fold's photos)."""
    t0 = time.perf_counter()
    d = Path(ctx.run_dir) / stage.name
    keyed = (key_of or _function(stage.key))(ctx)
    deps = [required_key(ctx.run_dir, s) for s in stage.keyed_on]
    keyed.key = stage_key(keyed.parts, deps)
    if keyed.serves is not None and not ctx.force and is_fresh(d, stage_key(keyed.serves, deps), stage.spare):
        return StageResult(stage.name, d, False, time.perf_counter() - t0)
    if begin_stage(d, keyed.key, ctx.force, owns=stage.owns, spare=stage.spare):
        warning = (read_stage(d) or {}).get(stage.warns) if stage.warns else None
        return StageResult(stage.name, d, False, time.perf_counter() - t0, warning=warning)
    done: Done = _function(stage.runs)(ctx, keyed)
    finish_stage(d, keyed.key, keyed.parts if done.config is None else done.config, t0, outputs=done.outputs,
                 seed=done.seed, owns=stage.owns, **done.record)
    return StageResult(stage.name, d, True, time.perf_counter() - t0, done.summary, warning=done.warning)
