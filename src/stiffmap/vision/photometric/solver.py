"""The solver of the photometric fit: damped Gauss-Newton (IRLS) and the noise model.

Gauss-Newton (Levenberg-Marquardt damped) with the analytic Jacobian of
:func:`~stiffmap.vision.photometric.model.model_and_jacobian` over the pose (perturbation t <- t + dt,
R <- Exp(dr) R in the camera frame, ``docs/conventions.md``), the blur and
dilation terms and the shading coefficients, started from the corner-based
pose: a first pass on an eighth of the pixels with equal weights, a noise model
var = alpha + beta I (read noise + photon shot noise) fitted to its residuals,
then all pixels with weights 1 / var and Huber weights (``huber`` noise sigmas)
against a partly bad region.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...geometry import displacement_from_poses
from ...posemath import perturb_pose
from .model import GEMM_SINGLE_THREAD, GEMV_SINGLE_THREAD, N_NONLINEAR, model_and_jacobian
from .pixels import PhotometricError, PhotometricSetup

__all__ = [
    "FitState",
    "Linearisation",
    "Solution",
    "gauss_newton",
    "linear_shading",
    "fit_noise_model",
    "wsum",
]

#: A chord step (the Jacobian, normal matrix and weights of an earlier linearisation, such as the
#: previous image's) ends a fit when that linearisation was taken within this many standard
#: deviations of the step's start (the metric of its normal matrix, all parameters) and the step
#: is itself shorter than this: the Jacobian changes by well under 1 % over such distances, so
#: the step leaves the fit within a few hundredths of a sigma of the optimum. Measured on the
#: nine image formations of benchmarks/bench_vision_speed.py: the default's poses differ from
#: cold fits' by 0.06-0.22 sigma RMS, and this rule (in place of steps of 3 sigma from a
#: linearisation at their start) moved them by < 0.01 sigma RMS. A step ending farther than
#: this from the linearisation linearises again where it ends.
CHORD_SIGMA = 10.0

#: Pixels per chunk of the fused model / Jacobian / normal-matrix evaluation: a chunk's ~20
#: single-precision arrays stay in a 2 MB cache (on such a machine, 16384 measured 20 % faster
#: per tracked image than 8192; 32768 and more no faster).
_CHUNK = 16384


def wsum(w: np.ndarray, e: np.ndarray) -> float:
    """sum w e^2, accumulated in double precision (elementwise: BLAS's dot product is threaded)."""
    return float(np.sum(w * e * e, dtype=np.float64))


def _weighted_gram(M: np.ndarray, w: np.ndarray, e: np.ndarray | None = None):
    """M diag(w) M^T for M of shape (p, N), summed over blocks of columns; with e, also M diag(w) e."""
    G = np.zeros((M.shape[0], M.shape[0]))
    g = np.zeros(M.shape[0])
    nk = max(64, min(GEMM_SINGLE_THREAD // M.shape[0] ** 2, GEMV_SINGLE_THREAD // M.shape[0]))
    for k in range(0, M.shape[1], nk):
        Mk = M[:, k : k + nk]
        Mw = Mk * w[k : k + nk]
        G += Mw @ Mk.T
        if e is not None:
            g += Mw @ e[k : k + nk]
    return G if e is None else (G, g)


def linear_shading(setup: PhotometricSetup, T, sig, dil) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares black level and contrast at a fixed pose, blur and dilation (linear in them)."""
    nb = setup.basis.shape[0]
    ones = np.zeros(nb)
    ones[0] = 1.0
    _, J = model_and_jacobian(setup, T, sig, dil, np.zeros(nb), ones)
    G, g = _weighted_gram(J[N_NONLINEAR:], np.ones(setup.n_pixels), setup.values)
    try:
        coef = np.linalg.solve(G, g)
    except np.linalg.LinAlgError:
        raise PhotometricError("the black level and contrast are undetermined") from None
    return coef[:nb], coef[nb:]


def _huber(r: np.ndarray, k: float) -> np.ndarray:
    a = np.abs(r)
    one = a.dtype.type(1.0)
    return np.where(a <= k, one, a.dtype.type(k) / np.maximum(a, np.finfo(a.dtype).tiny))


@dataclass
class FitState:
    T: np.ndarray
    sig: np.ndarray  # blur (3,), px
    dil: np.ndarray  # dilation (3,), px
    a: np.ndarray
    b: np.ndarray


@dataclass
class Solution:
    state: FitState
    iterations: int
    converged: bool
    e: np.ndarray  # residuals, DN: at the solution, or before its last step when a chord step ended it
    var: np.ndarray  # modelled noise variance, DN^2
    hw: np.ndarray  # Huber weights
    A: np.ndarray  # J^T W J at the last linearisation (p, p)
    lin: Linearisation | None = None  # the last linearisation, kept (chord steps)


@dataclass
class Linearisation:
    """A fit's last linearisation, kept for chord steps in the next image (same pixel set).

    ``evaluator`` holds the Jacobian and the weights at ``state``; ``A`` = J^T W J.
    """

    evaluator: _Evaluator
    A: np.ndarray
    state: FitState


class _Evaluator:
    """Residuals, noise, Huber weights and the normal equations of a state, chunk by chunk.

    The Jacobian of a chunk is written into one reused buffer, with the residuals as its
    last row, and its weighted Gram matrix [J; e] W [J; e]^T is accumulated at once (in
    double precision, over blocks of columns: a float32 set-up computes the model and the
    Jacobian in single precision). With ``keep``, the whole Jacobian of the last
    linearisation and the model there are kept (one buffer per chunk), for :meth:`gradient`
    and :meth:`predict`: a new linearisation is written beside the kept one and replaces it
    only when :meth:`commit` is called (its step accepted).
    """

    def __init__(self, setup: PhotometricSetup, noise_var, huber: float, keep: bool = False) -> None:
        self.setup = setup
        self.noise_var = noise_var
        self.huber = huber
        n = setup.n_pixels
        self.dtype = setup.values.dtype
        self.chunks = [setup.slice(k, min(k + _CHUNK, n)) for k in range(0, n, _CHUNK)]
        self.p = N_NONLINEAR + 2 * setup.basis.shape[0]
        self.keep = keep
        self.nv = max(64, GEMV_SINGLE_THREAD // self.p)
        if keep:
            # Columns padded with zeros to a multiple of nv: J W e as one batched product of
            # (p, nv) blocks, each below OpenBLAS's threading size.
            self.bufs = [
                np.zeros((self.p + 1, -(-ch.n_pixels // self.nv) * self.nv), dtype=self.dtype)
                for ch in self.chunks
            ]
            self._spare = [np.zeros_like(b) for b in self.bufs]
        else:
            buf = np.empty((self.p + 1, min(_CHUNK, n)), dtype=self.dtype)
            self.bufs = [buf] * len(self.chunks)
        # With keep: the model at the last linearisation, per chunk (its row p of bufs is e).
        self.models: list[np.ndarray] | None = None
        self.weights: np.ndarray | None = None
        self.var_lin: np.ndarray | None = None  # the noise variance at the linearisation
        self.lin_state: FitState | None = None
        self._staged: tuple | None = None
        self.nk = max(64, GEMM_SINGLE_THREAD // (self.p + 1) ** 2)

    def __call__(self, st: FitState, jacobian: bool = True):
        p = self.p
        es, vs, hs, ms = [], [], [], []
        G = np.zeros((p + 1, p + 1)) if jacobian else None
        bufs = self._spare if self.keep and jacobian else self.bufs
        for ch, buf in zip(self.chunks, bufs, strict=True):
            n = ch.n_pixels
            M = buf[:, :n]
            m, _ = model_and_jacobian(ch, st.T, st.sig, st.dil, st.a, st.b, jacobian=jacobian, out=M[:p])
            ms.append(m)
            e = ch.values - m
            var = self.noise_var(m)
            hw = _huber(e / np.sqrt(var), self.huber)
            if jacobian:
                M[p] = e
                w = hw / var
                for k in range(0, n, self.nk):
                    Mk = M[:, k : k + self.nk]
                    G += (Mk * w[k : k + self.nk]) @ Mk.T
            es.append(e)
            vs.append(var)
            hs.append(hw)
        e, var, hw = (np.concatenate(x) for x in (es, vs, hs))
        if not jacobian:
            return e, var, hw, None, None
        if self.keep:
            self._staged = (st, ms, hw / var, var)
        return e, var, hw, G[:p, :p], G[:p, p]

    def commit(self) -> None:
        """Keep the last linearisation computed (its Jacobian, model, weights and state)."""
        if self.keep and self._staged is not None:
            self.bufs, self._spare = self._spare, self.bufs
            self.lin_state, self.models, self.weights, self.var_lin = self._staged
            self._staged = None

    def predict(self, st: FitState):
        """Residuals, noise and Huber weights at ``st`` from the kept linearisation, m(x_L) +
        J_L (st - x_L), instead of the model (:data:`CHORD_SIGMA`: within it of x_L, the
        difference is below a hundredth of the noise)."""
        if self.models is None or self.lin_state is None:  # pragma: no cover - guarded by the caller
            raise RuntimeError("no linearisation kept")
        p, nv = self.p, self.nv
        delta = _parameter_change(st, self.lin_state).astype(self.dtype)
        es, vs, hs = [], [], []
        for ch, buf, m_lin in zip(self.chunks, self.bufs, self.models, strict=True):
            n, npad = ch.n_pixels, buf.shape[1]
            K = npad // nv
            # delta^T J over blocks of nv columns, each below OpenBLAS's threading size.
            J = buf[:p].reshape(p, K, nv).transpose(1, 0, 2)
            m = (delta @ J).reshape(npad)[:n]
            m += m_lin
            e = ch.values - m
            var = self.noise_var(m)
            es.append(e)
            vs.append(var)
            hs.append(_huber(e / np.sqrt(var), self.huber))
        return tuple(np.concatenate(x) for x in (es, vs, hs))

    def rebind(self, setup: PhotometricSetup, noise_var) -> None:
        """The same pixels (and kept Jacobian) with another image's values and noise model."""
        if setup.n_pixels != self.setup.n_pixels:  # pragma: no cover - guarded by the caller
            raise ValueError("a kept linearisation needs the same pixels")
        n = setup.n_pixels
        self.setup = setup
        self.noise_var = noise_var
        self.chunks = [setup.slice(k, min(k + _CHUNK, n)) for k in range(0, n, _CHUNK)]

    def gradient(self, e: np.ndarray, w: np.ndarray) -> np.ndarray:
        """J W e with the Jacobian of the kept linearisation and the weights ``w``, float64."""
        if self.models is None:  # pragma: no cover - guarded by the caller
            raise RuntimeError("no linearisation kept")
        we = (w * e).astype(self.dtype, copy=False)
        g = np.zeros(self.p)
        start = 0
        for ch, buf in zip(self.chunks, self.bufs, strict=True):
            n, npad = ch.n_pixels, buf.shape[1]
            wk = np.zeros(npad, dtype=self.dtype)
            wk[:n] = we[start : start + n]
            K = npad // self.nv
            J = buf[: self.p].reshape(self.p, K, self.nv).transpose(1, 0, 2)
            g += (J @ wk.reshape(K, self.nv, 1)).sum(axis=0)[:, 0]
            start += n
        return g


def gauss_newton(
    setup: PhotometricSetup,
    st: FitState,
    noise_var,
    huber: float,
    max_iter: int,
    tol: float = 0.1,
    *,
    chord: int = 0,
    start: Linearisation | None = None,
    watch=None,
) -> Solution:
    """Damped Gauss-Newton (IRLS) from ``st``; ``noise_var(model)`` -> variance per pixel (DN^2).

    ``chord`` = 0: converged when a step is below ``tol`` standard deviations of the
    parameters (its length in the metric of the normal matrix, sqrt(d^T A d)): the step is
    taken and the next one would be smaller still by the (linear) rate of convergence. The
    normal matrix returned is that of the last linearisation (less than ``tol`` sigma away).

    ``chord`` > 0 (a start a few sigma from the optimum): steps reuse the last linearisation's
    Jacobian, normal matrix and weights (the chord method: the gradient J W e at the new
    residuals, one model evaluation and no new Jacobian per step) while they end within
    :data:`CHORD_SIGMA` of where it was taken, for up to ``chord`` steps in a row; a step from a
    linearisation within :data:`CHORD_SIGMA` of its start, itself shorter than that, ends the
    fit without evaluating the model again (see :data:`CHORD_SIGMA`; ``tol`` then plays no
    part, and the normal matrix returned may be up to 2 :data:`CHORD_SIGMA` away); a step
    that does not lower the cost linearises again. The chord steps take the linearisation's
    weights, the step that ends the fit this state's Huber weights over the linearisation's
    noise variance. ``start``: the fit starts with that linearisation (the previous image's,
    on the same pixels, near ``st``), with no Jacobian computed here unless the fit moves too
    far from it. The solution keeps its last linearisation (``lin``) when ``chord``.
    ``watch(state)``, called after every step taken, may raise to stop the fit (a
    :class:`~stiffmap.vision.photometric.pixels.PhotometricError`).
    """
    nb = setup.basis.shape[0]
    evaluate, cur = _first_iterate(setup, st, noise_var, huber, chord, start)
    # Single precision rounds the model by ~1e-3 DN, which moves the cost by up to ~1 (chi^2):
    # steps within that are taken as not raising it (a diverging step raises it far more).
    slack = 1.0 if evaluate.dtype == np.float32 else 0.0
    lam = 1e-6
    it = 0
    chords = 0
    converged = False
    while it < max_iter:
        it += 1
        trial, lam = _trial_step(evaluate, cur, lam, tol, chord, chords, nb, slack)
        if not trial.accepted and (chords or not cur.fresh):
            _linearise(evaluate, cur)
            chord = chords = 0  # plain Gauss-Newton from here
            continue
        if not trial.accepted:
            converged = True  # no step lowers the cost: at the minimum to rounding
            break
        cur.st, cur.e, cur.var, cur.hw = trial.new, trial.e2, trial.var2, trial.hw2
        if watch is not None:
            watch(cur.st)
        lam = max(lam / 10, 1e-9)
        if trial.ended or (trial.last and cur.fresh):
            converged = True
            break
        if trial.relinearise:
            evaluate.commit()
            cur.A, cur.g = trial.A2, trial.g2
            cur.w = cur.hw / cur.var
            chords = 0
            cur.fresh = cur.near = True
        else:
            cur.near = _distance_sigma(cur.st, evaluate.lin_state, cur.A) < CHORD_SIGMA
            cur.w = evaluate.weights
            cur.g = evaluate.gradient(cur.e, cur.w)
            chords += 1
            cur.fresh = False
    lin = Linearisation(evaluate, cur.A, evaluate.lin_state) if evaluate.keep else None
    return Solution(cur.st, it, converged, cur.e, cur.var, cur.hw, cur.A, lin)


@dataclass
class _Iterate:
    """The fit's current state, its residuals, noise variance and Huber weights, and the normal
    matrix A, gradient g and weights w the next step is solved with. ``fresh``: the
    linearisation was taken at ``st``; ``near``: at ``st`` or near enough for a chord step to
    end the fit."""

    st: FitState
    e: np.ndarray
    var: np.ndarray
    hw: np.ndarray
    A: np.ndarray
    g: np.ndarray
    w: np.ndarray
    fresh: bool
    near: bool


def _first_iterate(setup, st, noise_var, huber, chord, start) -> tuple[_Evaluator, _Iterate]:
    """The evaluator and the first iterate: from ``start``'s linearisation (a chord fit near the
    previous image's), else a linearisation at ``st``."""
    if start is not None and chord > 0:
        evaluate = start.evaluator
        evaluate.rebind(setup, noise_var)
        A = start.A
        near = _distance_sigma(st, evaluate.lin_state, A) < CHORD_SIGMA
        if near:
            # Near the linearisation: the model there and its Jacobian give the residuals.
            e, var, hw = evaluate.predict(st)
        else:
            e, var, hw, _, _ = evaluate(st, jacobian=False)
        w = evaluate.weights
        g = evaluate.gradient(e, w)
        # fresh False: the linearisation is the previous image's, not at st
        return evaluate, _Iterate(st, e, var, hw, A, g, w, fresh=False, near=near)
    evaluate = _Evaluator(setup, noise_var, huber, keep=chord > 0)
    cur = _Iterate(st, *([None] * 6), fresh=True, near=True)
    _linearise(evaluate, cur)
    return evaluate, cur


def _linearise(evaluate: _Evaluator, cur: _Iterate) -> None:
    """Linearise at the current state (plain Gauss-Newton's step)."""
    cur.e, cur.var, cur.hw, cur.A, cur.g = evaluate(cur.st)
    evaluate.commit()
    cur.w = cur.hw / cur.var
    cur.fresh = cur.near = True


@dataclass
class _Trial:
    """The outcome of one iteration's step: whether one was ``accepted`` (the new state, its
    residuals, noise and Huber weights, and its normal matrix and gradient when
    ``relinearise``), whether it ``ended`` the fit (a chord step) or was the ``last``
    (shorter than the tolerance)."""

    accepted: bool = False
    ended: bool = False
    last: bool = False
    relinearise: bool = True
    new: FitState | None = None
    e2: np.ndarray | None = None
    var2: np.ndarray | None = None
    hw2: np.ndarray | None = None
    A2: np.ndarray | None = None
    g2: np.ndarray | None = None


def _trial_step(evaluate, cur: _Iterate, lam, tol, chord, chords, nb, slack) -> tuple[_Trial, float]:
    """A damped step from the current iterate, the damping raised until the cost does not
    increase (up to 10 attempts; a chord step that fails is not retried); the damping after."""
    cost = wsum(cur.w, cur.e)
    d = np.sqrt(np.diag(cur.A))
    d[d == 0] = 1.0
    An = cur.A / np.outer(d, d)
    gn = cur.g / d
    trial = _Trial()
    for attempt in range(10):
        M = An + lam * np.eye(An.shape[0])
        try:
            step = np.linalg.solve(M, gn) / d
        except np.linalg.LinAlgError:
            lam = max(lam * 10, 1e-6)
            continue
        new = _moved(cur.st, step, nb)
        if new is None:
            lam = max(lam * 10, 1e-6)
            continue
        length2 = float(step @ cur.A @ step)
        trial.last = length2 < tol * tol
        trial.relinearise = True
        if chord:
            if attempt == 0 and cur.near and length2 < CHORD_SIGMA**2:
                end = _ending_step(evaluate, cur, M, d, nb)
                if end is not None:
                    trial.new, trial.e2, trial.var2, trial.hw2 = end, cur.e, cur.var, cur.hw
                    trial.accepted = trial.ended = True
                    break
            trial.relinearise = (
                chords >= chord or not _distance_sigma(new, evaluate.lin_state, cur.A) < CHORD_SIGMA
            )
        trial.new = new
        trial.e2, trial.var2, trial.hw2, trial.A2, trial.g2 = evaluate(new, jacobian=trial.relinearise)
        # Cost at the same weights (IRLS): accept when it does not increase.
        if wsum(cur.w, trial.e2) <= cost * (1 + 1e-12) + slack:
            trial.accepted = True
            break
        if chords:  # a chord step that fails: linearise again where we are
            break
        lam = max(lam * 10, 1e-6)
    return trial, lam


def _ending_step(evaluate, cur: _Iterate, M, d, nb) -> FitState | None:
    """The last step of a chord fit, taken without evaluating the model again (None when it
    is not finite or not shorter than :data:`CHORD_SIGMA`).

    The residuals, noise and weights stay those before it (the cost they give is higher by at
    most CHORD_SIGMA^2 = 100 in sum w e^2 ~ N: s^2 by < 100 / N, 0.3 % for the ~30000 pixels of
    a board). Its gradient takes this state's Huber weights (over the linearisation's noise
    variance, its normal matrix's): the board barely moved, its residuals are at noise level
    but for real outliers, and a pixel newly hidden is down-weighted. (The chord steps before
    keep the linearisation's: a board that moved by 100 sigma has residuals of a few noise
    sigmas along every edge, which its own Huber weights would cut.)
    """
    end_step = np.linalg.solve(M, evaluate.gradient(cur.e, cur.hw / evaluate.var_lin) / d) / d
    end = _moved(cur.st, end_step, nb)
    if end is not None and float(end_step @ cur.A @ end_step) < CHORD_SIGMA**2:
        return end
    return None


def _moved(st: FitState, step: np.ndarray, nb: int) -> FitState | None:
    """The state moved by a step (its pose as :func:`~stiffmap.posemath.perturb_pose`); None when
    the step is not finite or leaves the blur's least sigma (over the edges' directions) at
    0.05 px or less."""
    sig = st.sig + step[6:9]
    if not np.isfinite(step).all() or sig[0] - np.hypot(sig[1], sig[2]) <= 0.05:
        return None
    return FitState(
        perturb_pose(st.T, step),
        sig,
        st.dil + step[9:12],
        st.a + step[N_NONLINEAR : N_NONLINEAR + nb],
        st.b + step[N_NONLINEAR + nb :],
    )


def _parameter_change(a: FitState, b: FitState) -> np.ndarray:
    """The parameters' change from ``b`` to ``a`` (the pose part as the perturbation of
    :func:`~stiffmap.posemath.perturb_pose`), shape (p,)."""
    return np.concatenate(
        [displacement_from_poses(b.T, a.T), a.sig - b.sig, a.dil - b.dil, a.a - b.a, a.b - b.b]
    )


def _distance_sigma(a: FitState, b: FitState, A: np.ndarray) -> float:
    """The length of the parameter change from ``b`` to ``a`` in the metric of A, sigmas."""
    d = _parameter_change(a, b)
    return float(np.sqrt(max(d @ A @ d, 0.0)))


def fit_noise_model(m: np.ndarray, e: np.ndarray) -> tuple[float, float]:
    """var = alpha + beta m from squared residuals (outliers beyond 4 robust sigma left out)."""
    mad = 1.4826 * np.median(np.abs(e - np.median(e)))
    keep = np.abs(e) < 4.0 * max(mad, 1e-6)
    mk, e2 = m[keep], e[keep] ** 2
    # Straight-line fit of e^2 against m (normal equations, elementwise sums).
    mm, ee = float(mk.mean()), float(e2.mean())
    sxx = float(np.sum((mk - mm) ** 2))
    beta = float(np.sum((mk - mm) * (e2 - ee))) / sxx if sxx > 0 else 0.0
    alpha = ee - beta * mm
    floor = max(0.05 * float(np.mean(e[keep] ** 2)), 1.0 / 12.0)
    beta = max(beta, 0.0)
    if alpha < floor:
        alpha = floor
    return alpha, beta
