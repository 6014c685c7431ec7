"""The one central-difference Jacobian of the tests, which check every analytic Jacobian against it."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def central_jacobian(f: Callable[[np.ndarray], np.ndarray], x, step) -> np.ndarray:
    """Central differences ``(f(x + h e_k) - f(x - h e_k)) / (2 h)`` along the last axis of ``x``.

    Parameters
    ----------
    f : callable
        Takes an array shaped like ``x`` and returns an array of any shape S. A function
        vectorised over poses, (N, d) -> (N, m), gives the N Jacobians at once.
    x : float or ndarray, shape (..., d)
        Where to differentiate. For a scalar ``x`` the result is the derivative df/dx, shape S.
    step : float or ndarray, shape (d,)
        The step h of each variable, in its unit (one step for all, or one per variable when
        the variables have different units, e.g. mm and rad).

    Returns
    -------
    ndarray, shape (*S, d)
        Column k (last axis) is the derivative along variable k.

    Notes
    -----
    The error is the truncation term h^2 f'''/6 plus the rounding term eps |f| / h, smallest
    near h ~ eps^(1/3) |x| (about 1e-5 of the variable's scale). Each test chooses its steps
    for its variables' scales and units, and its tolerance from the resulting error.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 0:
        return (f(x + step) - f(x - step)) / (2 * step)
    d = x.shape[-1]
    steps = np.broadcast_to(np.asarray(step, dtype=float), (d,))
    cols = []
    for k in range(d):
        e = np.zeros(d)
        e[k] = steps[k]
        cols.append((f(x + e) - f(x - e)) / (2 * steps[k]))
    return np.stack(cols, axis=-1)
