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

from .export import export_tables
from .runner import ProgressHook, RunSummary, run_campaign
from .sensor_runner import SensorCampaignResult, run_sensor_campaign
from .spec import CampaignSpec, load_spec
from .store import DB_NAME, Store

__all__ = ["CampaignRun", "run_and_export", "EXPORTS_DIR"]

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


def run_and_export(
    campaign_dir: str | Path,
    *,
    spec: CampaignSpec | None = None,
    workers: int = 1,
    method: str = "compliance",
    progress: ProgressHook | None = None,
) -> CampaignRun:
    """Run a campaign of either kind (resuming where it stopped), then export its tables.

    Parameters
    ----------
    campaign_dir : path
        Directory holding ``campaign.toml``.
    spec : CampaignSpec, optional
        ``load_spec(campaign_dir)`` if already read.
    workers, method, progress
        As :func:`~stiffmap.campaign.runner.run_campaign` (vision campaigns; a sensor
        campaign is analysed in this process, without progress calls).

    Returns
    -------
    CampaignRun

    Raises
    ------
    InputError
        When nothing can be done: no or bad campaign.toml, camera file missing or
        malformed.
    """
    if spec is None:
        spec = load_spec(campaign_dir)
    root = Path(campaign_dir).resolve()
    vision = sensor = None
    if spec.kind == "vision":
        vision = run_campaign(root, workers=workers, method=method, progress=progress)
        failures = vision.failures
    else:
        with Store(root / DB_NAME) as store:
            sensor = run_sensor_campaign(root, spec, store)
        failures = sensor.failures or []
    with Store(root / DB_NAME) as store:
        export_tables(store, root / EXPORTS_DIR, spec.name, failures)
    return CampaignRun(root=root, spec=spec, vision=vision, sensor=sensor, failures=failures)
