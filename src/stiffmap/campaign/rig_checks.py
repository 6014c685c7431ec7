"""A rig campaign's checks over all its image sets: what ``pose --rig`` says of one, for them all.

A campaign with ``[cameras]`` measures each image set (one image per camera) as the boards'
fused poses in the rig frame (:mod:`stiffmap.vision.fuse`). One image set measured by fewer
cameras, or whose cameras disagree, still gives a pose; over a whole campaign that hides two
mistakes that make every stiffness wrong without an error:

- a camera that measured nothing (all its images missing, truncated, of another size, folders):
  the results are the other cameras' alone, and a camera that measured only some image sets
  mixes displacements measured by different sets of cameras;
- cameras that disagree (a ``rig.json`` of another rig, its cameras' names swapped, a camera
  moved or turned since the rig was calibrated): the fused poses, and so the displacements
  and K, are wrong by far more than their uncertainty.

:func:`rig_failures` reads what each camera gave for every image set (the ``per_camera``
column of the measurements, :func:`stiffmap.campaign.measure.measure_position`) and words
the first and the second as failures of the run (``stiffmap run`` then exits 1,
``summary.json`` lists them); a camera that missed some image sets only is a note (a warning
line; those sets were measured by the others, as ``pose --rig`` measures one).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from typing import Any

__all__ = ["rig_failures"]


def _cameras_of(per_camera: Any) -> list[dict] | None:
    """A ``per_camera`` value (its JSON text or the list) as a list (None: not a rig's, unreadable)."""
    cams = per_camera
    if isinstance(cams, str | bytes):
        try:
            cams = json.loads(cams)
        except ValueError:
            return None
    if not isinstance(cams, list) or not all(isinstance(c, dict) and "name" in c for c in cams):
        return None
    return cams


def _short(text: str, n: int = 300) -> str:
    return text if len(text) <= n else text[: n - 3] + "..."


def _camera_gaps(sets: list[list[dict]], cameras: tuple[str, ...]) -> tuple[list[str], list[str]]:
    """A camera that measured nothing (a failure), or only some of the image sets (a note)."""
    failures, notes = [], []
    n = len(sets)
    for name in cameras:
        mine = [c for cams in sets for c in cams if c.get("name") == name]
        bad = [c for c in mine if not c.get("ok")]
        failed = len(bad) + n - len(mine)
        if failed == 0:
            continue
        reason = next((str(c["error"]) for c in bad if c.get("error")), "not measured")
        if failed == n:
            failures.append(
                f"camera {name} measured nothing in the {n} image set(s) ({_short(reason)}): the results "
                "are the other cameras' alone; put its images back, or remove it from the rig"
            )
        else:
            notes.append(
                f"camera {name} did not measure {failed} of the {n} image sets (first: {_short(reason)}): "
                "those were measured by the other cameras alone"
            )
    return failures, notes


def _disagreement(sets: list[list[dict]], rig_file: str) -> list[str]:
    """Image sets whose cameras' poses disagree: one failure naming the largest offsets."""
    bad = [cams for cams in sets if any(c.get("disagree") for c in cams)]
    if not bad:
        return []

    def spread(cams: list[dict]) -> float:
        return max((c.get("offset_mm") or 0.0) for c in cams)

    worst = max(bad, key=spread)
    parts = ", ".join(
        f"{c['name']} {c['offset_mm']:.3g} mm / {c['offset_deg']:.3g} deg"
        for c in worst
        if isinstance(c.get("offset_mm"), int | float) and isinstance(c.get("offset_deg"), int | float)
    )
    return [
        f"{rig_file}: the cameras disagree on the boards' poses in {len(bad)} of the {len(sets)} image "
        f"sets, far beyond their uncertainty (the largest, each camera's pose from the fused one: "
        f"{parts or 'unknown'}): is {rig_file} this rig's (its cameras' names in the right order), or "
        "did a camera move since it was calibrated? The stiffness measured with it is wrong; "
        "calibrate the rig again (stiffmap calibrate-rig)"
    ]


def rig_failures(
    rows: Iterable[tuple[str, Any]], cameras: tuple[str, ...], rig_file: str
) -> tuple[list[str], list[str]]:
    """The failures (and notes) of a rig campaign's cameras over all its measured image sets.

    Parameters
    ----------
    rows : iterable of (str, list or str)
        Of each of the campaign's ``measurements`` rows, its ``status`` and ``per_camera``: the
        list (or its JSON text) of each camera's entry, ``name``, ``ok``, ``error``,
        ``offset_mm``, ``offset_deg``, ``disagree``.
    cameras : tuple of str
        The rig's camera names.
    rig_file : str
        The rig file's name, for the messages.

    Returns
    -------
    failures : list of str
        One line per camera that measured no image set, and one when the cameras disagree in
        some image set; empty with one camera or when all is well.
    notes : list of str
        One line per camera that measured some of the image sets but not all.
    """
    if len(cameras) < 2:
        return [], []
    # The image sets measured (by one camera at least): one that no camera measured is a failure
    # of its own already.
    sets = [cams for status, per in rows if status == "ok" and (cams := _cameras_of(per)) is not None]
    if not sets:
        return [], []
    failures, notes = _camera_gaps(sets, cameras)
    return failures + _disagreement(sets, rig_file), notes
