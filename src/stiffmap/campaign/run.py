"""``stiffmap run`` on a campaign of either kind: run it, then export its tables.

:func:`run_and_export` reads the campaign's kind from ``campaign.toml`` and runs
it with the vision runner (:func:`stiffmap.campaign.runner.run_campaign`) or
the sensor runner (:func:`stiffmap.campaign.sensor_runner.run_sensor_campaign`),
then writes the exports (:func:`stiffmap.campaign.export.export_tables`: CSV,
Parquet and ``summary.json`` in ``exports/``). The report is the caller's to
write (:func:`stiffmap.report.campaign.write_campaign_report`): the report layer
sits above this one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from .export import export_tables
from .runner import ProgressHook, RunSummary, run_campaign
from .sensor_runner import SensorCampaignResult, check_recording_paths, run_sensor_campaign
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
    vision : RunSummary or None
        The vision runner's summary (None for a sensor campaign).
    sensor : SensorCampaignResult or None
        The sensor runner's result (None for a vision campaign).
    failures : list of str
        Every image, position, recording or step that failed (the run went on past them).
    """

    root: Path
    spec: CampaignSpec
    vision: RunSummary | None
    sensor: SensorCampaignResult | None
    failures: list[str]

    @property
    def db(self) -> Path:
        """The results database."""
        return self.root / DB_NAME

    @property
    def exports(self) -> Path:
        """The exports' directory."""
        return self.root / EXPORTS_DIR

    def nothing_measured(self) -> str | None:
        """Why no position (vision) or recording (sensor) has a result, or None when one has.

        Returns
        -------
        str or None
            "no position could be measured (n failed): " and the first failures.
        """
        with Store(self.db) as store:
            if self.spec.kind == "vision":
                rows = store.stiffness_rows()
                what = "position"
            else:
                rows = store.sensor_result_rows()
                what = "recording"
        if any(r["status"] == "ok" for r in rows):
            return None
        # The failures of files (images, recordings) first: they say why, the positions' follow.
        ranked = sorted(self.failures, key=lambda f: f.startswith(("position ", "model fit")))
        first = [f if len(f) <= 240 else f[:237] + "..." for f in ranked[:3]]
        more = f" (and {len(self.failures) - 3} more)" if len(self.failures) > 3 else ""
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
        As :func:`~stiffmap.campaign.runner.run_campaign` (vision campaigns; a sensor
        campaign is analysed in this process, without progress calls, and ``dask`` is
        ignored: its recordings are light).
    allow_outside : bool
        Let ``campaign.toml`` name files outside the campaign directory
        (:mod:`stiffmap.campaign.paths`).

    Returns
    -------
    CampaignRun

    Raises
    ------
    InputError
        When nothing can be done: no or bad campaign.toml, camera file missing or
        malformed, a file named outside the campaign directory, a results database
        that is not one (:class:`~stiffmap.campaign.store.Store`).
    """
    root = campaign_root(campaign_dir)
    if spec is None:
        spec = load_spec(root)
    vision = sensor = None
    if spec.kind == "vision":
        vision = run_campaign(
            root,
            workers=workers,
            method=method,
            progress=progress,
            allow_outside=allow_outside,
            dask=dask,
            send_images=send_images,
        )
        failures = vision.failures
    else:
        check_recording_paths(root, spec, allow_outside=allow_outside)  # before the database is made
        with Store(root / DB_NAME) as store:
            sensor = run_sensor_campaign(root, spec, store, allow_outside=allow_outside)
        failures = sensor.failures or []
    with Store(root / DB_NAME) as store:
        export_tables(store, root / EXPORTS_DIR, spec.name, failures)
    return CampaignRun(root=root, spec=spec, vision=vision, sensor=sensor, failures=failures)


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
