"""Issue 61, items 2 and 3: up to date means the files are there, and a stage folder's files of the user's stay.

A stage is skipped only when its record and the files it wrote agree: a deleted output is written again; a file
the user changed is kept and named (never removed, never written over); a re-run, or the resume of a killed
stage, removes only what curate wrote and says what it kept. Every case on a small imported run folder, copied
from one built once."""

from __future__ import annotations

import json
import os
import shutil

import pytest

from curate.cli import main
from curate.core.transforms_json import write_transforms

from test_export import ring, write_photos

FAST = ["--no-evaluate", "--method", "medoids", "--budget", "4", "--res", "8", "--triangulate", "off"]


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """(capture, run folder): 12 tiny photos with their poses, curated once without evaluation."""
    base = tmp_path_factory.mktemp("finished")
    cams = ring(12)
    write_photos(base / "cap", cams)
    write_transforms(base / "cap" / "transforms.json", cams)
    run = base / "run"
    assert main(["run", str(base / "cap" / "photos"), "--poses", str(base / "cap" / "transforms.json"),
                 "--out", str(run), *FAST]) == 0
    return base / "cap", run


@pytest.fixture()
def run(finished, tmp_path):
    """A copy of the finished run folder (its inputs are the module's capture)."""
    dst = tmp_path / "run"
    shutil.copytree(finished[1], dst, symlinks=True)
    return dst


@pytest.fixture()
def said(capsys, caplog):
    """``said()``: (stdout, stderr and the log's lines) since the last call (the CLI logs its warnings to
    stderr; under pytest the log is captured apart)."""
    def read() -> tuple[str, str]:
        out, err = capsys.readouterr()
        text = caplog.text
        caplog.clear()
        return out, err + text
    return read


def one_error(err: str) -> bool:
    """Exactly one ``curate ...: error:`` line, no trace."""
    return sum(": error: " in ln for ln in err.splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize("victim", ["images/*", "transforms.json", "sparse/0/images.bin", "sparse_pc.ply"])
def test_an_export_file_the_user_deleted_is_written_again(run, said, victim):
    """The user deletes an exported image, transforms.json or the model: `curate export RUN` with the same
    options said "skipped (unchanged)" and left the export incomplete; it exports again and says why."""
    exp = run / "export"
    if victim == "sparse_pc.ply" and not (exp / victim).exists():       # no points: no ply to delete
        victim = "images.txt"
    p = sorted(exp.glob(victim))[0]
    want = p.read_bytes()
    p.unlink()
    said()
    assert main(["export", str(run)]) == 0
    out, err = said()
    assert p.read_bytes() == want
    assert "export     skipped" not in out and f"{p.relative_to(exp)} is missing" in err


def test_every_stage_writes_a_missing_output_again(run, finished, said):
    """Up to date means the files are there, for every stage: a `curate run` with the same options rewrites the
    SfM stage's cameras, the occupancy grid and the selection the user deleted; what is there is not redone."""
    cap = finished[0]
    gone = [run / "sfm" / "cameras.json", run / "occupancy" / "occupancy.npz", run / "select" / "selection.json"]
    cameras, chosen = gone[0].read_bytes(), json.loads(gone[2].read_text())["chosen"]
    for p in gone:
        p.unlink()
    said()
    assert main(["run", str(cap / "photos"), "--poses", str(cap / "transforms.json"), "--out", str(run), *FAST]) == 0
    out = said()[0]
    assert all(p.is_file() for p in gone) and gone[0].read_bytes() == cameras
    assert json.loads(gone[2].read_text())["chosen"] == chosen
    assert "skipped" not in "".join(ln for ln in out.splitlines() if ln.startswith(("sfm", "occupancy", "select")))
    selection = run / "select" / "selection.json"
    selection.unlink()
    assert main(["export", str(run)]) == 2            # a stage command names the missing file and what writes it
    err = said()[1]
    assert f"{selection} is missing" in err and f"curate select {run}" in err and one_error(err)


def test_a_file_the_user_changed_is_kept_and_named(run, said):
    """An edit of the export's transforms.json or export.json: with the same options the export stays as it is
    and a line names the file; an export that must be redone (another mode) refuses, naming it, and removes
    nothing. Before, the export.json edit was discarded."""
    exp = run / "export"
    for name, mode in (("transforms.json", "copy"), ("export.json", "link")):
        p = exp / name
        edited = p.read_text().replace("{", "{\n", 1)
        p.write_text(edited)
        before = {q: q.read_bytes() for q in exp.rglob("*") if q.is_file()}
        said()
        assert main(["export", str(run)]) == 0
        err = said()[1]
        assert f"{name} changed since curate wrote it: kept as you left it" in err
        assert main(["export", str(run), "--mode", mode]) == 2
        err = said()[1]
        assert f"{p} was changed since curate" in err and one_error(err)
        assert {q: q.read_bytes() for q in exp.rglob("*") if q.is_file()} == before
        p.unlink()                                   # the user moves it out: the export is whole again
        assert main(["export", str(run)]) == 0 and p.read_text() != edited


def test_the_users_files_in_a_stage_folder_survive_reruns_and_are_named(run, said):
    """export/notes.txt and select/my-selection-notes.txt were deleted by a re-run; they stay, and the re-run
    says it kept them."""
    notes = {run / "export" / "notes.txt": b"shoot the hall again\n",
             run / "select" / "my-selection-notes.txt": b"frame 3 is blurred\n"}
    for p, data in notes.items():
        p.write_bytes(data)
    said()
    assert main(["export", str(run), "--force"]) == 0
    assert main(["select", str(run), "--budget", "5"]) == 0        # the selection and the export redone
    err = said()[1]
    assert all(p.read_bytes() == data for p, data in notes.items())
    assert "kept 1 file(s) of yours there (notes.txt)" in err
    assert "kept 1 file(s) of yours there (my-selection-notes.txt)" in err
    assert len(json.loads((run / "select" / "selection.json").read_text())["chosen"]) == 5
    assert len(list((run / "export" / "images").iterdir())) == 5
    for s in ("select", "export"):                   # never listed as curate's
        assert not any("notes" in f for f in json.loads((run / s / "stage.json").read_text())["files"])


def test_a_killed_stage_resumes_without_deleting_the_users_files(run, finished, said):
    """A stage killed half-way leaves its folder with curate's partial files and no record; the user then puts
    a file there (export/README-mine.txt after a SIGKILL during the export). The resumed run removed it; it
    now removes only the names the stage writes and keeps the README."""
    cap = finished[0]
    for stage in ("select", "export"):
        (run / stage / "stage.json").unlink()       # what a SIGKILL before the record leaves
    (run / "export" / "export.json").unlink()      # (the export writes its own manifest last)
    (run / "export" / "transforms.json").write_text("{half")
    mine = {run / "export" / "README-mine.txt": b"mine\n", run / "select" / "my-selection-notes.txt": b"mine too\n"}
    for p, data in mine.items():
        p.write_bytes(data)
    said()
    assert main(["run", str(cap / "photos"), "--poses", str(cap / "transforms.json"), "--out", str(run), *FAST]) == 0
    err = said()[1]
    assert all(p.read_bytes() == data for p, data in mine.items())
    assert "README-mine.txt" in err and "my-selection-notes.txt" in err
    assert json.loads((run / "export" / "transforms.json").read_text())["frames"]


def test_a_file_of_the_user_where_the_stage_writes_is_never_written_over(run, said):
    """A photo the user dropped into export/images (a name the export writes) still stops a re-export."""
    mine = run / "export" / "images" / "my_edit.jpg"
    mine.write_bytes(b"the user's")
    said()
    assert main(["export", str(run), "--force"]) == 2
    err = said()[1]
    assert "my_edit.jpg" in err and "did not write" in err and mine.read_bytes() == b"the user's"


def test_an_unreadable_edited_transforms_json_is_not_replaced(run, said, unprivileged):
    """The user edits the export's transforms.json, then makes it unreadable (chmod 000): the file could not be
    checked and was replaced by a new export; curate cannot prove it is its own, so it keeps it and says so."""
    p = run / "export" / "transforms.json"
    p.write_text(p.read_text().replace("{", "{ ", 1))
    edited = p.read_bytes()
    os.chmod(p, 0)
    with unprivileged(run):
        said()
        assert main(["export", str(run), "--mode", "copy"]) == 2
        err = said()[1]
    os.chmod(p, 0o644)
    assert p.read_bytes() == edited and f"{p} was changed since curate" in err


def test_an_unreadable_export_folder_is_a_one_line_error_naming_it(run, said, unprivileged):
    """`chmod 000 RUN/export` gave an internal error; it is one line naming the folder, exit 2."""
    exp = run / "export"
    os.chmod(exp, 0)
    try:
        with unprivileged(run):
            said()
            assert main(["export", str(run), "--mode", "copy"]) == 2
            err = said()[1]
    finally:
        os.chmod(exp, 0o755)
    assert one_error(err) and str(exp) in err and "internal error" not in err


def test_a_report_page_the_user_changed_is_kept_and_named(run, said):
    """The report is redone by every command; a report.html the user annotated was written over. It is kept, a
    line names it, and report.json is current; once the user moves it out, the page is written again."""
    page = run / "report.html"
    page.write_text(page.read_text().replace("<body>", "<body><p>my notes</p>", 1))
    edited = page.read_bytes()
    said()
    assert main(["select", str(run), "--budget", "5"]) == 0
    err = said()[1]
    assert page.read_bytes() == edited and f"{page} was changed since curate wrote it" in err
    assert json.loads((run / "report.json").read_text())["budget"] == 5
    page.unlink()
    assert main(["report", str(run)]) == 0 and b"my notes" not in page.read_bytes()
