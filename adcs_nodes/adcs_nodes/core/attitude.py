"""Attitude math: quaternions, rotation matrices, skew matrices, frame conventions.

Conventions (DESIGN section 4)
------------------------------
* Hamilton quaternions stored ``[x, y, z, w]`` (scalar last), as ``geometry_msgs`` and scipy.
* ``q_A_B`` rotates frame-B components into frame A: ``v_A = R(q_A_B) @ v_B``.
* Composition: ``q_A_C = q_A_B (x) q_B_C``; inverse ``q_B_A = conj(q_A_B)``.
* Kinematics of ``q_A_B`` with ``omega_B_A_B`` (rate of B w.r.t. A in B axes)::

      dq_A_B/dt = 1/2 q_A_B (x) [omega_B_A_B, 0]                                    (K1)

* Paper 000 (Lebedev et al.) writes ``Lambda = lambda0 + lambda`` scalar first with
  ``r_J = Lambda . r_E . conj(Lambda)`` (body E to orbit J), i.e. its ``Lambda`` is our
  ``q_orbit_body`` with the scalar moved to the front. The only conversion is
  :func:`from_scalar_first` / :func:`to_scalar_first`; it is pinned by a unit test against the
  paper's equation (10).

All functions take and return numpy arrays; they raise ``ValueError`` on non-finite input or a
zero-norm quaternion instead of returning NaN.
"""
from __future__ import annotations

import math

import numpy as np

_EPS_NORM = 1e-12


def _as_quat(q) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (4,):
        raise ValueError(f'quaternion must have shape (4,), got {q.shape}')
    if not math.isfinite(sum(q.tolist())) and not np.isfinite(q).all():   # finite sum: fast
        raise ValueError(f'quaternion is not finite: {q}')
    return q


def as_vec3(v, name: str = 'vector') -> np.ndarray:
    """``v`` as a finite float array of shape (3,); ``ValueError`` naming ``name`` if not."""
    v = np.asarray(v, dtype=float)
    if v.shape != (3,):
        raise ValueError(f'{name} must have shape (3,), got {v.shape}')
    if not math.isfinite(sum(v.tolist())) and not np.isfinite(v).all():
        raise ValueError(f'{name} is not finite: {v}')
    return v


def normalize(q) -> np.ndarray:
    """The unit quaternion ``q / |q|`` (4,), scalar last; ``ValueError`` if ``q`` is not
    finite or has (near) zero norm."""
    q = _as_quat(q)
    n = math.sqrt(q.dot(q))             # what np.linalg.norm computes for a real vector
    if n == math.inf:                   # |q| overflows (a finite q of ~1e300): scaled first
        q = q / np.max(np.abs(q))
        n = math.sqrt(q.dot(q))
    if n < _EPS_NORM:
        raise ValueError('quaternion has zero norm')
    return q / n


def canonical(q) -> np.ndarray:
    """Return the representative of ``{q, -q}`` with ``w >= 0`` (same rotation)."""
    q = normalize(q)
    return -q if q[3] < 0.0 else q


def identity() -> np.ndarray:
    """Identity quaternion ``[0, 0, 0, 1]``."""
    return np.array([0.0, 0.0, 0.0, 1.0])


def multiply(p, q) -> np.ndarray:
    """Hamilton product ``p (x) q`` of scalar-last quaternions.

    ``R(p (x) q) = R(p) @ R(q)``, so ``q_A_C = multiply(q_A_B, q_B_C)``.
    """
    px, py, pz, pw = _as_quat(p).tolist()     # Python floats: the same IEEE operations,
    qx, qy, qz, qw = _as_quat(q).tolist()     # without numpy scalar dispatch
    return np.array([
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
        pw * qw - px * qx - py * qy - pz * qz,
    ])


def conjugate(q) -> np.ndarray:
    """Conjugate ``[-x, -y, -z, w]``; the inverse rotation of a unit quaternion."""
    x, y, z, w = _as_quat(q).tolist()
    return np.array([-x, -y, -z, w])


def to_matrix(q) -> np.ndarray:
    """Rotation matrix ``R(q_A_B)`` (3, 3) with ``v_A = R @ v_B``. ``q`` is normalised first."""
    x, y, z, w = normalize(q).tolist()        # Python floats: the same IEEE operations
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def from_matrix(dcm) -> np.ndarray:
    """Quaternion (scalar last, ``w >= 0``) of a rotation matrix ``R_A_B`` (Shepperd's method);
    ``ValueError`` unless ``dcm`` is a finite proper rotation (orthonormal to 1e-6, det +1)."""
    m = np.asarray(dcm, dtype=float)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise ValueError('rotation matrix must be a finite (3, 3) array')
    if not np.allclose(m @ m.T, np.eye(3), atol=1e-6) or np.linalg.det(m) < 0:
        raise ValueError('matrix is not a proper rotation')
    tr = np.trace(m)
    cand = np.array([m[0, 0], m[1, 1], m[2, 2], tr])
    i = int(np.argmax(cand))
    if i == 3:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = np.array([(m[2, 1] - m[1, 2]), (m[0, 2] - m[2, 0]), (m[1, 0] - m[0, 1]), 0.0])
        q /= 4.0 * w
        q[3] = w
    else:
        j, k = (i + 1) % 3, (i + 2) % 3
        qi = 0.5 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = np.zeros(4)
        q[i] = qi
        q[j] = (m[j, i] + m[i, j]) / (4.0 * qi)
        q[k] = (m[k, i] + m[i, k]) / (4.0 * qi)
        q[3] = (m[k, j] - m[j, k]) / (4.0 * qi)
    return canonical(q)


def rotate(q_a_b, v_b) -> np.ndarray:
    """Components in frame A of the vector with components ``v_b`` in frame B."""
    return to_matrix(q_a_b) @ as_vec3(v_b)


def from_axis_angle(axis, angle: float) -> np.ndarray:
    """Quaternion of a right-handed rotation by ``angle`` [rad] about unit ``axis``."""
    axis = as_vec3(axis, 'axis')
    n = np.linalg.norm(axis)
    if n < _EPS_NORM:
        raise ValueError('rotation axis has zero norm')
    half = 0.5 * float(angle)
    return np.concatenate([np.sin(half) * axis / n, [np.cos(half)]])


def from_rotation_vector(phi) -> np.ndarray:
    """Quaternion of the rotation vector ``phi`` (axis * angle, rad); exact for any size."""
    phi = as_vec3(phi, 'rotation vector')
    angle = np.linalg.norm(phi)
    if angle < 1e-12:
        q = np.concatenate([0.5 * phi, [1.0]])
        return q / np.linalg.norm(q)
    return from_axis_angle(phi, angle)


def to_rotation_vector(q) -> np.ndarray:
    """Rotation vector (rad) of ``q``, angle in [0, pi] (shortest of ``q`` and ``-q``)."""
    q = canonical(q)
    s = np.linalg.norm(q[:3])
    if s < 1e-12:
        return 2.0 * q[:3]
    angle = 2.0 * np.arctan2(s, q[3])
    return angle * q[:3] / s


def angle_between(q1, q2) -> float:
    """Smallest rotation angle [rad] between two attitudes, in [0, pi]; ``q`` and ``-q`` equal."""
    d = abs(float(np.dot(normalize(q1), normalize(q2))))
    return 2.0 * np.arccos(min(1.0, d))


def skew(v) -> np.ndarray:
    """Cross-product matrix ``Phi(v)`` with ``Phi(v) @ p = v x p`` (paper 000 notation)."""
    x, y, z = as_vec3(v)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def derivative(q_a_b, omega_b_a_b) -> np.ndarray:
    """Time derivative of ``q_A_B`` for the rate ``omega_B_A_B`` [rad/s], equation (K1)."""
    w = as_vec3(omega_b_a_b, 'rate')
    return 0.5 * multiply(q_a_b, np.array([w[0], w[1], w[2], 0.0]))


def from_scalar_first(q_wxyz) -> np.ndarray:
    """Convert a scalar-first quaternion ``[w, x, y, z]`` (paper 000's Lambda) to ``[x, y, z, w]``.

    Paper 000's ``Lambda`` maps body to orbit (``r_J = Lambda r_E conj(Lambda)``), so the result
    is ``q_orbit_body``.
    """
    q = _as_quat(q_wxyz)
    return np.array([q[1], q[2], q[3], q[0]])


def to_scalar_first(q_xyzw) -> np.ndarray:
    """Convert ``[x, y, z, w]`` to the scalar-first ``[w, x, y, z]`` of paper 000."""
    q = _as_quat(q_xyzw)
    return np.array([q[3], q[0], q[1], q[2]])


def from_euler_321(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``q_ref_body`` of yaw-pitch-roll (3-2-1, z-y-x) Euler angles [rad].

    The body is reached from the reference frame by yaw about z, then pitch about the new y,
    then roll about the new x; ``R(q) = Rz(yaw) Ry(pitch) Rx(roll)``.
    """
    qz = from_axis_angle([0.0, 0.0, 1.0], yaw)
    qy = from_axis_angle([0.0, 1.0, 0.0], pitch)
    qx = from_axis_angle([1.0, 0.0, 0.0], roll)
    return multiply(multiply(qz, qy), qx)


def to_euler_321(q_ref_body) -> np.ndarray:
    """Roll, pitch, yaw [rad] (3-2-1) of ``q_ref_body``; inverse of :func:`from_euler_321`."""
    m = to_matrix(q_ref_body)
    pitch = -np.arcsin(np.clip(m[2, 0], -1.0, 1.0))
    roll = np.arctan2(m[2, 1], m[2, 2])
    yaw = np.arctan2(m[1, 0], m[0, 0])
    return np.array([roll, pitch, yaw])
