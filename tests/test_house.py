"""The house (issue 60): how often one `curate run` reads the same files of its run folder.

Every read of a file is counted by wrapping ``open`` (``builtins.open`` and ``io.open``: ``Path.read_text``,
``Path.read_bytes``, ``np.load`` and ``json.load(open(...))`` all go through it) while ``curate run`` runs in this
process on the project's sample walk (known poses, a small grid; ``--workers 1`` trains in this process too).

Before the run's reader (:mod:`curate.core.run`, :mod:`curate.core.reads`), at 4ba89d6, this run read
``sfm/cameras.json`` 8 times and ``sfm/stage.json`` 15 times (33 reads of stage records in all) without the
evaluation, 9 and 17 (53) with one fold; now twice (once to checksum it for the SfM record, once to parse it) and
once, each record at most twice."""

from __future__ import annotations

import builtins
import io
from collections import Counter
from pathlib import Path

import pytest

from curate import cli

SAMPLE = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
WATCHED = ("sfm/cameras.json", "sfm/stage.json")


def _count_reads(monkeypatch, run: Path) -> Counter:
    """Start counting every read of a file under ``run``; returns the live counter {path relative to run: reads}."""
    reads: Counter = Counter()
    real = io.open
    root = str(run.resolve())

    def counting_open(file, mode="r", *args, **kwargs):
        if isinstance(file, (str, Path)) and not any(c in mode for c in "wax+"):
            p = str(Path(file).resolve()) if not isinstance(file, int) else ""
            if p.startswith(root + "/"):
                reads[p[len(root) + 1:]] += 1
        return real(file, mode, *args, **kwargs)
    monkeypatch.setattr(builtins, "open", counting_open)
    monkeypatch.setattr(io, "open", counting_open)
    return reads


def _run(tmp_path, monkeypatch, *extra: str) -> Counter:
    run = tmp_path / "run"
    run.mkdir()
    argv = ["run", str(SAMPLE / "images"), "--poses", str(SAMPLE / "transforms.json"), "--out", str(run),
            "--budget", "12", "--res", "8", "--triangulate", "off", "--method", "stride", *extra]
    reads = _count_reads(monkeypatch, run)
    assert cli.main(argv) == 0
    monkeypatch.undo()
    return reads


def _check(reads: Counter) -> None:
    records = {k: n for k, n in reads.items() if k.endswith("stage.json")}
    print({k: reads[k] for k in WATCHED}, "stage records:", sum(records.values()), dict(reads))
    assert reads["sfm/cameras.json"] <= 2 and reads["sfm/stage.json"] <= 1, dict(reads)
    assert max(records.values()) <= 2, records


def test_one_run_without_evaluation_reads_the_sfm_result_and_each_record_once_or_twice(tmp_path, monkeypatch):
    _check(_run(tmp_path, monkeypatch, "--no-evaluate"))


def test_one_evaluated_run_reads_the_sfm_result_and_each_record_once_or_twice(tmp_path, monkeypatch):
    _check(_run(tmp_path, monkeypatch, "--folds", "1", "--workers", "1", "--iters", "5", "--eval-size", "16",
                "--random-seeds", "1"))


def test_a_kept_file_is_read_again_once_it_changed(tmp_path):
    """:func:`curate.core.reads.kept` parses a file once while it stays the same, and again after a rewrite: by a
    rename (curate's writes), in place, or to the same size."""
    import json
    import os
    from curate.core.reads import kept, read_json
    from curate.core.stage import read_stage, write_json_atomic
    parsed = []

    def parse(p):
        parsed.append(p)
        return p.read_text()
    f = tmp_path / "a.json"
    f.write_text('{"k": 1}')
    assert kept(f, "t", parse) == kept(f, "t", parse) == '{"k": 1}' and len(parsed) == 1
    write_json_atomic(f, {"k": 2})
    assert read_json(f) == {"k": 2} and json.loads(kept(f, "t", parse)) == {"k": 2} and len(parsed) == 2
    f.write_text('{"k": 3}')                                         # in place, the same size as the first
    assert read_json(f) == {"k": 3}
    st = os.stat(f)
    f.write_text('{"k": 4}')
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns))                 # even with the modification time put back
    assert read_json(f) == {"k": 4}                                  # (the change time moved)
    rec = read_json(f)
    rec["k"] = 5                                                     # what a caller gets is its own
    assert read_json(f) == {"k": 4}
    (tmp_path / "stage").mkdir()
    assert read_stage(tmp_path / "stage") is None
    write_json_atomic(tmp_path / "stage" / "stage.json", [1])
    assert read_stage(tmp_path / "stage") is None                    # not a record
    write_json_atomic(tmp_path / "stage" / "stage.json", {"key": "a"})
    assert read_stage(tmp_path / "stage") == {"key": "a"}


def test_the_shared_cameras_and_grid_are_read_only(tmp_path):
    """The cameras and the node grid every stage of a run shares cannot be changed by one of them."""
    import numpy as np
    from curate.core.cameras import Cameras, look_at
    from curate.core.run import load_cameras, load_node_grid
    from curate.core.paths import RunPaths
    paths = RunPaths(tmp_path)
    paths.sfm.mkdir()
    paths.occupancy.mkdir()
    Cameras(look_at(np.eye(3), np.zeros((3, 3))), 100.0, 100.0, 50.0, 40.0, 100, 80).save(paths.cameras)
    np.savez_compressed(paths.occupancy_npz, box_min=-np.ones(3), box_max=np.ones(3), res=4,
                        nodes_mask=np.ones((4, 4, 4), bool))
    cams, grid = load_cameras(tmp_path), load_node_grid(tmp_path)
    assert cams is load_cameras(tmp_path) and grid is load_node_grid(tmp_path)
    with pytest.raises(ValueError, match="read-only"):
        cams.c2w[0, 0, 3] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        grid.mask[0, 0, 0] = False
    assert cams[[0, 1]].c2w.flags.writeable                           # a subset is the caller's own


SELF_KEYED = {"sfm/colmap.py", "sfm/pose_import.py", "evaluate/stage.py", "evaluate/units.py", "suggest/stage.py"}
"""Where a stage still keys and skips by itself, each for a reason (docs/architecture.md#run-folder): SfM (its key
hashes the photos it finds), the evaluation and its trainings (each training a stage of its own), ``curate suggest``
(not a stage of ``curate run``)."""


def test_the_graph_owns_keys_and_skipping():
    """Every stage of the graph with a key function is keyed, skipped, begun and finished by the runner alone: no
    module but the runner and the self-keyed ones calls ``begin_stage``/``finish_stage``; every stage not keyed by
    the runner is one of those."""
    import re
    from curate.core.graph import STAGES
    root = Path(__file__).resolve().parents[1] / "curate"
    callers = {p.relative_to(root).as_posix() for p in root.rglob("*.py")
               if re.search(r"\b(begin_stage|finish_stage)\(", re.sub(r"def (begin|finish)_stage\(", "",
                                                                       p.read_text()))}
    assert callers == {"core/runner.py"} | SELF_KEYED
    assert {s.name for s in STAGES if s.key is None} == {"sfm", "evaluate", "report"}
    for s in STAGES:
        if s.key is not None:
            assert s.keyed_on and set(s.keyed_on) <= set(s.reads) | set(s.needs), s.name


def test_a_keyed_stage_is_computed_only_when_its_key_changed(tmp_path, monkeypatch):
    """The runner skips an up-to-date stage without calling its computation, and calls it again when an option in
    its key changed (the budget) or a file it wrote is gone."""
    from curate.core.graph import BY_NAME, RunContext
    from curate.core.runner import run_stage
    from curate.pipeline import saved_config
    from curate.select import stage as select_stage
    run = tmp_path / "run"
    run.mkdir()
    assert cli.main(["run", str(SAMPLE / "images"), "--poses", str(SAMPLE / "transforms.json"), "--out", str(run),
                     "--budget", "12", "--res", "8", "--triangulate", "off", "--method", "stride",
                     "--no-evaluate"]) == 0
    cfg, _ = saved_config(run)
    real, calls = select_stage.choose, []

    def counted(ctx, keyed):
        calls.append(keyed.key)
        return real(ctx, keyed)
    monkeypatch.setattr(select_stage, "choose", counted)
    res = run_stage(BY_NAME["select"], RunContext(cfg, run))
    assert not res.ran and calls == []
    from dataclasses import replace
    res = run_stage(BY_NAME["select"], RunContext(replace(cfg, budget="10"), run))
    assert res.ran and len(calls) == 1
    (run / "select" / "nodes.npz").unlink()
    res = run_stage(BY_NAME["select"], RunContext(replace(cfg, budget="10"), run))
    assert res.ran and len(calls) == 2 and calls[0] == calls[1] and (run / "select" / "nodes.npz").is_file()


def test_one_plan_after_sfm_decides_the_kind_method_and_budget_once(tmp_path, monkeypatch):
    """The capture's kind is worked out once in an evaluated run (before the plan: 4 times, once more per fold);
    the report records the plan; the selection and every fold run the method it resolved."""
    import json
    import curate.select.methods as methods
    calls = []
    real = methods.capture_kind

    def counted(cams):
        calls.append(len(cams))
        return real(cams)
    monkeypatch.setattr(methods, "capture_kind", counted)
    run = tmp_path / "run"
    assert cli.main(["run", str(SAMPLE / "images"), "--poses", str(SAMPLE / "transforms.json"), "--out", str(run),
                     "--budget", "12", "--res", "8", "--triangulate", "off", "--folds", "2", "--workers", "1",
                     "--iters", "5", "--eval-size", "16", "--random-seeds", "1"]) == 0
    assert len(calls) == 1
    rep = json.loads((run / "report.json").read_text())
    plan = rep["plan"]
    assert plan["n_budget"] == 12 and plan["method"] != "auto" and plan["kind"] in ("walk", "object")
    assert rep["selection"]["method"] == plan["method"]
    summ = json.loads((run / "evaluate" / "summary.json").read_text())
    assert {f["method"] for f in summ["protocol"]["folds"]} == {plan["method"]}


def test_a_budget_that_does_not_fit_stops_the_run_before_the_occupancy(tmp_path, capsys):
    """The plan checks the budget once, right after SfM: one line naming it, exit 2, no occupancy started."""
    run = tmp_path / "run"
    assert cli.main(["run", str(SAMPLE / "images"), "--poses", str(SAMPLE / "transforms.json"), "--out", str(run),
                     "--budget", "100000", "--res", "8", "--triangulate", "off", "--no-evaluate"]) == 2
    err = capsys.readouterr().err
    assert "budget 100000 is more than all" in err and "Traceback" not in err
    assert (run / "sfm" / "stage.json").is_file() and not (run / "occupancy").exists()
