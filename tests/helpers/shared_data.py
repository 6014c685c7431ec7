"""Where the real data beside the repository are (../shared/data), also from a git worktree.

A test that needs them is skipped, with the reason, when they are absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

#: The repository's root (tests/helpers/ is two levels below it).
REPO = Path(__file__).resolve().parents[2]
#: Real data nobody on this project made (see ../shared/data/*/README.md).
SHARED_DATA = REPO.parent / "shared" / "data"


def _find_shared(sub: str, probe: str) -> Path | None:
    """A folder of ../shared/data holding ``probe``, also from a git worktree.

    ``$STIFFMAP_SHARED_DATA`` may point at the shared data folder instead.
    """
    cands = [SHARED_DATA / sub, REPO.parents[1] / "shared" / "data" / sub]
    if os.environ.get("STIFFMAP_SHARED_DATA"):
        cands.insert(0, Path(os.environ["STIFFMAP_SHARED_DATA"]) / sub)
    for cand in cands:
        if (cand / probe).is_file():
            return cand
    return None


class _SharedData:
    """Where the real photographs are; a test that uses them is skipped, with the reason, when absent."""

    def __init__(self, path: Path | None, name: str = "calib_example") -> None:
        self.path = path
        self.name = name

    def _get(self) -> Path:
        if self.path is None:
            pytest.skip(
                f"the real photographs ../shared/data/{self.name} were not found next to the repository "
                "(set STIFFMAP_SHARED_DATA to the shared data folder)"
            )
        return self.path

    def __truediv__(self, other) -> Path:
        return self._get() / other

    def glob(self, pattern: str):
        return self._get().glob(pattern)

    def __fspath__(self) -> str:
        return str(self._get())

    __str__ = __fspath__


#: Bouguet's calibration example: 20 real 640x480 photographs of a 13x12 board, 30 mm squares.
CALIB_DIR = _SharedData(_find_shared("calib_example", "Image1.tif"))

#: Real photographs of 9x6 boards from three more cameras (../shared/data/real/README.md), with
#: the number of views where OpenCV 5.0's findChessboardCorners / findChessboardCornersSB find the
#: board, as that README reports them.
REAL_SETS = {
    "udacity": (_SharedData(_find_shared("real/udacity", "calibration1.jpg"), "real/udacity"), 17, 18),
    "christos": (_SharedData(_find_shared("real/christos", "0.jpg"), "real/christos"), 25, 19),
    "greninja": (_SharedData(_find_shared("real/greninja", "1.jpg"), "real/greninja"), 18, 15),
}
