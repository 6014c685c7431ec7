"""A small 3-D frame finite-element model (Euler-Bernoulli beams, direct stiffness method).

Independent of stiffmap's models: the tests build parallel robots' legs from beams with
joint releases, tie them to a rigid platform, and condense the assembly on the platform's
six coordinates, to check the virtual joint method's 6 x 6 stiffness against it.

Units: mm, N, MPa. A node has six coordinates (u mm, rotation vector rad), base frame.
"""

from __future__ import annotations

import numpy as np


def beam_local(L: float, E: float, G: float, A: float, I: float, J: float) -> np.ndarray:
    """The 12 x 12 stiffness of a straight beam of circular section in its own axes (x along it).

    Coordinates per end: u, v, w (mm), rx, ry, rz (rad); the textbook Euler-Bernoulli
    element (Przemieniecki, *Theory of Matrix Structural Analysis*, 1968, eq. 5.116).
    """
    k = np.zeros((12, 12))
    a, t = E * A / L, G * J / L
    b3, b2, b1 = 12 * E * I / L**3, 6 * E * I / L**2, E * I / L
    k[0, 0] = k[6, 6] = a
    k[0, 6] = -a
    k[3, 3] = k[9, 9] = t
    k[3, 9] = -t
    # bending in the x-y plane: v and rz
    k[1, 1] = k[7, 7] = b3
    k[1, 7] = -b3
    k[1, 5] = k[1, 11] = b2
    k[5, 7] = k[7, 11] = -b2
    k[5, 5] = k[11, 11] = 4 * b1
    k[5, 11] = 2 * b1
    # bending in the x-z plane: w and ry
    k[2, 2] = k[8, 8] = b3
    k[2, 8] = -b3
    k[2, 4] = k[2, 10] = -b2
    k[4, 8] = k[8, 10] = b2
    k[4, 4] = k[10, 10] = 4 * b1
    k[4, 10] = 2 * b1
    return np.triu(k) + np.triu(k, 1).T


def beam_global(p1, p2, E: float, G: float, A: float, I: float, J: float) -> np.ndarray:
    """The beam from p1 to p2 (mm) in base axes: ``T^T k T``, shape (12, 12)."""
    p1, p2 = np.asarray(p1, dtype=float), np.asarray(p2, dtype=float)
    L = float(np.linalg.norm(p2 - p1))
    x = (p2 - p1) / L
    helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(helper, x)
    y /= np.linalg.norm(y)
    lam = np.stack([x, y, np.cross(x, y)])  # rows: the beam's axes in base coordinates
    T = np.kron(np.eye(4), lam)
    return T.T @ beam_local(L, E, G, A, I, J) @ T


def condensed(K: np.ndarray, keep: int) -> np.ndarray:
    """Static condensation on the first ``keep`` coordinates: ``K_kk - K_ki K_ii^-1 K_ik``."""
    Kkk, Kki, Kii = K[:keep, :keep], K[:keep, keep:], K[keep:, keep:]
    return Kkk - Kki @ np.linalg.solve(Kii, Kki.T)


def rps_leg_platform_stiffness(base, axes, tips, tool, E, G, A, I, J, n_elements: int = 2) -> np.ndarray:
    """K6 at ``tool`` of a rigid platform on legs of beams: revolute at the base, ball at the top.

    Each leg is ``n_elements`` beams from ``base[i]`` to ``tips[i]`` (mm, base frame). At the
    base node the translations and the rotations other than about ``axes[i]`` are held (the
    revolute joint); at the top node the translations follow the platform
    (``u + theta x (tip - tool)``) and the rotations are the node's own (the ball joint).

    Returns
    -------
    ndarray, shape (6, 6)
        The platform's stiffness at ``tool``, base frame (N/mm, N, N*mm/rad).
    """
    n_legs = len(base)
    n_inner = n_elements - 1
    per_leg = 1 + 6 * n_inner + 3  # base rotation, inner nodes, top rotation
    n = 6 + n_legs * per_leg
    K = np.zeros((n, n))
    for i in range(n_legs):
        off = 6 + i * per_leg
        b, t = np.asarray(base[i], dtype=float), np.asarray(tips[i], dtype=float)
        w = np.asarray(axes[i], dtype=float) / np.linalg.norm(axes[i])
        r = t - np.asarray(tool, dtype=float)
        # node maps: node coordinates (6) = G @ the model's unknowns (n)
        nodes = []
        G0 = np.zeros((6, n))
        G0[3:, off] = w
        nodes.append((b, G0))
        for j in range(1, n_elements):
            Gj = np.zeros((6, n))
            Gj[:, off + 1 + 6 * (j - 1) : off + 1 + 6 * j] = np.eye(6)
            nodes.append((b + (t - b) * j / n_elements, Gj))
        Gt = np.zeros((6, n))
        Gt[:3, :3] = np.eye(3)
        Gt[:3, 3:6] = -np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
        Gt[3:, off + per_leg - 3 : off + per_leg] = np.eye(3)
        nodes.append((t, Gt))
        for (p1, G1), (p2, G2) in zip(nodes[:-1], nodes[1:], strict=True):
            Ge = np.vstack([G1, G2])
            K += Ge.T @ beam_global(p1, p2, E, G, A, I, J) @ Ge
    return condensed(0.5 * (K + K.T), 6)
