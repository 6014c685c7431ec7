"""Rigid transforms, orientation and compliant displacements.

Conventions (see ``docs/conventions.md``):

- A transform is a 4x4 homogeneous matrix named ``a2b``: it maps coordinates in
  frame ``a`` to frame ``b`` (the reference paper's :math:`{}^{B}A_{A}`).
  ``concat(a2b, b2c)`` returns ``a2c``.
- Lengths in mm, angles in rad.
- Orientation is stored as rotation matrices. The reference paper's Euler angles
  (psi about X, phi about Y, theta about Z, R = Rz(theta) Ry(phi) Rx(psi), its
  eqs. 3-5) are a view for reports.
- The compliant displacement between an unloaded and a loaded pose is the
  6-vector (dx, dy, dz, rx, ry, rz): the translation difference (mm) and the
  rotation vector (rad) of R_loaded R_unloaded^T, both in the frame the poses
  are expressed in (the robot base frame in a campaign).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "as_transform",
    "transform_from",
    "invert_transform",
    "concat",
    "transform_points",
    "euler_from_matrix",
    "matrix_from_euler",
    "rotvec_from_matrix",
    "matrix_from_rotvec",
    "cam2base_from_fixed",
    "displacement_from_poses",
    "displacement_at_point",
    "stiffness_in_frame",
    "mean_transform",
]


_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])


def _as_array(x, shape: tuple[int, ...], name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape[-len(shape) :] != shape:
        raise ValueError(f"{name} must have shape (..., {', '.join(map(str, shape))}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return a


def as_transform(a2b, name: str = "transform", *, atol: float = 1e-6) -> np.ndarray:
    """Check and return a rigid transform as float64.

    Parameters
    ----------
    a2b : array_like, shape (..., 4, 4)
        Homogeneous transform(s); translation in mm.
    name : str
        Used in error messages.
    atol : float
        Tolerance on the orthonormality of the rotation block and on the last row.

    Raises
    ------
    ValueError
        If the shape is wrong, a value is not finite, the last row is not
        (0, 0, 0, 1) or the rotation block is not a proper rotation.
    """
    T = _as_array(a2b, (4, 4), name)
    if T.ndim == 2 and _is_rigid(T, atol):
        return T  # one transform, checked on floats (it runs inside the pose fits: 5x faster)
    # Elementwise |a - b| <= atol is np.allclose with rtol = 0, at a sixth of its cost (this
    # check runs inside the pose fits' iterations).
    if not np.all(np.abs(T[..., 3, :] - _LAST_ROW) <= atol):
        raise ValueError(f"{name}: last row must be [0, 0, 0, 1], got {T[..., 3, :].tolist()}")
    R = T[..., :3, :3]
    big = float(np.abs(R).max())
    if big > 1.0 + atol:  # before R^T R, which would overflow for entries near 1e308
        raise ValueError(
            f"{name}: the 3x3 block is not a rotation matrix (an entry of {big:.3g}, beyond +-1)"
        )
    err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max()
    if err > atol or np.any(np.linalg.det(R) <= 0):
        raise ValueError(
            f"{name}: the 3x3 block is not a rotation matrix (orthonormal, det +1): "
            f"|R^T R - I| = {err:.2e}, det = {np.linalg.det(R)}"
        )
    return T


def _is_rigid(T: np.ndarray, atol: float) -> bool:
    """Whether one (4, 4) transform passes :func:`as_transform`'s checks (False: let it say why)."""
    (r00, r01, r02, _), (r10, r11, r12, _), (r20, r21, r22, _), last = T.tolist()
    if abs(last[0]) > atol or abs(last[1]) > atol or abs(last[2]) > atol or abs(last[3] - 1.0) > atol:
        return False
    cols = ((r00, r10, r20), (r01, r11, r21), (r02, r12, r22))
    for i in range(3):
        for j in range(i, 3):
            a, b = cols[i], cols[j]
            if abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] - (1.0 if i == j else 0.0)) > atol:
                return False
    det = r00 * (r11 * r22 - r12 * r21) - r01 * (r10 * r22 - r12 * r20) + r02 * (r10 * r21 - r11 * r20)
    return det > 0


def transform_from(R, t) -> np.ndarray:
    """Homogeneous transform from a rotation and a translation.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrix (not checked for orthonormality here).
    t : array_like, shape (..., 3)
        Translation, mm.

    Returns
    -------
    ndarray, shape (..., 4, 4)
    """
    R = _as_array(R, (3, 3), "R")
    t = _as_array(t, (3,), "t")
    batch = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros((*batch, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def invert_transform(a2b) -> np.ndarray:
    """Inverse of a rigid transform: ``b2a`` from ``a2b`` (exact, no matrix inverse).

    Parameters
    ----------
    a2b : array_like, shape (..., 4, 4)

    Returns
    -------
    b2a : ndarray, shape (..., 4, 4)
    """
    T = _as_array(a2b, (4, 4), "a2b")
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def concat(a2b, b2c) -> np.ndarray:
    """Chain two transforms: ``a2c = b2c @ a2b``.

    Parameters
    ----------
    a2b, b2c : array_like, shape (..., 4, 4)

    Returns
    -------
    a2c : ndarray, shape (..., 4, 4)

    Examples
    --------
    >>> import numpy as np
    >>> tool2flange = transform_from(np.eye(3), [0, 0, 100])
    >>> flange2base = transform_from(matrix_from_euler([0, 0, np.pi / 2]), [300, 0, 0])
    >>> transform_points(concat(tool2flange, flange2base), [0, 0, 0]).round(6)
    array([300.,   0., 100.])
    """
    return _as_array(b2c, (4, 4), "b2c") @ _as_array(a2b, (4, 4), "a2b")


def transform_points(a2b, points_a) -> np.ndarray:
    """Map points from frame ``a`` to frame ``b``.

    Parameters
    ----------
    a2b : array_like, shape (4, 4)
    points_a : array_like, shape (..., 3)
        Points in frame ``a``, mm.

    Returns
    -------
    ndarray, shape (..., 3)
        The same points in frame ``b``, mm.

    Examples
    --------
    A camera 500 mm above the base looking down (its z along the base's -z):

    >>> import numpy as np
    >>> cam2base = transform_from(matrix_from_euler([np.pi, 0, 0]), [0, 0, 500])
    >>> transform_points(cam2base, [10, 20, 400]).round(6)  # 400 mm in front of it
    array([ 10., -20., 100.])
    >>> transform_points(invert_transform(cam2base), [10, -20, 100]).round(6)
    array([ 10.,  20., 400.])
    """
    T = _as_array(a2b, (4, 4), "a2b")
    p = _as_array(points_a, (3,), "points_a")
    return p @ T[:3, :3].T + T[:3, 3]


def euler_from_matrix(R) -> np.ndarray:
    """The reference paper's Euler angles of a rotation matrix (its eqs. 3-5).

    With R = [U V W] (columns), psi = atan2(V_z, W_z) (about X),
    phi = asin(-U_z) (about Y), theta = atan2(U_y, U_x) (about Z), so that
    R = Rz(theta) Ry(phi) Rx(psi).

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3)
        (psi, phi, theta) in rad; phi in [-pi/2, pi/2]. At phi = +-pi/2 (gimbal
        lock) psi and theta are not separable; psi is then set to 0.
    """
    R = _as_array(R, (3, 3), "R")
    uz = np.clip(R[..., 2, 0], -1.0, 1.0)
    phi = np.arcsin(-uz)
    psi = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    theta = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    lock = np.abs(np.abs(uz) - 1.0) < 1e-12
    if np.any(lock):
        # cos(phi) = 0: R = Rz(theta) Ry(+-pi/2) Rx(psi) depends on theta -+ psi only.
        psi = np.where(lock, 0.0, psi)
        theta_lock = np.arctan2(-R[..., 0, 1], R[..., 1, 1])
        theta = np.where(lock, theta_lock, theta)
    return np.stack([psi, phi, theta], axis=-1)


def matrix_from_euler(angles) -> np.ndarray:
    """Rotation matrix R = Rz(theta) Ry(phi) Rx(psi) from (psi, phi, theta) in rad.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        (psi about X, phi about Y, theta about Z), rad.

    Returns
    -------
    ndarray, shape (..., 3, 3)

    Examples
    --------
    A quarter turn about Z maps x to y; :func:`euler_from_matrix` gives the angles back:

    >>> import numpy as np
    >>> R = matrix_from_euler([0.1, -0.2, np.pi / 2])
    >>> (R @ [1, 0, 0]).round(3)
    array([0.   , 0.98 , 0.199])
    >>> euler_from_matrix(R).round(6)
    array([ 0.1     , -0.2     ,  1.570796])
    """
    a = _as_array(angles, (3,), "angles")
    psi, phi, theta = a[..., 0], a[..., 1], a[..., 2]
    cx, sx = np.cos(psi), np.sin(psi)
    cy, sy = np.cos(phi), np.sin(phi)
    cz, sz = np.cos(theta), np.sin(theta)
    R = np.empty((*a.shape[:-1], 3, 3))
    R[..., 0, 0] = cz * cy
    R[..., 0, 1] = cz * sy * sx - sz * cx
    R[..., 0, 2] = cz * sy * cx + sz * sx
    R[..., 1, 0] = sz * cy
    R[..., 1, 1] = sz * sy * sx + cz * cx
    R[..., 1, 2] = sz * sy * cx - cz * sx
    R[..., 2, 0] = -sy
    R[..., 2, 1] = cy * sx
    R[..., 2, 2] = cy * cx
    return R


def rotvec_from_matrix(R) -> np.ndarray:
    """Rotation vector (axis times angle, rad) of a rotation matrix: the logarithm Log(R).

    SciPy's method (``Rotation.from_matrix(R).as_rotvec()``: the unit quaternion from the
    largest of the diagonal and the trace, then 2 atan2(|v|, w) v / |v|); one matrix on
    floats, 10x faster than SciPy's set-up (the pose fits take one per step), several with SciPy.
    R must be a rotation to rounding (the two paths then agree to the bit; a matrix far from
    orthonormal is read differently by each).

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3)
        Angle in [0, pi].

    Raises
    ------
    ValueError
        A matrix whose determinant is not positive (a reflection, a null frame).
    """
    R = _as_array(R, (3, 3), "R")
    if R.ndim == 2:
        return _rotvec_one(R)
    from scipy.spatial.transform import Rotation  # imported here: 0.2 s that most commands never need

    flat = R.reshape(-1, 3, 3)
    rv = Rotation.from_matrix(flat).as_rotvec()
    return rv.reshape(*R.shape[:-2], 3)


def _rotvec_one(R: np.ndarray) -> np.ndarray:
    """:func:`rotvec_from_matrix` of one (3, 3) matrix, with SciPy's arithmetic on floats."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = R.tolist()
    det = m00 * (m11 * m22 - m12 * m21) - m01 * (m10 * m22 - m12 * m20) + m02 * (m10 * m21 - m11 * m20)
    if not det > 0:  # as SciPy's
        raise ValueError(f"R is not a rotation: its determinant is {det:.3g} (a reflection or a null frame)")
    tr = m00 + m11 + m22
    choice, best = 0, m00
    for k, v in ((1, m11), (2, m22), (3, tr)):
        if v > best:
            choice, best = k, v
    if choice == 0:
        q = (1.0 - tr + 2.0 * m00, m10 + m01, m20 + m02, m21 - m12)
    elif choice == 1:
        q = (m01 + m10, 1.0 - tr + 2.0 * m11, m21 + m12, m02 - m20)
    elif choice == 2:
        q = (m02 + m20, m12 + m21, 1.0 - tr + 2.0 * m22, m10 - m01)
    else:
        q = (m21 - m12, m02 - m20, m10 - m01, 1.0 + tr)
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    x, y, z, w = (c / n for c in q)
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    angle = 2.0 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    if angle <= 1e-3:
        a2 = angle * angle
        scale = 2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0
    else:
        scale = angle / math.sin(angle / 2.0)
    return np.array([scale * x, scale * y, scale * z])


def _rodrigues(x, y, z, c, s) -> tuple:
    """The nine entries (row by row) of cos(a) I + (1 - cos(a)) k k^T + sin(a) [k]x.

    ``x, y, z`` the unit axis k, ``c, s`` the cosine and sine of the angle: floats or arrays.
    """
    c1 = 1.0 - c
    return (
        c + c1 * (x * x),
        c1 * (x * y) - s * z,
        c1 * (x * z) + s * y,
        c1 * (x * y) + s * z,
        c + c1 * (y * y),
        c1 * (y * z) - s * x,
        c1 * (x * z) - s * y,
        c1 * (y * z) + s * x,
        c + c1 * (z * z),
    )


def matrix_from_rotvec(rotvec) -> np.ndarray:
    """Rotation matrix from a rotation vector (rad): the exponential map Exp(r).

    Rodrigues' formula R = cos(a) I + (1 - cos(a)) k k^T + sin(a) [k]x with a = |r|
    and k = r / a (the identity for a below the machine epsilon), with the operations of
    OpenCV's ``cv2.Rodrigues`` in the same order (the two agree to the last bit when
    their sine and cosine do). The one home of the exponential: pose updates
    R <- Exp(dr) R (:func:`stiffmap.posemath.perturb_pose`), OpenCV's rotation vectors,
    the test-bed's small rotations.

    Parameters
    ----------
    rotvec : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    r = _as_array(rotvec, (3,), "rotvec")
    eps = np.finfo(np.float64).eps
    if r.ndim == 1:
        # One rotation (each step of a pose fit): the same arithmetic on floats, 8x faster.
        x, y, z = (float(v) for v in r)
        angle = math.sqrt(x * x + y * y + z * z)
        if angle < eps:
            return np.eye(3)
        inv = 1.0 / angle
        entries = _rodrigues(x * inv, y * inv, z * inv, math.cos(angle), math.sin(angle))
        return np.array(entries).reshape(3, 3)
    flat = r.reshape(-1, 3)
    x, y, z = flat[:, 0], flat[:, 1], flat[:, 2]
    angle = np.sqrt(x * x + y * y + z * z)
    tiny = angle < eps
    a = np.where(tiny, 1.0, angle)
    inv = 1.0 / a
    R = np.stack(_rodrigues(x * inv, y * inv, z * inv, np.cos(a), np.sin(a)), axis=-1).reshape(-1, 3, 3)
    R[tiny] = np.eye(3)
    return R.reshape(*r.shape[:-1], 3, 3)


def cam2base_from_fixed(fixed2base, fixed2cam) -> np.ndarray:
    """The camera expressed in the robot base frame, through the fixed target.

    Implements the reference paper's eq. 1: cam2base = fixed2base . inv(fixed2cam),
    where ``fixed2base`` is the known pose of the target on the robot base and
    ``fixed2cam`` is that target's pose measured by the camera.

    Parameters
    ----------
    fixed2base : array_like, shape (4, 4)
        Pose of the fixed target in the robot base frame, mm.
    fixed2cam : array_like, shape (..., 4, 4)
        Pose of the fixed target in the camera frame, mm.

    Returns
    -------
    cam2base : ndarray, shape (..., 4, 4)
    """
    return concat(invert_transform(fixed2cam), _as_array(fixed2base, (4, 4), "fixed2base"))


def displacement_from_poses(unloaded2ref, loaded2ref, point=None) -> np.ndarray:
    """Compliant displacement between an unloaded and a loaded pose.

    Parameters
    ----------
    unloaded2ref, loaded2ref : array_like, shape (..., 4, 4)
        The moving target's pose without and with load, in a common reference
        frame (the robot base frame in a campaign), mm.
    point : array_like, shape (3,), optional
        A point of the moving body in the target's frame (mm), e.g. the tool
        point. The translation is that of this point; default the target's origin.

    Returns
    -------
    ndarray, shape (..., 6)
        (dx, dy, dz) in mm: loaded minus unloaded position of the point, and
        (rx, ry, rz) in rad: rotation vector of R_loaded R_unloaded^T, both in
        the reference frame.
    """
    T0 = _as_array(unloaded2ref, (4, 4), "unloaded2ref")
    T1 = _as_array(loaded2ref, (4, 4), "loaded2ref")
    p = np.zeros(3) if point is None else _as_array(point, (3,), "point")
    x0 = (T0[..., :3, :3] @ p) + T0[..., :3, 3]
    x1 = (T1[..., :3, :3] @ p) + T1[..., :3, 3]
    dR = T1[..., :3, :3] @ np.swapaxes(T0[..., :3, :3], -1, -2)
    return np.concatenate([x1 - x0, rotvec_from_matrix(dR)], axis=-1)


def displacement_at_point(delta, offset) -> np.ndarray:
    """Move a small displacement to another point of the same rigid body.

    Parameters
    ----------
    delta : array_like, shape (..., 6)
        (dx, dy, dz, rx, ry, rz) of the body at point A, mm and rad.
    offset : array_like, shape (3,)
        B - A in the same frame, mm.

    Returns
    -------
    ndarray, shape (..., 6)
        The displacement at B to first order: d_B = d_A + r x (B - A), same r.
    """
    d = _as_array(delta, (6,), "delta")
    o = _as_array(offset, (3,), "offset")
    out = d.copy()
    out[..., :3] = d[..., :3] + np.cross(d[..., 3:], o)
    return out


def stiffness_in_frame(K, a2b) -> np.ndarray:
    """Express a stiffness matrix given in frame ``a`` in frame ``b``.

    Parameters
    ----------
    K : array_like, shape (3, 3) or (6, 6)
        Stiffness in frame ``a`` (N/mm; for 6x6 the blocks are N/mm, N, N*mm/rad).
        A 6x6 stiffness refers to the origin of frame ``a``.
    a2b : array_like, shape (4, 4)

    Returns
    -------
    ndarray
        For 3x3, R K R^T (a translational stiffness does not depend on the point).
        For 6x6, the stiffness at the origin of ``a`` (same physical point),
        rotated into ``b``'s axes: blockdiag(R, R) K blockdiag(R, R)^T.

    Examples
    --------
    A tool frame turned a quarter turn about z: its stiff x axis is the base's y axis.

    >>> import numpy as np
    >>> K_tool = np.diag([300.0, 50.0, 80.0])  # N/mm
    >>> tool2base = transform_from(matrix_from_euler([0, 0, np.pi / 2]), [0, 0, 0])
    >>> np.diag(stiffness_in_frame(K_tool, tool2base)).round(6)
    array([ 50., 300.,  80.])
    """
    T = as_transform(a2b, "a2b")
    K = np.asarray(K, dtype=np.float64)
    R = T[:3, :3]
    if K.shape == (3, 3):
        return R @ K @ R.T
    if K.shape == (6, 6):
        B = np.zeros((6, 6))
        B[:3, :3] = R
        B[3:, 3:] = R
        return B @ K @ B.T
    raise ValueError(f"K must be 3x3 or 6x6, got shape {K.shape}")


def mean_transform(transforms) -> np.ndarray:
    """Mean of rigid transforms: mean translation, rotation projected from the mean matrix.

    The chordal mean: the rotation closest (Frobenius) to the average of the
    rotation matrices. For the small scatter of repeated measurements of one pose
    it equals the mean of the rotation vectors to second order.

    Parameters
    ----------
    transforms : array_like, shape (n, 4, 4)
        Poses ``a2b`` of the same frames, mm.

    Returns
    -------
    ndarray, shape (4, 4)
    """
    T = np.asarray(transforms, dtype=np.float64)
    if T.ndim != 3 or T.shape[1:] != (4, 4) or len(T) == 0:
        raise ValueError(f"transforms must have shape (n, 4, 4) with n >= 1, got {T.shape}")
    U, _, Vt = np.linalg.svd(T[:, :3, :3].mean(axis=0))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return transform_from(R, T[:, :3, 3].mean(axis=0))
