"""A run folder's COLMAP database, read from a copy.

pycolmap opens a database to read and write, and rewrites its bytes even when nothing is asked but a read (a
run folder's ``sfm/database.db`` had another SHA-1 after ``pycolmap.Database.open(...).close()``); the run
folder's record then says the file was changed since curate wrote it, and ``curate sfm --force`` refuses to
clear it. The research scripts that read a run's matches read a copy instead::

    with database_copy(run / "sfm" / "database.db") as db:
        ...
"""

from __future__ import annotations

import tempfile
from contextlib import contextmanager
from pathlib import Path

from curate.sfm.matching import copy_database


@contextmanager
def database_copy(db: Path):
    """A copy of the COLMAP database ``db`` (with what its write-ahead log holds) in a temporary folder,
    removed on leaving."""
    with tempfile.TemporaryDirectory(prefix="curate_db_") as tmp:
        yield copy_database(Path(db), Path(tmp) / "database.db")
