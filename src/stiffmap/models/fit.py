"""Fit a mechanism's parameters to measurements by nonlinear least squares.

Two kinds of measurements:

- **stiffness matrices** at poses (the vision path): K_meas (N/mm), each entry
  an observation with an optional standard error (:func:`fit_stiffness`);
- **static errors** (the sensor path, which reads one displacement component
  per recording): at a pose, a force F (N) is applied and the displacement
  along a unit direction n is measured, ``value = n . K^-1 F`` (mm), with an
  optional standard error (:func:`fit_static_errors`).

The chosen parameters (any of the model's scalar parameters: ``kj``, ``kb`` of
the 3PRR, ``k_theta`` of the Delta, or geometric ones) are estimated by
``scipy.optimize.least_squares`` on the weighted residuals
``(observed - predicted) / std``, over the parameters' logarithms (so they stay
positive and the problem is scaled). The model's values of the parameters are only a start:
where the observations (or, for stiffness matrices, their inverses) are linear in the
parameters or in their inverses (a serial robot's joint compliances, a parallel robot's leg
stiffnesses), the fit runs from the weighted linear least-squares solution (non-negative), its
own minimum whatever the start (:func:`linear_start`); otherwise from the given values, with a
second run from a linear or linearised start when the first fails or ends higher
(:func:`_solve`). A trial step the model cannot evaluate is a rejected step. The covariance is
``(J^T J)^-1`` in log parameters (J the Jacobian of the weighted residuals at the
solution), multiplied by the reduced chi-square ``chi2 / dof`` unless
``absolute_sigma`` is True (the given standard errors are then taken as exact),
and carried to the parameters by ``dp = p dlog p``.

6-DOF deflections of a platform that turns (:func:`fit_deflections6`) may come with full
6 x 6 covariances: each deflection's residual is then whitened by the Cholesky factor of its
covariance (:mod:`~stiffmap.models.whiten`), and with ``extra_noise`` a shared 6 x 6 noise the
covariances leave out is estimated and added to each (``ModelFit.extra_covariance``).

Refusals (:class:`~stiffmap.errors.DesignError`, a ``ValueError``):

- a parameter the data do not feel: a relative change of it changes the
  predictions by less than ``MIN_RELATIVE_SENSITIVITY`` times as much;
- parameters the data cannot tell apart: the Jacobian, its columns scaled to
  unit length, has an inverse condition number below ``MIN_INVERSE_CONDITION``
  (for example ``E`` and ``area`` of the 3PRR, which only enter as ``E * area``);
- fewer observations than parameters; unknown parameter names; non-positive
  starting values (refused by the model itself).

A design that can determine the parameters, but badly, passes with an
:class:`~stiffmap.errors.IllConditionedWarning` (condition above ``CONDITION_WARN``).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import DesignError, IllConditionedWarning
from ..stats import chi2_sf
from .base import POSE_DIM, Mechanism, PoseError, as_forces, as_points, format_pose
from .whiten import as_float, whitener

__all__ = [
    "ModelFit",
    "fit_stiffness",
    "fit_static_errors",
    "fit_deflections6",
    "static_error_predictions",
    "MIN_RELATIVE_SENSITIVITY",
    "MIN_INVERSE_CONDITION",
    "CONDITION_WARN",
    "MAX_RELATIVE_STD",
    "SEPARATION_CORRELATION",
    "separation_notes",
]

#: Below this relative sensitivity (relative change of the predictions per relative
#: change of a parameter) a parameter is refused as not determined by the data.
MIN_RELATIVE_SENSITIVITY = 1e-6
#: Below this inverse condition number of the column-normalised Jacobian the
#: parameters are refused as not separable.
MIN_INVERSE_CONDITION = 1e-6
#: Above this condition number of the column-normalised Jacobian a warning is issued.
CONDITION_WARN = 1e3
#: A fitted parameter whose standard error exceeds this fraction of its value is named as
#: one the data cannot determine (:func:`separation_notes`).
MAX_RELATIVE_STD = 1.0
#: With such a parameter, the others it is correlated with at least this much are named beside it.
SEPARATION_CORRELATION = 0.99


@dataclass(frozen=True)
class ModelFit:
    """Result of a model fit.

    Attributes
    ----------
    kind : str
        ``"stiffness"``, ``"static_error"``, ``"stiffness6"`` (K6 entries) or ``"deflection6"``
        (6-DOF deflections under wrenches: :func:`fit_deflections6`).
    names : tuple of str
        The fitted parameters.
    estimate : ndarray, shape (p,)
        Their estimates (the model's units: N/mm, N*mm/rad, mm, ...).
    std : ndarray, shape (p,)
        Standard errors (NaN when they cannot be known: no residual degree of
        freedom and ``absolute_sigma`` False).
    covariance : ndarray, shape (p, p)
    correlation : ndarray, shape (p, p)
    initial : ndarray, shape (p,)
        Starting values (the model's values before the fit).
    model : Mechanism
        The fitted model (``model.with_params(**values)``).
    poses : ndarray, shape (n_poses, dim), mm
        The distinct poses of the observations.
    pose_index : ndarray of int, shape (n_obs,)
        The pose of each observation.
    observed, predicted : ndarray, shape (n_obs,)
        Per observation (mm for static errors; N/mm for stiffness entries, row-major
        K of each pose in turn).
    sigma : ndarray, shape (n_obs,)
        Standard errors used as weights (1 where none were given; for K6 without them, the
        relative weights of :func:`fit_stiffness`; for deflections with full covariances, the
        components' standard deviations, the weights being the whitening by those covariances).
    residuals : ndarray, shape (n_obs,)
        ``observed - predicted`` (mm or N/mm).
    residual_rms_per_pose : ndarray, shape (n_poses,)
        RMS of the residuals of each pose (mm or N/mm).
    chi2 : float
        Sum of squared weighted residuals.
    dof : int
        Observations minus parameters.
    reduced_chi2 : float
        ``chi2 / dof`` (NaN when dof = 0); about 1 when the given standard errors are right.
    condition : float
        Condition number of the Jacobian of the weighted residuals with respect to
        the parameters' logarithms, columns scaled to unit length (1 for one
        parameter; large when parameters are hard to tell apart).
    sensitivity : ndarray, shape (p,)
        Relative sensitivity of the predictions to each parameter (see module docstring).
    absolute_sigma : bool
    converged : bool
    nfev : int
    message : str
    notes : tuple of str
        What may make the result wrong (no residual degree of freedom, no convergence, a misfit
        the fit could not account for): a campaign counts them as failures.
    extra_covariance : ndarray, shape (6, 6), or None
        For :func:`fit_deflections6` with ``extra_noise``: the noise (mm^2, mm*rad, rad^2)
        estimated as missing from the given covariances and added to each (None otherwise).
    info : tuple of str
        What the fit did that a reader should know but that is accounted for (the extra noise
        estimated, in words): printed, not a failure.
    """

    kind: str
    names: tuple[str, ...]
    estimate: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    initial: np.ndarray
    model: Mechanism
    poses: np.ndarray
    pose_index: np.ndarray
    observed: np.ndarray
    predicted: np.ndarray
    sigma: np.ndarray
    residuals: np.ndarray
    residual_rms_per_pose: np.ndarray
    chi2: float
    dof: int
    reduced_chi2: float
    condition: float
    sensitivity: np.ndarray
    absolute_sigma: bool
    converged: bool
    nfev: int
    message: str
    notes: tuple[str, ...] = field(default_factory=tuple)
    extra_covariance: np.ndarray | None = None
    info: tuple[str, ...] = field(default_factory=tuple)

    @property
    def extra_std(self) -> np.ndarray | None:
        """Standard deviations of the extra noise per axis (u mm, rotation rad), or None."""
        return None if self.extra_covariance is None else np.sqrt(np.diag(self.extra_covariance))

    @property
    def values(self) -> dict[str, float]:
        """Estimates by name."""
        return {k: float(v) for k, v in zip(self.names, self.estimate, strict=True)}

    @property
    def std_values(self) -> dict[str, float]:
        """Standard errors by name."""
        return {k: float(v) for k, v in zip(self.names, self.std, strict=True)}

    def to_dict(self) -> dict:
        """Plain JSON-able summary (``stiffmap fit --json``)."""
        return {
            "kind": self.kind,
            "mechanism": self.model.name,
            "parameters": {
                k: {"estimate": float(e), "std": float(s), "initial": float(i)}
                for k, e, s, i in zip(self.names, self.estimate, self.std, self.initial, strict=True)
            },
            "correlation": self.correlation,
            "model_parameters": self.model.params(),
            "n_observations": int(self.observed.size),
            "n_poses": int(self.poses.shape[0]),
            "dof": self.dof,
            "chi2": self.chi2,
            "reduced_chi2": self.reduced_chi2,
            "condition": self.condition,
            "sensitivity": dict(zip(self.names, self.sensitivity.tolist(), strict=True)),
            "absolute_sigma": self.absolute_sigma,
            "converged": self.converged,
            "residual_rms": float(np.sqrt(np.mean(self.residuals**2))),
            "poses": [
                {"pose": p, "residual_rms": r}
                for p, r in zip(self.poses.tolist(), self.residual_rms_per_pose.tolist(), strict=True)
            ],
            "notes": list(self.notes),
            "info": list(self.info),
            "extra_covariance": self.extra_covariance,
            "extra_std": self.extra_std,
        }


def _check_names(model: Mechanism, params: Sequence[str]) -> tuple[tuple[str, ...], np.ndarray]:
    if isinstance(params, str):
        params = (params,)
    names = tuple(str(p) for p in params)
    if not names:
        raise ValueError("no parameter to fit: give at least one name")
    valid = model.params()
    bad = [n for n in names if n not in valid]
    if bad:
        raise ValueError(
            f"unknown parameter(s) to fit for {model.name}: {', '.join(bad)}; valid: {', '.join(valid)}"
        )
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"parameter(s) given more than once: {', '.join(dup)}")
    p0 = np.array([float(valid[n]) for n in names])
    if not np.all(np.isfinite(p0) & (p0 > 0)):
        k = int(np.flatnonzero(~(np.isfinite(p0) & (p0 > 0)))[0])
        why = " (inf: a rigid element, which has nothing to fit; leave it out)" if np.isinf(p0[k]) else ""
        raise ValueError(
            f"cannot fit {names[k]}: its starting value {float(p0[k]):g} is not a positive finite number{why}"
        )
    return names, p0


def _check_sigma(sigma, shape: tuple[int, ...], name: str) -> np.ndarray | None:
    if sigma is None:
        return None
    s = np.asarray(sigma, dtype=np.float64)
    if s.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {s.shape}")
    if not np.all(np.isfinite(s) & (s > 0)):
        i = np.unravel_index(int(np.flatnonzero(~(np.isfinite(s) & (s > 0)))[0]), shape)
        where = tuple(int(v) for v in i)
        raise ValueError(f"{name} must be positive and finite; entry {where} is {float(s[i])!r}")
    return s


def _group_poses(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    uniq, inv = np.unique(P, axis=0, return_inverse=True)
    # Keep the poses in order of first appearance.
    first = np.array([np.flatnonzero(inv == k)[0] for k in range(uniq.shape[0])])
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return uniq[order], rank[np.ravel(inv)]


def _jac_log(fun, x: np.ndarray, step: float = 1e-5) -> np.ndarray:
    """Central-difference Jacobian of ``fun`` with respect to x (log parameters)."""
    cols = []
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = step
        cols.append((fun(x + e) - fun(x - e)) / (2 * step))
    return np.stack(cols, axis=1)


def _trial_jacobian(trial, x: np.ndarray) -> np.ndarray:
    """The optimiser's Jacobian of ``trial`` at an accepted point x: central differences with
    ``least_squares``' own "3-point" steps, one-sided on a side where the model cannot be
    evaluated (a pose at the edge of its reach), zero when neither side can."""
    f0 = trial(x)
    cols = []
    for k in range(x.size):
        h = np.zeros_like(x)
        h[k] = np.finfo(float).eps ** (1 / 3) * max(1.0, abs(x[k])) * (1.0 if x[k] >= 0 else -1.0)
        h[k] = (x[k] + h[k]) - x[k]
        fp, fm = trial(x + h), trial(x - h)
        ok_p, ok_m = np.all(np.isfinite(fp)), np.all(np.isfinite(fm))
        if ok_p and ok_m:
            cols.append((fp - fm) / (2 * h[k]))
        elif ok_p or ok_m:
            cols.append((fp - f0) / h[k] if ok_p else (f0 - fm) / h[k])
        else:
            cols.append(np.zeros_like(f0))
    return np.stack(cols, axis=1)


def _check_design(names, J: np.ndarray, scale: float) -> tuple[float, np.ndarray]:
    """Refuse parameters the data cannot determine; return (condition, relative sensitivities)."""
    norms = np.linalg.norm(J, axis=0)
    sens = norms / scale if scale > 0 else np.zeros_like(norms)
    dead = [n for n, s in zip(names, sens, strict=True) if not s >= MIN_RELATIVE_SENSITIVITY]
    if dead:
        detail = ", ".join(f"{n} ({s:.2g})" for n, s in zip(names, sens, strict=True) if n in dead)
        raise DesignError(
            f"the data cannot determine {', '.join(dead)}: the predictions do not change with "
            f"{'it' if len(dead) == 1 else 'them'} (relative sensitivity {detail} < "
            f"{MIN_RELATIVE_SENSITIVITY:g}); fix {'it' if len(dead) == 1 else 'them'} instead of fitting"
        )
    Jn = J / norms
    _, s, Vt = np.linalg.svd(Jn, full_matrices=False)
    inv_cond = s[-1] / s[0]
    if inv_cond < MIN_INVERSE_CONDITION:
        v = Vt[-1]
        involved = [n for n, c in zip(names, v, strict=True) if abs(c) > 0.1]
        raise DesignError(
            f"the data cannot tell {', '.join(involved)} apart: their effects on the predictions are "
            f"proportional (inverse condition {inv_cond:.2g} < {MIN_INVERSE_CONDITION:g}); fit one of them "
            "and fix the others"
        )
    return float(1.0 / inv_cond), sens


def _weigher(sigma, weights, whiten, n: int):
    """The observations' weights (``sigma``, else ``weights``, else ones) and the function that
    weighs a residual vector (divides by them, or whitens ``d`` at a time by ``whiten``)."""
    w = (np.ones(n) if weights is None else weights) if sigma is None else sigma
    if whiten is None:

        def weigh(r: np.ndarray) -> np.ndarray:
            return r / w
    else:
        d = whiten.shape[-1]

        def weigh(r: np.ndarray) -> np.ndarray:
            return np.einsum("mab,mb->ma", whiten, r.reshape(-1, d)).reshape(-1)

    return w, weigh


def _residual_functions(model: Mechanism, names, predict, y: np.ndarray, weigh):
    """The model at log parameters ``x`` and the weighted residuals there; a parameter run to 0
    or infinity, or a pose made unreachable, is a :class:`DesignError` naming the values."""

    def model_at(x: np.ndarray) -> Mechanism:
        values = np.exp(x)
        try:
            return model.with_params(**dict(zip(names, values.tolist(), strict=True)))
        except ValueError as e:  # a parameter run to 0 or infinity: the data do not hold it
            now = ", ".join(f"{k} = {v:.6g}" for k, v in zip(names, values, strict=True))
            raise DesignError(
                f"during the fit, {now}: {e}; the data do not hold these parameters (fit fewer, or "
                "start closer to the solution)"
            ) from None

    def resid(x: np.ndarray) -> np.ndarray:
        yhat = predict(model_at(x))
        if not np.all(np.isfinite(yhat)):
            now = ", ".join(f"{k} = {v:.6g}" for k, v in zip(names, np.exp(x), strict=True))
            raise DesignError(
                f"during the fit, {now} made a pose unreachable or singular; "
                "fix the geometry or start closer to the solution"
            )
        return weigh(y - yhat)

    def trial(x: np.ndarray) -> np.ndarray:
        """The residuals at a trial step of the optimiser: NaN where ``resid`` refuses, which
        ``least_squares`` takes as a rejected step (it shrinks its trust region and tries again)."""
        try:
            return resid(x)
        except ValueError:
            return np.full(y.size, np.nan)

    return model_at, resid, trial


@dataclass(frozen=True)
class LinearView:
    """Observations in which a model's spring parameters may act linearly (the start of a fit).

    ``predict(model)`` gives the view's values (for static errors the predictions themselves,
    for stiffness matrices their inverses, the compliances), ``observed`` the measured ones, and
    ``to_observations(r)`` carries a residual of the view, linearly, to (about) the residual of
    the observations (identity, or ``-K r K`` per pose for compliances), so that the weights of
    the observations weigh it.
    """

    predict: Callable[[Mechanism], np.ndarray]
    observed: np.ndarray
    to_observations: Callable[[np.ndarray], np.ndarray] = np.asarray


#: A view is taken as linear in the parameters (or in their inverses) when its values at a
#: second point differ from the straight line through the first by less than this (relative).
LINEAR_TOL = 1e-6


def _view_columns(view: LinearView, model: Mechanism, names, v0: np.ndarray, to_p, check: bool = True):
    """(A, b): the view's values ``A v + b`` for parameters ``to_p(v)``, the columns found by
    doubling each v in turn at v0; when ``check``, None unless they are linear in v (checked
    at a second point), else (a linearisation) by moving each v by 1 % (a geometric parameter
    doubled or halved may leave the poses unreachable). None where the model refuses a value."""

    def g(v: np.ndarray) -> np.ndarray:
        return view.predict(model.with_params(**dict(zip(names, to_p(v).tolist(), strict=True))))

    try:
        with np.errstate(all="ignore"):
            g0 = g(v0)
            h = v0 * (1.0 if check else 1e-2)
            A = np.stack([(g(v0 + h[j] * np.eye(v0.size)[j]) - g0) / h[j] for j in range(v0.size)], axis=1)
            v1 = v0 * np.where(np.arange(v0.size) % 2, 0.6, 1.5)
            g1 = g(v1) if check else g0
    except (ValueError, np.linalg.LinAlgError):
        return None
    b = g0 - A @ v0
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(g1))):
        return None
    if check and np.linalg.norm(g1 - (A @ v1 + b)) > LINEAR_TOL * max(np.linalg.norm(g1), np.linalg.norm(g0)):
        return None
    return A, b


def _solve_view(view: LinearView, model: Mechanism, names, v0: np.ndarray, to_p, weigh, check: bool = True):
    """The non-negative weighted least-squares solution v of the view's values ``A v + b``
    (:func:`_view_columns` at v0; columns scaled to unit length), a parameter held at 0 moved to
    where its column gives 1e-3 of the predictions, and whether one was; None when the view is
    not linear (when ``check``) or a column is zero (not felt)."""
    from scipy import optimize  # on first use, as in _fit

    cols = _view_columns(view, model, names, v0, to_p, check)
    if cols is None:
        return None
    A, b = cols
    M = np.stack([weigh(view.to_observations(A[:, j])) for j in range(A.shape[1])], axis=1)
    norms = np.linalg.norm(M, axis=0)
    if not np.all(norms > 0):
        return None
    r0 = weigh(view.to_observations(view.observed - b))
    v = optimize.lsq_linear(M / norms, r0, bounds=(0.0, np.inf), method="bvls", tol=1e-14).x / norms
    if not np.any(v > 0):
        return None
    return np.where(v > 0, v, 1e-3 * np.linalg.norm(M @ v) / norms), not np.all(v > 0)


def linear_start(model: Mechanism, names, p0: np.ndarray, views: Sequence[LinearView], weigh):
    """(x, exact): log parameters minimising the weighted residuals of the first view in which
    the fitted parameters (or their inverses, the compliances) act linearly, non-negative
    (bounded linear least squares), and whether x is the minimum of the fit itself (the first
    view linear, no parameter held by the bound); None when no view is linear.

    A serial robot's static errors ``n . J C J^T F`` and compliances ``C = sum c_i J_i J_i^T``
    are linear in the joints' compliances c_i = 1/k_i, as are a non-redundant parallel robot's
    (``C = J^-1 diag(c) J^-T``); a parallel robot's stiffness ``K = sum k_i u_i u_i^T`` is linear
    in its legs' stiffnesses. There the solution does not depend on the starting values: the
    columns are found at them, then again at the first solution (where no parameter swamps the
    others), and the problem solved again. A parameter the bound holds at 0 (rigid, or
    infinitely soft) starts where its column gives 1e-3 of the predictions, and the nonlinear
    fit decides.
    """
    for i, view in enumerate(views):
        for to_p in (np.reciprocal, np.asarray):
            found = _solve_view(view, model, names, to_p(p0), to_p, weigh)
            if found is not None:
                found = _solve_view(view, model, names, found[0], to_p, weigh)
            if found is not None:
                return np.log(to_p(found[0])), i == 0 and not found[1]
    return None


#: Linearised steps of :func:`linearised_start` at most (each p + 1 evaluations of the model),
#: halvings of a step that does not lower the cost, and tenfold raises of a parameter the
#: predictions do not feel at the start (a compliance far below the others' in series).
LINEARISED_STEPS = 10
HALVINGS = 8
RAISES = 30


def _felt(view: LinearView, model: Mechanism, names, v: np.ndarray, to_p) -> np.ndarray:
    """v with each parameter the view does not feel at all (its column zero: far below the
    others in rounding) raised tenfold until it is felt (at most ``RAISES`` times)."""
    for _ in range(RAISES):
        cols = _view_columns(view, model, names, v, to_p, check=False)
        dead = None if cols is None else ~(np.linalg.norm(cols[0], axis=0) > 0)
        if dead is None or not dead.any():
            break
        v = np.where(dead, 10.0 * v, v)
    return v


def linearised_start(model: Mechanism, names, p0: np.ndarray, view: LinearView, weigh, cost):
    """Where the parameters do not act linearly (a robot whose legs have two springs in series
    and in parallel, geometry fitted with springs): from the given values (a parameter not felt
    there raised until it is, :func:`_felt`), bounded linear least-squares steps, the columns
    found again at each step (Gauss-Newton in the compliances, then in the parameters
    themselves, kept positive by the bound), each step halved in log parameters until ``cost``
    (log parameters -> sum of squared weighted residuals, inf where the model cannot be
    evaluated) falls; the log parameters of the lowest cost reached (None when none could be
    evaluated)."""
    best, best_cost = None, np.inf
    for to_p in (np.reciprocal, np.asarray):
        x = np.log(to_p(_felt(view, model, names, to_p(p0), to_p)))
        c = cost(x)
        if c < best_cost:
            best, best_cost = x, c
        for _ in range(LINEARISED_STEPS):
            found = _solve_view(view, model, names, to_p(np.exp(x)), to_p, weigh, check=False)
            if found is None:
                break
            step = np.log(to_p(found[0])) - x
            for t in 0.5 ** np.arange(HALVINGS):
                c_new = cost(x + t * step)
                if c_new < c:
                    break
            if not c_new < c:
                break
            x, c = x + t * step, c_new
            if c < best_cost:
                best, best_cost = x, c
    return best


def _log_covariance(
    J: np.ndarray, red: float, dof: int, absolute_sigma: bool, notes: list[str]
) -> np.ndarray:
    """Covariance of the log parameters: ``(J^T J)^-1``, times the reduced chi-square unless
    ``absolute_sigma``; NaN (with a note) without a residual degree of freedom."""
    cov_log = np.linalg.inv(J.T @ J)
    if absolute_sigma:
        pass
    elif dof > 0:
        cov_log = cov_log * red
    else:
        p = J.shape[1]
        cov_log = np.full((p, p), np.nan)
        notes.append("no residual degree of freedom: standard errors unknown (give std and absolute_sigma)")
    return cov_log


#: A run from the given values is kept unless a run from the linear start reaches a cost
#: lower by more than this (relative): the same minimum reached twice differs by rounding.
COST_RTOL = 1e-12


def _solve(model: Mechanism, names, p0: np.ndarray, views, y: np.ndarray, fns):
    """The ``least_squares`` run of the fit. Where the observations are linear in the fitted
    parameters or their inverses, the minimum is the solution of :func:`linear_start` whatever
    the start: the run starts there (central differences). Otherwise a run from the given
    values (the design first checked there), kept when it converged and its cost is not above
    that of the linear start (a start from ``views``), or, where no view is linear, when the
    data feel every parameter where it ended (:func:`_held`): results at a good start are those
    of a plain fit. Else a second run from the linear start (or from the point
    :func:`linearised_start` reaches), and of the two the run that ended held, at the lower
    cost, is kept. When none runs, the first run's error (a parameter the data cannot
    determine, named) is raised."""
    model_at, predict, weigh, resid, trial = fns

    def cost(x: np.ndarray) -> float:
        r = trial(x)
        return float(r @ r) if np.all(np.isfinite(r)) else np.inf

    own = LinearView(predict, y)
    xl, exact = linear_start(model, names, p0, (own, *views), weigh) or (None, False)
    if exact:
        run = _run(names, xl, fns, _trial_jacobian)
        if not isinstance(run, Exception) and run.success:
            return run
    first, error = _run(names, np.log(p0), fns, "2-point"), None
    if isinstance(first, Exception):
        first, error = None, first
    if first is not None and first.success:
        if cost(first.x) <= cost(xl) * (1 + COST_RTOL) if xl is not None else _held(names, first, fns):
            return first
    if xl is None or not np.all(np.isfinite(xl)):
        xl = linearised_start(model, names, p0, own, weigh, cost)
    second = None if xl is None else _run(names, xl, fns, _trial_jacobian)
    runs = [r for r in (first, second) if r is not None and not isinstance(r, Exception)]
    if not runs:
        raise error
    return min(runs, key=lambda r: (not _held(names, r, fns), cost(r.x)))


def _held(names, run, fns) -> bool:
    """Whether a run converged where the data feel and separate every parameter (the design
    check passes there): not a parameter run off to where nothing changes with it."""
    if run is None or isinstance(run, Exception) or not run.success:
        return False
    model_at, predict, weigh, resid, _ = fns
    try:
        _check_design(names, _jac_log(resid, run.x), float(np.linalg.norm(weigh(predict(model_at(run.x))))))
    except ValueError:
        return False
    return True


def _run(names, x0: np.ndarray, fns, jac):
    """``least_squares`` from x0 (log parameters) after the design check there; its error (a
    ``ValueError``: the design refused, the start cannot be evaluated, a Jacobian not finite)
    returned, not raised. ``fns``: (model_at, predict, weigh, resid, trial); ``jac``:
    "2-point" (``least_squares``' own) or a function ``(trial, x) -> J``."""
    from scipy import optimize  # on first use: 0.15 s that most commands never need

    model_at, predict, weigh, resid, trial = fns
    try:
        scale = float(np.linalg.norm(weigh(predict(model_at(x0)))))
        _check_design(names, _jac_log(resid, x0), scale)
        return optimize.least_squares(
            trial,
            x0,
            jac=jac if isinstance(jac, str) else (lambda x: jac(trial, x)),
            method="trf",
            x_scale="jac",
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
        )
    except ValueError as e:
        return e


def _fit(
    kind: str,
    model: Mechanism,
    params: Sequence[str],
    predict,
    y: np.ndarray,
    sigma: np.ndarray | None,
    poses: np.ndarray,
    pose_index: np.ndarray,
    absolute_sigma: bool,
    weights: np.ndarray | None = None,
    whiten: np.ndarray | None = None,
    views: Sequence[LinearView] = (),
) -> ModelFit:
    """The fit, solved as :func:`_solve` says; ``weights`` (relative, used only when
    ``sigma`` is None) scale observations of mixed units (K6's blocks) without claiming to be
    their standard errors; ``whiten`` (m, d, d), when given, whitens the observations d at a
    time (``L^-1`` of each group's covariance, :func:`~stiffmap.models.whiten.whitener`)
    instead of dividing them by ``sigma``, which is then only recorded; ``views`` are where the
    parameters may act linearly besides the observations themselves (:func:`linear_start`)."""
    names, p0 = _check_names(model, params)
    n, p = y.size, len(names)
    if n < p:
        raise DesignError(f"{n} observation(s) cannot determine {p} parameters ({', '.join(names)})")
    w, weigh = _weigher(sigma, weights, whiten, n)
    notes: list[str] = []
    if sigma is None and absolute_sigma:
        raise ValueError("absolute_sigma=True needs the standard errors of the observations")
    model_at, resid, trial = _residual_functions(model, names, predict, y, weigh)
    res = _solve(model, names, p0, views, y, (model_at, predict, weigh, resid, trial))
    x = res.x
    fitted = model_at(x)
    r_w = resid(x)
    J = _jac_log(resid, x)
    scale = float(np.linalg.norm(weigh(predict(fitted))))
    condition, sens = _check_design(names, J, scale)
    if condition > CONDITION_WARN:
        warnings.warn(
            f"model fit of {', '.join(names)}: condition number {condition:.3g} > {CONDITION_WARN:g}; "
            "the estimates are strongly correlated and sensitive to noise",
            IllConditionedWarning,
            stacklevel=3,
        )
    chi2 = float(r_w @ r_w)
    dof = n - p
    red = chi2 / dof if dof > 0 else float("nan")
    cov_log = _log_covariance(J, red, dof, absolute_sigma, notes)
    return _model_fit(
        kind,
        names,
        p0,
        res,
        cov_log,
        fitted,
        predict(fitted),
        y,
        w,
        sigma is not None,
        poses,
        pose_index,
        chi2=chi2,
        dof=dof,
        red=red,
        condition=condition,
        sens=sens,
        absolute_sigma=absolute_sigma,
        notes=notes,
    )


def _model_fit(
    kind: str,
    names,
    p0,
    res,
    cov_log,
    fitted,
    yhat,
    y,
    w,
    has_sigma: bool,
    poses,
    pose_index,
    *,
    chi2: float,
    dof: int,
    red: float,
    condition: float,
    sens,
    absolute_sigma: bool,
    notes: list[str],
) -> ModelFit:
    """The :class:`ModelFit` of a solved fit: the parameters' covariance from the log ones
    (``dp = p dlog p``), the residuals and their RMS per pose, the notes (read-only arrays)."""
    est = np.exp(res.x)
    cov = cov_log * np.outer(est, est)
    std = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    resid_raw = y - yhat
    n_poses = poses.shape[0]
    rms = np.sqrt(np.bincount(pose_index, resid_raw**2, n_poses) / np.bincount(pose_index, minlength=n_poses))
    if not res.success:
        notes.append(f"least squares did not converge: {res.message}")
    notes.extend(_misfit_notes(names, chi2, dof, has_sigma, resid_raw, y))
    notes.extend(separation_notes(names, est, std, corr))
    for a in (est, std, cov, corr, p0, poses, pose_index, y, yhat, w, resid_raw, rms, sens):
        a.setflags(write=False)
    return ModelFit(
        kind=kind,
        names=names,
        estimate=est,
        std=std,
        covariance=cov,
        correlation=corr,
        initial=p0,
        model=fitted,
        poses=poses,
        pose_index=pose_index,
        observed=y,
        predicted=yhat,
        sigma=w,
        residuals=resid_raw,
        residual_rms_per_pose=rms,
        chi2=chi2,
        dof=dof,
        reduced_chi2=red,
        condition=condition,
        sensitivity=sens,
        absolute_sigma=bool(absolute_sigma),
        converged=bool(res.success),
        nfev=int(res.nfev),
        message=str(res.message),
        notes=tuple(notes),
    )


def separation_notes(names, estimate, std, correlation) -> list[str]:
    """The fitted parameters whose standard error exceeds ``MAX_RELATIVE_STD`` times their
    value, named as what the data do not determine: one note per such parameter with those it
    is correlated with at ``|r| >= SEPARATION_CORRELATION`` (what the data cannot separate it
    from; a pair is named once).

    A strong correlation alone is not named: the Delta's ``k_theta`` and ``E_arm`` are
    correlated -0.999 and still determined to 0.02 % and 0.85 % on 48 positions (1 um).
    Parameters without a standard error (NaN) or at 0 (held by a bound) are skipped.
    """
    est, sd, r = np.asarray(estimate, float), np.asarray(std, float), np.asarray(correlation, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(np.isfinite(est) & (est != 0.0) & np.isfinite(sd), sd / np.abs(est), 0.0)
    out: list[str] = []
    named: set[int] = set()
    for i in np.flatnonzero(rel > MAX_RELATIVE_STD):
        if i in named:
            continue
        close = [j for j in range(len(names)) if j != i and abs(r[i, j]) >= SEPARATION_CORRELATION]
        named.update([i, *close])
        shown = [k for k in (i, *close) if rel[k] > 0]
        values = ", ".join(f"{names[k]} = {est[k]:.4g} ± {sd[k]:.3g} ({100 * rel[k]:.0f} %)" for k in shown)
        if close:
            pairs = ", ".join(f"{names[j]} (correlation {r[i, j]:+.4f})" for j in close)
            out.append(
                f"the data cannot separate {names[i]} from {pairs}: {values}; fix one of them or "
                "measure where their effects differ"
            )
        else:
            out.append(
                f"the data cannot determine {names[i]}: {values} (the standard error above the value); "
                "fix it or measure where it acts"
            )
    return out


def _check_valid_poses(model: Mechanism, P: np.ndarray, what: str) -> None:
    m = model.evaluate(P)
    if not np.all(m.valid):
        i = int(np.flatnonzero(~m.valid)[0])
        raise PoseError(
            f"{what} {i}: pose {format_pose(P[i])} {m.reasons[i]}; the model cannot be evaluated there",
            pose=P[i],
            index=i,
            reason=m.reasons[i],
        )


#: Below this chi-square probability (given standard errors) the fit is called a misfit.
MISFIT_P = 1e-3
#: Without standard errors: residual RMS above this fraction of the data RMS is a misfit.
MISFIT_RELATIVE = 0.1


def _misfit_notes(
    names, chi2: float, dof: int, has_sigma: bool, resid: np.ndarray, y: np.ndarray
) -> list[str]:
    """A note when the fitted model does not explain the data (a wrong parameter fitted?)."""
    fitted = ", ".join(names)
    hint = (
        f"the model with {fitted} fitted does not explain the measurements: another parameter may be "
        "wrong (a fixed one, or the geometry), or a measurement is"
    )
    if has_sigma and dof > 0:
        p = chi2_sf(chi2, dof)
        if p < MISFIT_P:
            return [
                f"{hint} (chi2/dof = {chi2 / dof:.3g} over {dof} dof, p = {p:.2g}; "
                "or the errors are underestimated)"
            ]
        return []
    rel = float(np.sqrt(np.mean(resid**2)) / max(np.sqrt(np.mean(y**2)), 1e-300))
    if dof > 0 and rel > MISFIT_RELATIVE:
        return [f"{hint} (residual RMS {100 * rel:.3g} % of the measurements' RMS)"]
    return []


def _stiffness_shape(model: Mechanism, P: np.ndarray, Km: np.ndarray) -> tuple[bool, int]:
    """Whether measured stiffnesses ``Km`` are K6 and their size (ValueError: a wrong shape, or
    a matrix with NaN or infinite values)."""
    six = model.dim == POSE_DIM and Km.shape[1:] == (6, 6)
    dim = 6 if six else (3 if model.dim == POSE_DIM else model.dim)
    if Km.shape != (P.shape[0], dim, dim):
        also = f" or ({P.shape[0]}, 6, 6) (K6)" if model.dim == POSE_DIM else ""
        raise ValueError(
            f"K must have shape ({P.shape[0]}, {dim}, {dim}){also} (one matrix per pose), got {Km.shape}"
        )
    if not np.all(np.isfinite(Km)):
        i = int(np.flatnonzero(~np.all(np.isfinite(Km), axis=(1, 2)))[0])
        raise ValueError(f"K of pose {i} contains NaN or infinite values")
    return six, dim


def fit_stiffness(
    model: Mechanism,
    points,
    K,
    *,
    params: Sequence[str] = ("k_theta",),
    K_std=None,
    absolute_sigma: bool = False,
) -> ModelFit:
    """Fit parameters to measured stiffness matrices.

    Parameters
    ----------
    model : Mechanism
        Starting values of the fitted parameters and values of the others.
    points : array_like, shape (n, dim), mm
        Poses of the measurements (base frame).
    K : array_like, shape (n, dim, dim), N/mm
        Measured stiffness at each pose (all entries are observations). For a robot whose
        platform turns (``dim = 6``, poses x, y, z mm, roll, pitch, yaw rad): K6, shape
        (n, 6, 6) (N/mm, N and N*mm/rad blocks; fitted to the model's ``K6``), or K of a pure
        force, shape (n, 3, 3).
    params : sequence of str
        Parameters to fit (names of ``model.params()``).
    K_std : array_like, shape of K, optional
        Standard errors of the entries (unit weights when omitted; for K6, weights
        ``s_i s_j`` with s = (1, 1, 1, L, L, L), L the model's ``length_mm`` (or 100 mm): the
        entries in mm and rad-as-L-mm alike).
    absolute_sigma : bool
        Take ``K_std`` as exact (do not rescale the covariance by the reduced chi-square).

    Returns
    -------
    ModelFit
        With ``kind = "stiffness"`` (``"stiffness6"`` for K6); observations are the entries of
        each K, row-major.

    Raises
    ------
    PoseError
        A pose the model cannot evaluate (named).
    DesignError
        The data cannot determine the parameters (see module docstring).
    """
    P, _ = as_points(points, model.dim)
    Km = np.asarray(K, dtype=np.float64)
    six, dim = _stiffness_shape(model, P, Km)
    S = _check_sigma(K_std, Km.shape, "K_std")
    weights = None
    if six and S is None:  # K6's entries in mm and rad-as-L-mm alike
        s = np.array([1.0, 1.0, 1.0, *(3 * [float(getattr(model, "length_mm", 100.0))])])
        weights = np.broadcast_to(np.outer(s, s), Km.shape).reshape(-1)
    _check_valid_poses(model, P, "pose")

    def predict(m: Mechanism) -> np.ndarray:
        mm = m.evaluate(P)
        return (mm.K6 if six else mm.K).reshape(-1)

    idx = np.repeat(np.arange(P.shape[0]), dim * dim)
    return _fit(
        "stiffness6" if six else "stiffness",
        model,
        params,
        predict,
        Km.reshape(-1),
        None if S is None else S.reshape(-1),
        P,
        idx,
        absolute_sigma,
        weights,
        views=_compliance_views(predict, Km),
    )


def _compliance_views(predict, Km: np.ndarray) -> tuple[LinearView, ...]:
    """The measured stiffness matrices as compliances ``K^-1`` (linear in a serial robot's joint
    compliances), their residuals carried back to stiffness by ``-K r K`` (none when a measured K
    is singular: the fit then starts from the given values)."""
    n, d = Km.shape[0], Km.shape[-1]
    try:
        Cm = np.linalg.inv(Km)
    except np.linalg.LinAlgError:
        return ()

    def compliances(m: Mechanism) -> np.ndarray:
        return np.linalg.inv(predict(m).reshape(n, d, d)).reshape(-1)

    def to_stiffness(r: np.ndarray) -> np.ndarray:
        return -(Km @ r.reshape(n, d, d) @ Km).reshape(-1)

    return (LinearView(compliances, Cm.reshape(-1), to_stiffness),)


def static_error_predictions(model: Mechanism, points, forces, directions) -> np.ndarray:
    """Predicted measured values ``n . K^-1 F`` (mm) of static-error observations.

    Parameters
    ----------
    points : array_like, shape (n, dim), mm
    forces : array_like, shape (n, dim), N
    directions : array_like, shape (n, dim)
        Unit measurement directions.

    Returns
    -------
    ndarray, shape (n,), mm
        NaN where the model cannot be evaluated.
    """
    P, _ = as_points(points, model.dim)
    uniq, inv = np.unique(P, axis=0, return_inverse=True)  # each pose evaluated once
    m = model.evaluate(uniq)
    inv = np.ravel(inv)
    F = as_forces(forces, P.shape[0], m.dim)
    u = np.full(F.shape, np.nan)
    v = m.valid[inv]
    if np.any(v):
        u[v] = np.linalg.solve(m.K[inv[v]], F[v][..., None])[..., 0]
    return np.einsum("ij,ij->i", u, np.asarray(directions, dtype=np.float64))


def fit_static_errors(
    model: Mechanism,
    points,
    forces,
    directions,
    values,
    *,
    params: Sequence[str] = ("kj",),
    std=None,
    absolute_sigma: bool = False,
) -> ModelFit:
    """Fit parameters to measured static errors, one displacement component per observation.

    Observation i: at pose ``points[i]`` the force ``forces[i]`` (N) moves the tool by
    ``K^-1 F`` and a sensor reads its component along the unit vector
    ``directions[i]``: ``values[i]`` (mm).

    Parameters
    ----------
    model : Mechanism
    points : array_like, shape (n, dim), mm
        (For ``dim = 6``: poses, x, y, z mm and roll, pitch, yaw rad.)
    forces : array_like, shape (n, dim) (n, 3 for dim = 6), N
        At the tool point.
    directions : array_like, shape (n, dim) (n, 3 for dim = 6)
        Measurement directions (unit vectors; refused when not of unit length within 1e-6).
    values : array_like, shape (n,), mm
    params : sequence of str
        Parameters to fit (names of ``model.params()``), e.g. ``("kj",)`` or ``("kj", "kb")``.
    std : array_like, shape (n,), mm, optional
        Standard errors of the values (unit weights when omitted).
    absolute_sigma : bool
        Take ``std`` as exact.

    Returns
    -------
    ModelFit
        With ``kind = "static_error"``; observations at the same pose share a pose index.

    Raises
    ------
    PoseError
        A pose the model cannot evaluate (named).
    DesignError
        The data cannot determine the parameters.
    """
    dim = model.dim
    P, _ = as_points(points, dim)
    n = P.shape[0]
    F = np.asarray(forces, dtype=np.float64)
    U = np.asarray(directions, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    fdim = 3 if dim == POSE_DIM else dim  # a turning platform's poses: forces still 3-D
    for a, name in ((F, "forces"), (U, "directions")):
        if a.shape != (n, fdim):
            raise ValueError(f"{name} must have shape ({n}, {fdim}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} contains NaN or infinite values")
    if y.shape != (n,) or not np.all(np.isfinite(y)):
        raise ValueError(f"values must be {n} finite numbers (mm), got shape {y.shape}")
    nrm = np.linalg.norm(U, axis=1)
    if np.any(np.abs(nrm - 1) > 1e-6):
        i = int(np.flatnonzero(np.abs(nrm - 1) > 1e-6)[0])
        raise ValueError(f"directions[{i}] = {U[i].tolist()} is not a unit vector (norm {nrm[i]:.6g})")
    if np.all(np.linalg.norm(F, axis=1) == 0):
        raise DesignError("every force is zero: static errors without load cannot determine stiffness")
    s = _check_sigma(std, (n,), "std")
    _check_valid_poses(model, P, "observation")
    poses, idx = _group_poses(P)

    def predict(m: Mechanism) -> np.ndarray:
        return static_error_predictions(m, P, F, U)

    return _fit("static_error", model, params, predict, y, s, poses, idx, absolute_sigma)


def _deflection_inputs(model: Mechanism, points, wrenches, deflections):
    """The poses, wrenches and deflections of :func:`fit_deflections6`, checked: (n, 6) each,
    finite, not every wrench zero."""
    if model.dim != POSE_DIM:
        raise ValueError(f"{model.name}: 6-DOF deflections need a platform that turns (dim = 6)")
    P, _ = as_points(points, POSE_DIM)
    n = P.shape[0]
    W = np.asarray(wrenches, dtype=np.float64)
    D = np.asarray(deflections, dtype=np.float64)
    for a, name in ((W, "wrenches"), (D, "deflections")):
        if a.shape != (n, 6):
            raise ValueError(f"{name} must have shape ({n}, 6), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} contains NaN or infinite values")
    if np.all(W == 0):
        raise DesignError("every wrench is zero: deflections without load cannot determine stiffness")
    return P, W, D


def _deflection_fitter(P: np.ndarray, W: np.ndarray, D: np.ndarray, params, absolute_sigma: bool):
    """``fit_with(start, Cx, absolute)``: the deflections fitted from the model ``start`` with
    the covariances ``Cx`` (whitened by them; None: relative weights, rad as L mm)."""
    n = P.shape[0]
    poses, idx = _group_poses(P)

    def predict(m: Mechanism) -> np.ndarray:
        K6 = m.evaluate(poses).K6[idx]
        return np.linalg.solve(K6, W[..., None])[..., 0].reshape(-1)

    y, obs_pose = D.reshape(-1), np.repeat(idx, 6)

    def fit_with(start: Mechanism, Cx: np.ndarray | None, absolute: bool = absolute_sigma) -> ModelFit:
        if Cx is None:  # no covariance: relative weights, rad as L mm
            L = float(getattr(start, "length_mm", 100.0))
            weights = np.tile([1.0, 1.0, 1.0, 1 / L, 1 / L, 1 / L], n)
            return _fit("deflection6", start, params, predict, y, None, poses, obs_pose, absolute, weights)
        sigma = np.sqrt(np.einsum("mii->mi", Cx)).reshape(-1)
        Linv = whitener(Cx, n, 6)
        return _fit("deflection6", start, params, predict, y, sigma, poses, obs_pose, absolute, whiten=Linv)

    return fit_with


def fit_deflections6(
    model: Mechanism,
    points,
    wrenches,
    deflections,
    *,
    params: Sequence[str],
    std=None,
    cov=None,
    extra_noise: bool = False,
    absolute_sigma: bool = False,
) -> ModelFit:
    """Fit parameters of a robot whose platform turns to its measured 6-DOF deflections.

    Observation i: at pose ``points[i]`` the wrench ``wrenches[i]`` at the tool point moves
    the platform by ``K6^-1 w`` (u mm, rotation vector rad), measured as ``deflections[i]``
    (the six components are six observations). A camera measures both; loads hung off the
    tool point give moments, so the fit sees the rotational block too (the hexapod analogue
    of :func:`~stiffmap.models.joint_fit.fit_joint_compliances`).

    Parameters
    ----------
    model : Mechanism
        With ``dim = 6`` (poses) and ``K6`` in its maps (:class:`~stiffmap.models.legs6.LegRobot6`).
    points : array_like, shape (n, 6)
        Poses: x, y, z (mm), roll, pitch, yaw (rad).
    wrenches : array_like, shape (n, 6)
        Force (N) and moment (N*mm) at the tool point, base frame.
    deflections : array_like, shape (n, 6)
        u (mm) and rotation vector (rad), base frame.
    params : sequence of str
    std : array_like, shape (n, 6), optional
        Standard errors of the deflections' components (mm, rad): each component weighed
        alone. Without ``std`` or ``cov`` the rotations weigh as the robot's size in mm
        (``length_mm``, else 100 mm) per rad.
    cov : array_like, shape (n, 6, 6), optional
        Each deflection's full covariance (mm^2, mm*rad, rad^2; symmetric positive definite):
        the residuals are whitened by its Cholesky factor (:mod:`~stiffmap.models.whiten`), so
        the correlations between a deflection's components count. Not with ``std``.
    extra_noise : bool
        Estimate a noise X (6 x 6, positive semidefinite) the given covariances leave out,
        shared by every deflection, and fit with ``cov + X`` (:func:`_extra_noise_fit`); the
        result's ``extra_covariance`` and a note give it, its standard errors are those of
        ``cov + X`` (``absolute_sigma`` True). Needs ``cov`` or ``std``.
    absolute_sigma : bool

    Returns
    -------
    ModelFit
        With ``kind = "deflection6"``; observations row-major (u then rotation per wrench);
        ``sigma`` the standard deviations of the components (with the extra noise).

    Raises
    ------
    PoseError, DesignError
        As :func:`fit_stiffness`.
    InputError
        ``cov`` of a wrong shape, not finite, symmetric or positive definite (its row named).
    """
    P, W, D = _deflection_inputs(model, points, wrenches, deflections)
    C = _deflection_cov(std, cov, P.shape[0])
    _check_valid_poses(model, P, "observation")
    fit_with = _deflection_fitter(P, W, D, params, absolute_sigma)
    if not extra_noise:
        return fit_with(model, C)
    if C is None:
        raise ValueError("extra_noise=True needs the deflections' covariances (cov or std)")
    return _extra_noise_fit(fit_with, model, C)


def _deflection_cov(std, cov, n: int) -> np.ndarray | None:
    """The deflections' covariances (n, 6, 6) from ``std`` or ``cov`` (None without either)."""
    if std is not None and cov is not None:
        raise ValueError("give std (each component alone) or cov (full covariances), not both")
    if std is not None:
        S = _check_sigma(std, (n, 6), "std")
        return np.einsum("mi,ij->mij", S**2, np.eye(6))
    if cov is None:
        return None
    C = as_float(cov, "cov")
    whitener(C, n, 6)  # its checks: shape, finite, symmetric, positive definite (the row named)
    return 0.5 * (C + np.swapaxes(C, 1, 2))


#: The extra noise's iteration stops when X changes by less than this (in units of the mean
#: given covariance, or of X when larger; far below X's sampling error, about sqrt(2 / n) for n
#: deflections) or after ``EXTRA_NOISE_ITERATIONS``.
EXTRA_NOISE_TOL = 1e-3
EXTRA_NOISE_ITERATIONS = 50


def _extra_noise_fit(fit_with, model: Mechanism, C: np.ndarray) -> ModelFit:
    """The fit with ``C + X``, X (6 x 6, PSD) the noise the covariances C (n, 6, 6) leave out.

    A moment estimate iterated to its fixed point: fit with ``C + X``; with r the deflections'
    residuals (n, 6), S = sum r r^T / (n - p/6) (the residuals' scatter, the parameters'
    share of it given back) and C_bar = mean C, ``X = L_b P+(L_b^-1 (S - C_bar) L_b^-T) L_b^T``
    (L_b the Cholesky factor of C_bar, P+ keeps the positive eigenvalues: X is the scatter in
    excess of the stated covariances, in every direction where there is an excess, measured in
    units of the stated covariance so that mm and rad are compared fairly). X = 0 when the
    residuals scatter no more than C says. The standard errors are those of ``C + X`` as given
    (``absolute_sigma``): X was estimated to explain the scatter, and scaling by chi2/dof again
    made them about 5 % short over simulated draws (X's positive part is biased upwards, so
    chi2/dof comes out a little below 1).
    """
    n = C.shape[0]
    Cbar = C.mean(axis=0)
    Lb = np.linalg.cholesky(Cbar)
    X = np.zeros((6, 6))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f0 = f = fit_with(model, C)
        for _ in range(EXTRA_NOISE_ITERATIONS):
            r = f.residuals.reshape(n, 6)
            S = r.T @ r / (n - len(f.names) / 6)
            A = np.linalg.solve(Lb, np.linalg.solve(Lb, S - Cbar).T)
            lam, V = np.linalg.eigh(0.5 * (A + A.T))
            A = (V * np.maximum(lam, 0.0)) @ V.T
            X_new = Lb @ A @ Lb.T
            step = np.linalg.norm(np.linalg.solve(Lb, np.linalg.solve(Lb, X_new - X).T))
            X = 0.5 * (X_new + X_new.T)
            if step <= EXTRA_NOISE_TOL * max(1.0, float(np.linalg.norm(A))):
                break
            f = fit_with(f.model, C + X)
    f = fit_with(f.model, C + X, absolute=True)  # X explains the scatter: no chi2/dof again
    X.setflags(write=False)
    if not np.any(X):
        return replace(f, initial=f0.initial, extra_covariance=X, notes=f0.notes)
    return replace(f, initial=f0.initial, extra_covariance=X, info=(_extra_note(f, f0, X),))


def _extra_note(f: ModelFit, f0: ModelFit, X: np.ndarray) -> str:
    """The extra noise in words: it replaces the given covariances' misfit note (``info``)."""
    s = np.sqrt(np.diag(X))
    note = (
        f"the deflections scatter more than their covariances say (chi2/dof = {f0.reduced_chi2:.3g} with "
        f"them alone): an extra noise was estimated and added to each, std per axis u "
        f"{', '.join(f'{v:.3g}' for v in s[:3])} mm, rotation {', '.join(f'{1e3 * v:.3g}' for v in s[3:])} "
        f"mrad (chi2/dof {f.reduced_chi2:.3g} with it)"
    )
    return note
