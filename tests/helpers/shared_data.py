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


def _find_calib_example() -> Path | None:
    """The real calibration photographs (../shared/data/calib_example), also from a git worktree.

    ``$STIFFMAP_SHARED_DATA`` may point at the shared data folder instead.
    """
    cands = [SHARED_DATA / "calib_example", REPO.parents[1] / "shared" / "data" / "calib_example"]
    if os.environ.get("STIFFMAP_SHARED_DATA"):
        cands.insert(0, Path(os.environ["STIFFMAP_SHARED_DATA"]) / "calib_example")
    for cand in cands:
        if (cand / "Image1.tif").is_file():
            return cand
    return None


class _SharedData:
    """Where the real photographs are; a test that uses them is skipped, with the reason, when absent."""

    def __init__(self, path: Path | None) -> None:
        self.path = path

    def _get(self) -> Path:
        if self.path is None:
            pytest.skip(
                "the real photographs ../shared/data/calib_example were not found next to the repository "
                "(set STIFFMAP_SHARED_DATA to the shared data folder)"
            )
        return self.path

    def __truediv__(self, other) -> Path:
        return self._get() / other

    def glob(self, pattern: str):
        return self._get().glob(pattern)

    def __fspath__(self) -> str:
        return str(self._get())


#: Bouguet's calibration example: 20 real 640x480 photographs of a 13x12 board, 30 mm squares.
CALIB_DIR = _SharedData(_find_calib_example())
