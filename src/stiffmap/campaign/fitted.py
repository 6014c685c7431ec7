"""The model a campaign fitted, with its parameters' covariance (``stiffmap compensate --from-campaign``).

A campaign that ``stiffmap run`` has processed holds its model fit in ``stiffmap.db``
(``model_fit``: the vision path's ``stiffness`` fit, the sensor path's ``static_error``
fit): the fitted parameters, their standard errors and covariance. :func:`fitted_model`
builds the campaign's robot model (``robot`` of ``campaign.toml``, as ``stiffmap run``
does) with those parameters. A URDF arm's model is the joint stiffnesses at the tool point
(the campaign's loads were hung at ``loads.point_mm``; the cutting force acts at the tool).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..models.base import Mechanism
from .fingerprint import robot_changes, stale_fit_message
from .robot import robot_model
from .run import campaign_root
from .spec import SPEC_NAME, load_spec
from .store import DB_NAME, Store

__all__ = ["FittedModel", "fitted_model"]

#: The fits, in the order they are looked for.
FIT_NAMES = ("stiffness", "static_error")


@dataclass(frozen=True)
class FittedModel:
    """A campaign's fitted model.

    Attributes
    ----------
    mechanism : Mechanism
        The robot model with the fitted parameters.
    names : tuple of str
        The fitted parameters, in the covariance's order.
    cov : ndarray, shape (p, p)
        Their covariance (units of the parameters squared).
    std : dict of str to float
        Their standard errors.
    fit : str
        Which fit (``stiffness``: vision campaign; ``static_error``: sensor campaign).
    source : str
        The campaign directory.
    """

    mechanism: Mechanism
    names: tuple[str, ...]
    cov: np.ndarray
    std: dict[str, float]
    fit: str
    source: str


def fitted_model(directory: str | Path) -> FittedModel:
    """The model a campaign fitted (module docstring).

    Raises
    ------
    InputError
        Not a campaign, no results database, no successful model fit (its error named).
    """
    root = campaign_root(directory)
    spec = load_spec(root)
    db = root / DB_NAME
    with Store(db, read_only=True) as store:
        rows = [store.model_fit(n) for n in FIT_NAMES]
    rows = [r for r in rows if r is not None]
    if not rows:
        raise InputError(
            "no model fit in the results database: run 'stiffmap run' on the campaign first", source=str(db)
        )
    ok = [r for r in rows if r.status == "ok"]
    if not ok:
        raise InputError(f"the campaign's model fit failed: {rows[0].error}", source=str(db))
    row = ok[0]
    params = row.params or {}
    changes = robot_changes(row.robot, spec, root, params)
    if changes:
        raise InputError(stale_fit_message(changes, root), source=str(root / SPEC_NAME))
    std = row.std or {}
    cov = np.atleast_2d(row.cov)
    names = tuple(params)
    if cov.shape != (len(names), len(names)):
        raise InputError(
            f"model_fit {row.name}: covariance of shape {cov.shape} for {len(names)} "
            "parameter(s): the database was edited or damaged",
            source=str(db),
        )
    q = None if spec.positions is None else spec.positions.q_deg
    try:
        model = robot_model(spec.robot, root, configurations_deg=q).with_params(
            **{k: float(v) for k, v in params.items()}
        )
    except ValueError as e:
        raise InputError(f"campaign.toml robot: {e}", source=str(root)) from None
    return FittedModel(model, names, cov, {k: float(v) for k, v in std.items()}, row.name, str(root))
