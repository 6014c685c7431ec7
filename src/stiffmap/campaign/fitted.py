"""The model a campaign fitted, with its parameters' covariance (``stiffmap compensate --from-campaign``).

A campaign that ``stiffmap run`` has processed holds its model fit in ``stiffmap.db``
(``model_fit``: the vision path's ``stiffness`` fit, the sensor path's ``static_error``
fit): the fitted parameters, their standard errors and covariance. :func:`fitted_model`
builds the campaign's robot model (``robot`` of ``campaign.toml``, as ``stiffmap run``
does) with those parameters. A URDF arm's model is the joint stiffnesses at the tool point
(the campaign's loads were hung at ``loads.point_mm``; the cutting force acts at the tool).
"""

from __future__ import annotations

import math
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
    if spec.robot.kind is None:
        raise InputError(
            f'the campaign has no robot model (robot.model = "{spec.robot.model}"): nothing was fitted; '
            "give the robot KIND (and --param) to compensate with a model of your own",
            source=str(root / SPEC_NAME),
        )
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
        why = rows[0].error or f"its status is {rows[0].status!r}, not 'ok'"
        raise InputError(f"the campaign's model fit failed: {why}", source=str(db))
    row = ok[0]
    params = row.params or {}
    changes = robot_changes(row.robot, spec, root, params)
    if changes:
        raise InputError(stale_fit_message(changes, root), source=str(root / SPEC_NAME))
    std = row.std or {}
    names = tuple(params)
    cov = _checked_cov(row.cov, params, row.name, db)
    q = None if spec.positions is None else spec.positions.q_deg
    try:
        model = robot_model(spec.robot, root, configurations_deg=q)
    except ValueError as e:
        raise InputError(f"campaign.toml robot: {e}", source=str(root)) from None
    try:
        model = model.with_params(**{k: float(v) for k, v in params.items()})
    except ValueError as e:  # the fit's values, which campaign.toml did not give
        raise InputError(
            f"model_fit {row.name}: the fitted parameters do not make a robot ({e}): the database was "
            "edited or damaged; run 'stiffmap run' on the campaign again",
            source=str(db),
        ) from None
    return FittedModel(model, names, cov, {k: float(v) for k, v in std.items()}, row.name, str(root))


def _checked_cov(cov, params: dict, fit: str, db: Path) -> np.ndarray:
    """The fit's covariance if it is one: p x p for its p parameters, symmetric and positive
    semidefinite (to rounding), no standard error a million times its parameter, finite or
    entirely NaN (a fit without a residual degree of freedom, or none stored: unknown); else
    InputError naming the database."""
    names = tuple(params)
    if cov is None:
        return np.full((len(names), len(names)), np.nan)
    cov = np.atleast_2d(np.asarray(cov, dtype=float))
    why = ""
    if cov.shape != (len(names), len(names)):
        why = f"covariance of shape {cov.shape} for {len(names)} parameter(s)"
    elif np.all(np.isnan(cov)):
        return cov
    elif not np.all(np.isfinite(cov)):
        why = "covariance with NaN or infinite entries"
    else:
        big = [
            n for n, v in zip(names, np.diag(cov), strict=True) if math.sqrt(abs(v)) > 1e6 * abs(params[n])
        ]
        scale = float(np.max(np.abs(cov))) if cov.size else 0.0
        if big:
            why = f"standard error of {big[0]} over a million times its value ({params[big[0]]:g})"
        elif not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-12 * scale):
            why = "covariance not symmetric"
        elif cov.size and float(np.min(np.linalg.eigvalsh(0.5 * cov + 0.5 * cov.T))) < -1e-9 * scale:
            why = "covariance with a negative variance (not positive semidefinite)"
    if why:
        raise InputError(f"model_fit {fit}: {why}: the database was edited or damaged", source=str(db))
    return cov
