"""A report directory: write ``index.html``, the PNGs and ``data.json``; read ``data.json`` back."""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..errors import InputError
from ..io import atomic_write_bytes, atomic_write_text, dumps_json
from .data import ReportData

__all__ = ["write_report", "load_report_data", "report_files", "DATA_FILE", "INDEX_FILE"]

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
    # matplotlib and plotly load only here, when a report is written: `import stiffmap.report` stays light.
    from .html import build_html
    from .static_figures import ALL_FIGURES, png_bytes

    for name, build in ALL_FIGURES if png else ():
        fig = build(data)
        if fig is None:
            continue
        atomic_write_bytes(out / name, png_bytes(fig))
        written.append(name)
    for name, _ in ALL_FIGURES:
        if name not in written and (out / name).is_file():
            (out / name).unlink()
    atomic_write_text(out / DATA_FILE, dumps_json(data.to_dict(), indent=None) + "\n")
    index = out / INDEX_FILE
    atomic_write_text(index, build_html(data, written + [DATA_FILE]))
    return index


def load_report_data(path: str | os.PathLike) -> ReportData:
    """Read a JSON dump of :class:`ReportData` (as written beside a report as ``data.json``).

    Raises
    ------
    InputError
        Naming the file and the key that is missing or wrong.
    """
    p = Path(path)
    src = str(path)
    if not p.is_file():
        raise InputError("file not found" if not p.exists() else "not a file", source=src)
    try:
        obj = json.loads(p.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 JSON file", source=src) from None
    except json.JSONDecodeError as e:
        raise InputError(
            f"not valid JSON: {e.msg} at line {e.lineno}, column {e.colno}", source=src
        ) from None
    except RecursionError:
        raise InputError("not a usable JSON file: nested too deeply", source=src) from None
    except ValueError:  # an integer of thousands of digits
        raise InputError("not a usable JSON file: a number has thousands of digits", source=src) from None
    return ReportData.from_dict(obj, source=src)


def report_files(index: str | os.PathLike) -> list[str]:
    """Names of the files in the directory of a report's ``index.html`` (hidden ones left out), sorted."""
    return sorted(p.name for p in Path(index).parent.iterdir() if p.is_file() and not p.name.startswith("."))
