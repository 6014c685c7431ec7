"""Maps and reports: the self-contained HTML report (plotly) and PNG figures (matplotlib).

matplotlib and plotly are imported only here, and only when a report is
written: ``import stiffmap.report`` loads the data contract alone.

- :mod:`stiffmap.report.data`: :class:`ReportData` and its parts (the contract
  the campaign runner fills), with a JSON round trip.
- :mod:`stiffmap.report.writer`: :func:`write_report` writes ``out_dir/index.html``
  (self-contained, offline, one embedded plotly.js) + PNGs for papers +
  ``data.json``; :func:`load_report_data` reads ``data.json`` back.
- :mod:`stiffmap.report.html`: the page; :mod:`stiffmap.report.interactive_figures`:
  its plotly figures; :mod:`stiffmap.report.static_figures`: the matplotlib PNGs;
  :mod:`stiffmap.report.figure_data`: what both kinds of figure compute.
- :mod:`stiffmap.report.browser`: open a page in headless Chromium and collect
  console errors and network requests.
- :mod:`stiffmap.report.example`: complete example data (vision and sensor).
"""

from __future__ import annotations

from .data import (
    CalibrationData,
    CampaignInfo,
    Failure,
    LoadData,
    MeasuredStiffness,
    ModelMap,
    ModelStiffness,
    OrientationMap,
    Parameter,
    ReportData,
    SensorMap,
    SensorResults,
    TruthStiffness,
)
from .writer import load_report_data, write_report

__all__ = [
    "CalibrationData",
    "CampaignInfo",
    "Failure",
    "LoadData",
    "MeasuredStiffness",
    "ModelMap",
    "OrientationMap",
    "ModelStiffness",
    "Parameter",
    "ReportData",
    "SensorMap",
    "SensorResults",
    "TruthStiffness",
    "write_report",
    "load_report_data",
]
