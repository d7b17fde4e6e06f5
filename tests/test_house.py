"""The house (issue 60): how often one `curate run` reads the same files of its run folder.

Every read of a file is counted by wrapping ``open`` (``builtins.open`` and ``io.open``: ``Path.read_text``,
``Path.read_bytes``, ``np.load`` and ``json.load(open(...))`` all go through it) while ``curate run`` runs in this
process on the project's sample walk (known poses, a small grid; ``--workers 1`` trains in this process too).

Measured at 4ba89d6: ``sfm/cameras.json`` is read 8 times and ``sfm/stage.json`` 15 times (33 reads of stage
records in all) without the evaluation, 9 and 17 (53) with one fold. The bounds are the measure, not a goal yet."""

from __future__ import annotations

import builtins
import io
from collections import Counter
from pathlib import Path


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
    assert reads["sfm/cameras.json"] <= 9 and reads["sfm/stage.json"] <= 17, dict(reads)


def test_one_run_without_evaluation_reads_the_sfm_result_and_its_record_again_and_again(tmp_path, monkeypatch):
    _check(_run(tmp_path, monkeypatch, "--no-evaluate"))


def test_one_evaluated_run_reads_the_sfm_result_and_its_record_again_and_again(tmp_path, monkeypatch):
    _check(_run(tmp_path, monkeypatch, "--folds", "1", "--workers", "1", "--iters", "5", "--eval-size", "16",
                "--random-seeds", "1"))
