"""Independent deflection solvers and path checks for the machining tests.

None of these goes through ``stiffmap.machining`` or the models' stiffness code:

- :func:`truss_3prr`: the milling study's plane truss (its Figs. 7-8, eqs. 4-6) assembled
  and solved by direct stiffness in this file: the tool node and three slider nodes, three
  bar elements E A / L, and at each slider a spring kj along its rail and kb across it. The
  slider positions come from the study's eqs. 1-3 solved here.
- :func:`arm_deflection`: the six-joint arm's tool-point deflection ``C = J K^-1 J^T`` with
  J the central-difference Jacobian of the chain's forward kinematics (position and the
  rotation vector of R R0^T), configurations by the chain's damped least squares.
- :func:`delta_deflection`: the Delta's ``K = J^T k_theta J`` with ``J = dtheta/dP`` by
  central differences of its inverse kinematics (the actuators are its only springs).
"""

from __future__ import annotations

import math

import numpy as np

from stiffmap.geometry import rotvec_from_matrix

S3 = math.sqrt(3.0)


def truss_3prr(points, force, *, h, L, EA, kj, kb) -> np.ndarray:
    """Tool deflections (N, 2) mm of the 3PRR truss at tool positions (N, 2) mm under forces (N, 2) N."""
    T = np.asarray(points, dtype=float)
    F = np.broadcast_to(np.asarray(force, dtype=float), T.shape)
    V = np.array([[0.0, 0.0], [h, 0.0], [h / 2, S3 / 2 * h]])
    u = np.array([[S3 / 2, 0.5], [-S3 / 2, 0.5], [0.0, -1.0]])
    up = np.stack([-u[:, 1], u[:, 0]], axis=1)
    n = T.shape[0]
    K = np.zeros((n, 8, 8))
    for i in range(3):
        d = T - V[i]
        s = d @ u[i]
        w = d @ up[i]
        li = s - np.sqrt(L * L - w * w)  # eqs. 1-3: the slider behind the tool's foot on its rail
        S = V[i] + li[:, None] * u[i]
        e = (T - S) / L
        kb_ = (EA / L) * np.einsum("ni,nj->nij", e, e)  # bar element, eq. 5 in the global frame
        dofs = [0, 1, 2 + 2 * i, 3 + 2 * i]
        blk = np.block([[kb_, -kb_], [-kb_, kb_]])
        for a, da in enumerate(dofs):
            for b, db in enumerate(dofs):
                K[:, da, db] += blk[:, a, b]
        Ks = kj * np.outer(u[i], u[i]) + kb * np.outer(up[i], up[i])
        K[:, 2 + 2 * i : 4 + 2 * i, 2 + 2 * i : 4 + 2 * i] += Ks
    rhs = np.zeros((n, 8))
    rhs[:, :2] = F
    return np.linalg.solve(K, rhs[..., None])[:, :2, 0]


def arm_deflection(chain, k_theta, rotation, points, forces, q0, spins=None) -> tuple[np.ndarray, np.ndarray]:
    """Deflections (N, 3) mm of the arm's tool point at positions (N, 3) mm (base frame) holding
    ``rotation`` (turned by ``spins`` about the base z), solved in order from ``q0``; and the last q."""
    P = np.asarray(points, dtype=float)
    F = np.asarray(forces, dtype=float)
    kinv = 1.0 / np.asarray(k_theta, dtype=float)
    out = np.zeros_like(P)
    q = np.asarray(q0, dtype=float)
    for i in range(P.shape[0]):
        R = rotation
        if spins is not None:
            c, s = math.cos(spins[i]), math.sin(spins[i])
            R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ rotation
        r = chain.inverse(P[i], R, q0=q)
        assert r.converged, f"IK of the check did not converge at {P[i]}"
        q = r.q
        J = _fd_jacobian(chain, q)
        C = J @ np.diag(kinv) @ J.T
        out[i] = C[:3, :3] @ F[i]
    return out, q


def _fd_jacobian(chain, q, h=1e-6) -> np.ndarray:
    """6 x n: tool-point velocity (mm/rad) and angular velocity (rad/rad), central differences."""
    p0, R0 = chain.forward(q)
    J = np.zeros((6, q.size))
    for k in range(q.size):
        dq = np.zeros(q.size)
        dq[k] = h
        pp, Rp = chain.forward(q + dq)
        pm, Rm = chain.forward(q - dq)
        J[:3, k] = (pp - pm) / (2 * h)
        J[3:, k] = (rotvec_from_matrix(Rp @ R0.T) - rotvec_from_matrix(Rm @ R0.T)) / (2 * h)
    return J


def delta_deflection(delta, points, forces, h=1e-4) -> np.ndarray:
    """Deflections (N, 3) mm of a Delta with rigid links: K = k_theta J^T J, J = dtheta/dP by central
    differences of its inverse kinematics."""
    P = np.asarray(points, dtype=float)
    F = np.asarray(forces, dtype=float)
    J = np.zeros((P.shape[0], 3, 3))
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        tp = delta.inverse_kinematics(P + d).q
        tm = delta.inverse_kinematics(P - d).q
        J[:, :, k] = (tp - tm) / (2 * h)
    K = delta.k_theta * np.einsum("nki,nkj->nij", J, J)
    return np.linalg.solve(K, F[..., None])[..., 0]


def output_samples(path, per_mm: float = 2.0, minimum: int = 9):
    """Dense samples along the feed moves of a (compensated) toolpath: move index, s, point."""
    L = path.length()
    ms, ss = [], []
    for m in np.flatnonzero(path.feed):
        k = max(minimum, int(math.ceil(L[m] * per_mm)) + 1)
        ms.append(np.full(k, m))
        ss.append(np.linspace(0.0, 1.0, k))
    m = np.concatenate(ms)
    s = np.concatenate(ss)
    return m, s, path.point(m, s)


def distance_to_path(path, Q) -> np.ndarray:
    """Distance (mm) of points (N, 3) to the nearest feed move of a programmed toolpath."""
    feed = np.flatnonzero(path.feed)
    best = np.full(Q.shape[0], np.inf)
    for m in feed:
        best = np.minimum(best, path.distance(np.full(Q.shape[0], m), Q))
    return best
