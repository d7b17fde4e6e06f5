"""Options of the export (:class:`ExportConfig`): ``curate run --export-mode/--undistort/--downscale/...`` and
``curate export RUN --mode/...`` bind their flags to these fields."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

ExportMode = Literal["hardlink", "copy", "link"]
MODES = get_args(ExportMode)
"""``ExportConfig.mode`` choices."""
Undistort = Literal["auto", "off"]
UNDISTORT = get_args(Undistort)
"""``ExportConfig.undistort`` choices."""
DOWNSCALES = (2, 4, 8)
"""``ExportConfig.downscale`` factors nerfstudio (``--downscale-factor``) and 3DGS (``-r``) know."""


@dataclass(frozen=True)
class ExportConfig:
    """How the chosen subset is written (``RUN/export``)."""

    mode: ExportMode = "hardlink"
    """How the photos enter ``images/``: 'hardlink' (hard links to the originals where the file system allows,
    copies elsewhere: the export alone carries every image, for tar or rsync to a training machine, and takes no
    space on the same disk), 'copy', or 'link' (symbolic links to the originals: nothing is copied, and the
    export is valid only beside them)."""
    undistort: Undistort = "auto"
    """'auto': where a camera has lens distortion (a phone video's radial distortion), the images are undistorted
    and the cameras written as PINHOLE (COLMAP's undistorter), as 3D Gaussian splatting's loader requires; 'off':
    the original photos with their distorted cameras (OPENCV in transforms.json)."""
    keep_distorted: bool = False
    """With undistortion: also keep the original photos and their distorted model in ``distorted/images`` and
    ``distorted/sparse/0``."""
    downscale: tuple[int, ...] = ()
    """Also write the images downscaled by these factors (2, 4 or 8), each into a folder named images and the
    factor beside the images folder (e.g. --downscale 2,4), as nerfstudio's --downscale-factor reads them."""
    min_track: int = 2
    """A sparse point is kept in ``sparse/0`` when at least this many chosen images observe it."""

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"export mode must be one of {MODES}, got {self.mode!r}")
        if self.undistort not in UNDISTORT:
            raise ValueError(f"--undistort must be one of {UNDISTORT}, got {self.undistort!r}")
        bad = [f for f in self.downscale if f not in DOWNSCALES]
        if bad or len(set(self.downscale)) != len(self.downscale):
            raise ValueError(f"--downscale takes distinct factors among {DOWNSCALES} (e.g. 2,4), got "
                             f"{','.join(map(str, self.downscale))}")
        if not isinstance(self.min_track, int) or self.min_track < 1:
            raise ValueError("min_track must be >= 1")
