"""Where each result lies in a run folder: the one spelling of its layout (docs/architecture.md, "The run folder").

``RunPaths(run_dir).cameras`` is ``RUN/sfm/cameras.json``; a stage's folder is named as the stage
(:data:`curate.core.graph.STAGES`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class RunPaths:
    """The files and folders of one run folder."""

    root: Path
    """The run folder."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    def stage(self, name: str) -> Path:
        """A stage's folder (``RUN/<name>``)."""
        return self.root / name

    def record(self, name: str) -> Path:
        """A stage's record (``RUN/<name>/stage.json``), written last: it says the stage finished."""
        return self.root / name / "stage.json"

    @property
    def run_json(self) -> Path:
        """The run's resolved options and inputs."""
        return self.root / "run.json"

    @property
    def sfm(self) -> Path:
        return self.root / "sfm"

    @property
    def cameras(self) -> Path:
        """The registered cameras (OpenCV camera-to-world)."""
        return self.sfm / "cameras.json"

    @property
    def images_json(self) -> Path:
        """Every input photo: kept, dropped or skipped, and why."""
        return self.sfm / "images.json"

    @property
    def working_images(self) -> Path:
        """SfM's working copies of the photos."""
        return self.sfm / "images"

    @property
    def occupancy(self) -> Path:
        return self.root / "occupancy"

    @property
    def occupancy_npz(self) -> Path:
        """The selection's node grid."""
        return self.occupancy / "occupancy.npz"

    @property
    def nodes(self) -> Path:
        """The nodes and what the chosen photos see of each (written by the select stage)."""
        return self.select / "nodes.npz"

    @property
    def budget(self) -> Path:
        return self.root / "budget"

    @property
    def budget_json(self) -> Path:
        """The budget measured on the capture (``--budget auto``, evaluated)."""
        return self.budget / "budget.json"

    @property
    def select(self) -> Path:
        return self.root / "select"

    @property
    def selection(self) -> Path:
        """The chosen photos and how."""
        return self.select / "selection.json"

    @property
    def evaluate(self) -> Path:
        return self.root / "evaluate"

    @property
    def summary(self) -> Path:
        """The evaluation's figures."""
        return self.evaluate / "summary.json"

    @property
    def gt(self) -> Path:
        """The held-out photos at the evaluation's size."""
        return self.evaluate / "gt"

    @property
    def export(self) -> Path:
        return self.root / "export"

    @property
    def export_json(self) -> Path:
        """What the export wrote."""
        return self.export / "export.json"

    @property
    def export_transforms(self) -> Path:
        """The export's transforms.json."""
        return self.export / "transforms.json"

    @property
    def report_json(self) -> Path:
        return self.root / "report.json"

    @property
    def report_html(self) -> Path:
        return self.root / "report.html"

    @property
    def parts(self) -> Path:
        """The other models of a capture that split, each a run folder."""
        return self.root / "parts"


def inside(path: str | Path, root: str | Path) -> bool:
    """Whether ``path`` stays in the folder ``root``: it lies there by name (``..`` resolved without following
    links), and with every link on the way followed it still lies there or is a photo (a file with an image
    extension: a folder of links to the photos, as a batch or a dataset tool makes, is the user's capture; a
    link to ``/etc/passwd`` or to a folder of other files is not)."""
    import os
    p, r = Path(os.path.abspath(path)), Path(os.path.abspath(root))
    if not p.is_relative_to(r):
        return False
    real = Path(os.path.realpath(p))
    if real.is_relative_to(Path(os.path.realpath(r))):
        return True
    from curate.core.images import IMAGE_EXTS
    return real.suffix.lower() in IMAGE_EXTS and real.is_file()


def within_capture(root: str | Path, name: str, source: str | Path, entry: str) -> Path:
    """``root / name``: the file a pose file's entry names, resolved against the capture's folder ``root``.

    A pose file says which photo each pose describes; a name that leaves ``root`` (``..``, an absolute path
    elsewhere, a link to something outside that is not a photo: :func:`inside`) would make curate read, and
    export, any file the pose file points at (``../../../etc/passwd``). ``ValueError`` naming the pose file
    ``source`` and the ``entry`` (``frame 3``, ``image 12``) when it leaves; nothing is opened here."""
    import os
    p = Path(name)
    full = p if p.is_absolute() else Path(root) / p
    lexical = Path(os.path.abspath(full)).is_relative_to(Path(os.path.abspath(root)))
    if inside(full, root) or (lexical and not full.exists()):   # a link to nothing reads nothing: "missing" later
        return full
    why = (f"a link that leads to {os.path.realpath(full)}, not a photo" if lexical else
           "an absolute path elsewhere" if p.is_absolute() else "a path that climbs out of it")
    raise ValueError(f"{source}: {entry} names {name!r}, outside the capture's folder {root} ({why}); curate "
                     "reads only photos inside it: give the photo folder (curate run PHOTOS --poses ...), or "
                     "copy the photos into it")
