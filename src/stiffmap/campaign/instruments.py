"""The registry of instruments: what a campaign measures with, one entry each.

An instrument (:class:`Instrument`) is what a campaign's ``campaign.toml`` measures with --
one calibrated camera (``[camera]``), a rig of several (``[cameras]``), a displacement
sensor's recordings (``[sensor]``) -- and what ``stiffmap run`` does with it: its runner
(images -> K per position, recordings -> static errors), what it measures, and which of its
results say that something was measured. :func:`~stiffmap.campaign.run.run_and_export`, the
command line and the report read the entry of a campaign (:func:`instrument_of`) instead of
branching on its kind. Adding an instrument (the measured points of a tracker next) is one
entry (:func:`register_instrument`) and its runner (CONTRIBUTING.md, "an instrument").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .runner import ProgressHook, run_vision_campaign
from .sensor_runner import check_recording_paths, run_sensor_campaign
from .spec import CampaignSpec
from .store import DB_NAME, Store

__all__ = [
    "RunOptions",
    "Instrument",
    "INSTRUMENTS",
    "register_instrument",
    "instrument_of",
    "STIFFNESS",
    "STATIC_ERROR",
]

#: What an instrument's campaign measures: K per position, or static errors per recording.
STIFFNESS = "stiffness"
STATIC_ERROR = "static_error"


@dataclass(frozen=True)
class RunOptions:
    """What ``stiffmap run`` passes to any instrument's runner (each uses what applies to it).

    ``workers``, ``method``, ``progress``, ``dask`` and ``send_images`` as
    :func:`~stiffmap.campaign.runner.run_vision_campaign`; ``allow_outside`` lets
    campaign.toml name files outside the campaign directory.
    """

    workers: int = 1
    method: str = "compliance"
    progress: ProgressHook | None = None
    allow_outside: bool = False
    dask: str | None = None
    send_images: bool = False


@dataclass(frozen=True)
class Instrument:
    """One instrument a campaign measures with.

    Attributes
    ----------
    name : str
        ``camera``, ``rig``, ``sensor``.
    kind : str
        The campaign's ``kind`` in campaign.toml (``vision``, ``sensor``).
    section : str
        Its campaign.toml section (``camera``, ``cameras``, ``sensor``).
    summary : str
        One line.
    applies : callable
        ``applies(spec) -> bool``: a campaign measured with it.
    run : callable
        ``run(root, spec, options: RunOptions) -> (result, failures)``: measure (resuming),
        derive, fit the model, write the database (the exports are the caller's).
    measures : str
        :data:`STIFFNESS` (K per position) or :data:`STATIC_ERROR` (per recording).
    item : str
        What one of its results is about, for messages: ``position``, ``recording``.
    rows : callable
        ``rows(store)``: the results whose ``status`` says whether an item was measured.
    per_image : bool
        Its work goes image by image (a progress bar counts images).
    """

    name: str
    kind: str
    section: str
    summary: str
    applies: Callable[[CampaignSpec], bool]
    run: Callable[[Path, CampaignSpec, RunOptions], tuple[Any, list[str]]]
    measures: str
    item: str
    rows: Callable[[Store], list]
    per_image: bool = False


#: Every instrument, by name, in the order :func:`instrument_of` tries them.
INSTRUMENTS: dict[str, Instrument] = {}


def register_instrument(instrument: Instrument, *, replace: bool = False) -> Instrument:
    """Add ``instrument`` to :data:`INSTRUMENTS` (ValueError when its name is taken)."""
    if instrument.name in INSTRUMENTS and not replace:
        raise ValueError(f"an instrument {instrument.name!r} is registered already")
    INSTRUMENTS[instrument.name] = instrument
    return instrument


def instrument_of(spec: CampaignSpec) -> Instrument:
    """The instrument a campaign measures with (the first entry that applies).

    Raises
    ------
    ValueError
        No instrument applies (a spec built without validation).
    """
    for inst in INSTRUMENTS.values():
        if inst.applies(spec):
            return inst
    raise ValueError(f"no instrument measures a campaign of kind {spec.kind!r}")


def _run_vision(root: Path, spec: CampaignSpec, o: RunOptions):
    summary = run_vision_campaign(
        root,
        workers=o.workers,
        method=o.method,
        progress=o.progress,
        allow_outside=o.allow_outside,
        dask=o.dask,
        send_images=o.send_images,
    )
    return summary, summary.failures


def _run_sensor(root: Path, spec: CampaignSpec, o: RunOptions):
    check_recording_paths(root, spec, allow_outside=o.allow_outside)  # before the database is made
    with Store(root / DB_NAME) as store:
        result = run_sensor_campaign(root, spec, store, allow_outside=o.allow_outside)
    return result, result.failures or []


_VISION = "vision"

register_instrument(
    Instrument(
        name="rig",
        kind=_VISION,
        section="cameras",
        summary="several calibrated cameras (rig.json): board poses fused in the rig frame -> K per position",
        applies=lambda spec: spec.kind == _VISION and spec.cameras is not None,
        run=_run_vision,
        measures=STIFFNESS,
        item="position",
        rows=lambda store: store.stiffness_rows(),
        per_image=True,
    )
)
register_instrument(
    Instrument(
        name="camera",
        kind=_VISION,
        section="camera",
        summary="one calibrated camera (camera.json): board poses -> displacements -> K per position",
        applies=lambda spec: spec.kind == _VISION,
        run=_run_vision,
        measures=STIFFNESS,
        item="position",
        rows=lambda store: store.stiffness_rows(),
        per_image=True,
    )
)
register_instrument(
    Instrument(
        name="sensor",
        kind="sensor",
        section="sensor",
        summary="a displacement sensor's recordings of stepped loads -> static error per recording",
        applies=lambda spec: spec.kind == "sensor",
        run=_run_sensor,
        measures=STATIC_ERROR,
        item="recording",
        rows=lambda store: store.sensor_result_rows(),
    )
)
