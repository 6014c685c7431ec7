"""``stiffmap run`` on any campaign: run it with its instrument, then export its tables.

:func:`run_and_export` is the one entry point: it reads ``campaign.toml``, finds what the
campaign measures with in the instruments' registry
(:func:`stiffmap.campaign.instruments.instrument_of`: a camera or a rig, through
:func:`stiffmap.campaign.runner.run_vision_campaign`; a sensor's recordings, through
:func:`stiffmap.campaign.sensor_runner.run_sensor_campaign`), runs it, then writes the
exports (:func:`stiffmap.campaign.export.export_tables`: CSV, Parquet and ``summary.json``
in ``exports/``). The report is the caller's to
write (:func:`stiffmap.report.campaign.write_campaign_report`): the report layer
sits above this one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from .export import export_tables
from .instruments import Instrument, RunOptions, instrument_of
from .paths import ALLOW_OUTSIDE_OPTION, own_file
from .robot import check_robot
from .runner import ProgressHook, RunSummary
from .sensor_runner import SensorCampaignResult
from .spec import SPEC_NAME, CampaignSpec, load_spec
from .store import DB_NAME, Store

__all__ = ["CampaignRun", "run_and_export", "campaign_root", "EXPORTS_DIR"]

#: The exports' directory in a campaign directory.
EXPORTS_DIR = "exports"


@dataclass(frozen=True)
class CampaignRun:
    """What :func:`run_and_export` did.

    Attributes
    ----------
    root : Path
        The campaign directory (resolved).
    spec : CampaignSpec
    instrument : Instrument
        What the campaign measures with (:mod:`stiffmap.campaign.instruments`).
    result : RunSummary or SensorCampaignResult
        The instrument's runner's summary.
    failures : list of str
        Every image, position, recording or step that failed (the run went on past them).
    """

    root: Path
    spec: CampaignSpec
    instrument: Instrument
    result: RunSummary | SensorCampaignResult
    failures: list[str]

    @property
    def vision(self) -> RunSummary | None:
        """The vision runner's summary (None for another instrument's campaign)."""
        return self.result if isinstance(self.result, RunSummary) else None

    @property
    def sensor(self) -> SensorCampaignResult | None:
        """The sensor runner's result (None for another instrument's campaign)."""
        return self.result if isinstance(self.result, SensorCampaignResult) else None

    @property
    def db(self) -> Path:
        """The results database."""
        return self.root / DB_NAME

    @property
    def exports(self) -> Path:
        """The exports' directory."""
        return self.root / EXPORTS_DIR

    def nothing_measured(self) -> str | None:
        """Why no item (a position, a recording) has a result, or None when one has.

        Returns
        -------
        str or None
            "no position could be measured (n failed): " and the first failures.
        """
        with Store(self.db) as store:
            rows = self.instrument.rows(store)
        if any(r.status == "ok" for r in rows):
            return None
        # The failures of files (images, recordings) first: they say why, the positions' follow.
        ranked = sorted(self.failures, key=lambda f: f.startswith(("position ", "model fit")))
        first = [f if len(f) <= 240 else f[:237] + "..." for f in ranked[:3]]
        more = f" (and {len(self.failures) - 3} more)" if len(self.failures) > 3 else ""
        what = self.instrument.item
        verb = "measured" if what == "position" else "analysed"
        return (
            f"no {what} could be {verb} ({len(rows)} failed): "
            + "; ".join(first or ["no failure recorded"])
            + more
        )


def run_and_export(
    campaign_dir: str | Path,
    *,
    spec: CampaignSpec | None = None,
    workers: int = 1,
    method: str = "compliance",
    progress: ProgressHook | None = None,
    allow_outside: bool = False,
    dask: str | None = None,
    send_images: bool = False,
) -> CampaignRun:
    """Run a campaign of either kind (resuming where it stopped), then export its tables.

    Parameters
    ----------
    campaign_dir : path
        Directory holding ``campaign.toml`` (or that file itself).
    spec : CampaignSpec, optional
        ``load_spec(campaign_dir)`` if already read.
    workers, method, progress, dask, send_images
        As :func:`~stiffmap.campaign.runner.run_vision_campaign` (campaigns measured by
        cameras; a sensor campaign is analysed in this process, without progress calls, and
        ``dask`` is ignored: its recordings are light).
    allow_outside : bool
        Let ``campaign.toml`` name files outside the campaign directory
        (:mod:`stiffmap.campaign.paths`).

    Returns
    -------
    CampaignRun

    Raises
    ------
    InputError
        When nothing can be done (found before any image or recording is measured: the
        whole ``[robot]`` section, :func:`~stiffmap.campaign.robot.check_robot`): no or bad
        campaign.toml, a robot file missing, unreadable or outside the campaign directory, an
        unknown tip frame, parameter or parameter to fit, camera file missing or
        malformed, a file named outside the campaign directory, a results database
        that is not one (:class:`~stiffmap.campaign.store.Store`).
    """
    root = campaign_root(campaign_dir)
    if spec is None:
        spec = load_spec(root)
    instrument = instrument_of(spec)
    check_robot(spec, root, allow_outside=allow_outside)  # the whole [robot] before any image
    out = own_file(root, DB_NAME, allow_outside=allow_outside)
    if out is not None:  # a run would write another folder's results database
        raise InputError(
            f"{out}: a run writes its results there; remove the link (or give {ALLOW_OUTSIDE_OPTION})",
            source=str(root),
        )
    options = RunOptions(workers, method, progress, allow_outside, dask, send_images)
    result, failures = instrument.run(root, spec, options)
    with Store(root / DB_NAME) as store:
        export_tables(store, root / EXPORTS_DIR, spec.name, failures, getattr(result, "info", ()))
    return CampaignRun(root=root, spec=spec, instrument=instrument, result=result, failures=failures)


def campaign_root(path: str | Path) -> Path:
    """The campaign directory of ``path`` (a directory, or its ``campaign.toml``), resolved.

    Raises
    ------
    InputError
        ``path`` is another file, or does not exist.
    """
    p = Path(path)
    if p.is_file() and p.name == SPEC_NAME:
        p = p.parent
    if not p.exists():
        raise InputError("no such campaign directory", source=str(p))
    if not p.is_dir():
        raise InputError(f"is a file, not a campaign directory (a folder holding {SPEC_NAME})", source=str(p))
    return p.resolve()
