"""Write a report directory: ``index.html`` (self-contained), the PNGs and ``data.json``."""

from __future__ import annotations

import os
from pathlib import Path

from ..io import atomic_write_bytes, atomic_write_text, dumps_json
from .data import ReportData

__all__ = ["write_report", "DATA_FILE", "INDEX_FILE"]

INDEX_FILE = "index.html"
#: The JSON dump of the data (``stiffmap report DATA.json`` re-renders from it).
DATA_FILE = "data.json"


def write_report(data: ReportData, out_dir: str | os.PathLike, *, png: bool = True) -> Path:
    """Write the report of ``data`` into ``out_dir`` and return the path of ``index.html``.

    Every file is written atomically (temporary file, then rename), the page
    last, so a reader never sees a half-written report. PNGs of an earlier
    report that this data no longer produces are removed.

    Parameters
    ----------
    data : ReportData
    out_dir : path-like
        Created when missing.
    png : bool
        Also write the matplotlib PNGs (figures for papers).
    """
    if not isinstance(data, ReportData):
        raise ValueError(f"data: expected a ReportData, got {type(data).__name__}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[str] = []
    if png:
        from .figures import ALL_FIGURES, png_bytes

        for name, build in ALL_FIGURES:
            fig = build(data)
            if fig is None:
                continue
            atomic_write_bytes(out / name, png_bytes(fig))
            written.append(name)
    from .figures import ALL_FIGURES as _names

    for name, _ in _names:
        if name not in written and (out / name).is_file():
            (out / name).unlink()
    atomic_write_text(out / DATA_FILE, dumps_json(data.to_dict(), indent=None) + "\n")
    from .html import build_html

    index = out / INDEX_FILE
    atomic_write_text(index, build_html(data, written + [DATA_FILE]))
    return index
