"""Maps and reports: matplotlib figures and the self-contained HTML report.

matplotlib and plotly are imported only here, and only when a report is
written: ``import stiffmap.report`` loads the data contract alone.

- :mod:`stiffmap.report.data`: :class:`ReportData` and its parts (the contract
  the campaign runner fills), with a JSON round trip.
- :func:`write_report`: ``out_dir/index.html`` (self-contained, offline, one
  embedded plotly.js) + PNGs for papers + ``data.json``.
- :mod:`stiffmap.report.browser`: open a page in headless Chromium and collect
  console errors and network requests.
- :mod:`stiffmap.report.example`: complete example data (vision and sensor).
"""

from __future__ import annotations

import os
from pathlib import Path

from .data import (
    CalibrationData,
    CampaignInfo,
    Failure,
    LoadData,
    MeasuredStiffness,
    ModelMap,
    ModelStiffness,
    Parameter,
    ReportData,
    SensorMap,
    SensorResults,
    TruthStiffness,
)

__all__ = [
    "CalibrationData",
    "CampaignInfo",
    "Failure",
    "LoadData",
    "MeasuredStiffness",
    "ModelMap",
    "ModelStiffness",
    "Parameter",
    "ReportData",
    "SensorMap",
    "SensorResults",
    "TruthStiffness",
    "write_report",
    "load_report_data",
]


def write_report(data: ReportData, out_dir: str | os.PathLike, *, png: bool = True) -> Path:
    """Write ``out_dir/index.html``, the PNGs and ``data.json``; return the page's path.

    See :func:`stiffmap.report.writer.write_report`.
    """
    from .writer import write_report as _write

    return _write(data, out_dir, png=png)


def load_report_data(path: str | os.PathLike) -> ReportData:
    """Read a JSON dump of :class:`ReportData` (as written beside a report as ``data.json``).

    Raises
    ------
    InputError
        Naming the file and the key that is missing or wrong.
    """
    import json

    from ..errors import InputError

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
    return ReportData.from_dict(obj, source=src)
