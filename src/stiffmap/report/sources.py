"""What a report is written from: a campaign directory, a ``data.json`` dump or a built-in example.

:func:`write_report_from` takes what ``stiffmap report DATA [OUT_DIR]`` takes:
a campaign directory (after ``stiffmap run``; its report goes to
``CAMPAIGN/report`` unless ``out_dir`` says otherwise), the ``data.json``
written beside every report, or with ``example=True`` the name of an example
of :mod:`stiffmap.report.example`.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..campaign.run import campaign_root
from ..campaign.spec import SPEC_NAME
from ..errors import InputError
from .campaign import write_campaign_report
from .example import example_sensor, example_vision
from .writer import load_report_data, write_report

__all__ = ["EXAMPLES", "write_report_from"]

#: The built-in examples by name.
EXAMPLES = {"vision": example_vision, "sensor": example_sensor}


def write_report_from(
    source: str | os.PathLike,
    out_dir: str | os.PathLike | None = None,
    *,
    example: bool = False,
    png: bool = True,
    allow_outside: bool = False,
) -> Path:
    """Write the report of a campaign, a ``data.json`` or an example; return its ``index.html``.

    Parameters
    ----------
    source : str or path-like
        A campaign directory, a ``data.json`` file, or (``example``) an example's name.
    out_dir : path-like, optional
        The report's directory; needed except for a campaign (default ``CAMPAIGN/report``).
    example : bool
        ``source`` names one of :data:`EXAMPLES`.
    png : bool
        Also write the PNG figures.
    allow_outside : bool
        A campaign's ``campaign.toml`` may name files outside its directory
        (:mod:`stiffmap.campaign.paths`).

    Raises
    ------
    InputError
        A directory that is no campaign, no ``out_dir`` where one is needed, an unknown
        example, or a bad ``data.json`` (naming the file and the key).
    """
    if not example and Path(source).name == SPEC_NAME and Path(source).is_file():
        source = campaign_root(source)  # a campaign named by its campaign.toml, as `run` takes it
    if not example and Path(source).is_dir():
        if not (Path(source) / SPEC_NAME).is_file():
            raise InputError(
                f"{source}: a directory without {SPEC_NAME}; expected a campaign or a data.json file"
            )
        return write_campaign_report(source, out_dir=out_dir, png=png, allow_outside=allow_outside)
    if out_dir is None:
        if not example and not Path(source).exists():
            raise InputError("no such campaign directory or data.json file", source=str(source))
        what = f"{source}: " if not example else ""
        raise InputError(f"{what}give OUT_DIR, the directory to write the report to")
    if example:
        if source not in EXAMPLES:
            raise InputError(f"--example: unknown example {source!r}; expected one of {', '.join(EXAMPLES)}")
        data = EXAMPLES[source]()
    else:
        data = load_report_data(source)
    return write_report(data, out_dir, png=png)
