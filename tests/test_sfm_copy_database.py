"""curate.sfm.matching.copy_database: a run's database copied with what its write-ahead log still holds."""

from __future__ import annotations

import shutil
import sqlite3

from curate.sfm.matching import copy_database


def test_a_copy_holds_the_rows_the_log_has_not_yet_written_back(tmp_path):
    """A database in WAL mode whose tables and rows are only in its log (a connection still open, nothing
    checkpointed): a file copy loses them, copy_database keeps them and returns where it wrote."""
    src = tmp_path / "database.db"
    con = sqlite3.connect(src)
    con.execute("PRAGMA journal_mode=WAL")
    con.execute("PRAGMA wal_autocheckpoint=0")
    con.execute("CREATE TABLE matches (pair_id INTEGER PRIMARY KEY, rows INTEGER)")
    con.commit()
    con.executemany("INSERT INTO matches VALUES (?, ?)", [(i, 10 * i) for i in range(50)])
    con.commit()                              # in the log only, while con is open
    assert (tmp_path / "database.db-wal").stat().st_size > 0

    plain = tmp_path / "plain.db"
    shutil.copy2(src, plain)
    try:
        lost = sqlite3.connect(plain).execute("SELECT count(*) FROM matches").fetchone()[0] == 0
    except sqlite3.OperationalError:          # no such table: the file holds none of it
        lost = True
    assert lost

    dst = tmp_path / "copy.db"
    assert copy_database(src, dst) == dst
    got = sqlite3.connect(dst).execute("SELECT count(*), sum(rows) FROM matches").fetchone()
    assert got == (50, 10 * sum(range(50)))
    con.close()


def test_copying_a_finished_runs_database_leaves_its_folder_as_it_was(tmp_path):
    """A database in WAL mode that no connection holds (a finished run's): the copy has every row, and nothing
    is written beside the original (a read-only reader left an empty log and its index there, files the run
    folder's record does not list)."""
    run = tmp_path / "sfm"
    run.mkdir()
    src = run / "database.db"
    con = sqlite3.connect(src)
    con.execute("PRAGMA journal_mode=WAL")
    con.execute("CREATE TABLE matches (pair_id INTEGER PRIMARY KEY, rows INTEGER)")
    con.executemany("INSERT INTO matches VALUES (?, ?)", [(i, 3 * i) for i in range(20)])
    con.commit()
    con.close()                               # the last connection: the log written back and removed
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    assert list(before) == ["database.db"]
    dst = copy_database(src, tmp_path / "copy.db")
    got = sqlite3.connect(dst).execute("SELECT count(*), sum(rows) FROM matches").fetchone()
    assert got == (20, 3 * sum(range(20)))
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before
