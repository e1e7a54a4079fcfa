"""Small rotation helpers: axis rotations, Euler channels, quaternions, vector alignment.

Arrays in, arrays out; batch dimensions first; angles in radians unless a
name says ``deg``. Rotation matrices act on column vectors (``v' = R @ v``).
"""
from __future__ import annotations

import numpy as np


def rot_x(angle: np.ndarray | float) -> np.ndarray:
    """Rotation about +x by ``angle`` (right-hand rule), shape ``(..., 3, 3)``."""
    return _axis_rotation(np.asarray(angle, dtype=np.float64), 0)


def rot_y(angle: np.ndarray | float) -> np.ndarray:
    """Rotation about +y by ``angle``, shape ``(..., 3, 3)``."""
    return _axis_rotation(np.asarray(angle, dtype=np.float64), 1)


def rot_z(angle: np.ndarray | float) -> np.ndarray:
    """Rotation about +z by ``angle``, shape ``(..., 3, 3)``."""
    return _axis_rotation(np.asarray(angle, dtype=np.float64), 2)


def _axis_rotation(angle: np.ndarray, axis: int) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(angle.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


AXIS_ROTATIONS = {"x": rot_x, "y": rot_y, "z": rot_z}


def euler_to_matrix(angles_deg: np.ndarray, order: str) -> np.ndarray:
    """Compose axis rotations in the order given, BVH style: ``R = R_order[0] @ R_order[1] @ ...``.

    Args:
        angles_deg: ``(..., len(order))`` angles in degrees, one column per letter of ``order``.
        order: axis letters, e.g. ``"zxy"`` (lower case).
    """
    angles = np.radians(np.asarray(angles_deg, dtype=np.float64))
    out = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for k, axis in enumerate(order):
        out = out @ AXIS_ROTATIONS[axis](angles[..., k])
    return out


def matrix_to_euler(R: np.ndarray, order: str) -> np.ndarray:
    """Inverse of :func:`euler_to_matrix` for a 3-letter order of distinct axes; degrees ``(..., 3)``.

    Solved numerically-safely (clipped arcsin); at gimbal lock the first angle takes all of the
    shared rotation, which still reproduces ``R`` exactly.
    """
    R = np.asarray(R, dtype=np.float64)
    idx = ["xyz".index(a) for a in order]
    i, j, k = idx
    # Sign of the permutation decides the signs of the closed form (Shoemake's Euler angles).
    parity = 1.0 if (j - i) % 3 == 1 else -1.0
    sy = np.clip(parity * R[..., i, k], -1.0, 1.0)
    b = np.arcsin(sy)
    cb = np.cos(b)
    regular = cb > 1e-9
    a = np.where(regular, np.arctan2(-parity * R[..., j, k], R[..., k, k]), np.arctan2(parity * R[..., k, j], R[..., j, j]))
    c = np.where(regular, np.arctan2(-parity * R[..., i, j], R[..., i, i]), 0.0)
    return np.degrees(np.stack([a, b, c], axis=-1))


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` to unit quaternions ``(..., 4)`` as ``(w, x, y, z)``, w >= 0."""
    R = np.asarray(R, dtype=np.float64)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    # Each candidate is accurate where its squared component is large; pick the largest.
    cand = np.stack(
        [
            np.stack([1 + m00 + m11 + m22, R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1),
            np.stack([R[..., 2, 1] - R[..., 1, 2], 1 + m00 - m11 - m22, R[..., 0, 1] + R[..., 1, 0], R[..., 0, 2] + R[..., 2, 0]], -1),
            np.stack([R[..., 0, 2] - R[..., 2, 0], R[..., 0, 1] + R[..., 1, 0], 1 - m00 + m11 - m22, R[..., 1, 2] + R[..., 2, 1]], -1),
            np.stack([R[..., 1, 0] - R[..., 0, 1], R[..., 0, 2] + R[..., 2, 0], R[..., 1, 2] + R[..., 2, 1], 1 - m00 - m11 + m22], -1),
        ],
        axis=-2,
    )
    best = np.argmax(np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1), axis=-1)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` (w, x, y, z; normalised here) to rotation matrices ``(..., 3, 3)``."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def quat_nlerp(q0: np.ndarray, q1: np.ndarray, alpha: float) -> np.ndarray:
    """Normalised linear interpolation along the shorter arc (good for densely sampled motion)."""
    sign = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    q = (1.0 - alpha) * q0 + alpha * sign * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def align_vectors(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction ``src`` onto direction ``dst`` (both ``(..., 3)``).

    Zero-length inputs give the identity; opposite directions turn 180 degrees about an axis
    perpendicular to ``src``.
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    shape = np.broadcast_shapes(src.shape, dst.shape)
    a = np.broadcast_to(src, shape)
    b = np.broadcast_to(dst, shape)
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    degenerate = (na[..., 0] < 1e-12) | (nb[..., 0] < 1e-12)
    a = a / np.where(na < 1e-12, 1.0, na)
    b = b / np.where(nb < 1e-12, 1.0, nb)
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    # Rodrigues in the form I + [v]x + [v]x^2 / (1 + c), stable except for c -> -1.
    vx = np.zeros(shape[:-1] + (3, 3))
    vx[..., 0, 1], vx[..., 0, 2] = -v[..., 2], v[..., 1]
    vx[..., 1, 0], vx[..., 1, 2] = v[..., 2], -v[..., 0]
    vx[..., 2, 0], vx[..., 2, 1] = -v[..., 1], v[..., 0]
    opposite = c < -1.0 + 1e-9
    scale = 1.0 / np.where(opposite, 1.0, 1.0 + c)
    R = np.eye(3) + vx + (vx @ vx) * scale[..., None, None]
    if np.any(opposite):
        # Half turn about any axis perpendicular to a.
        helper = np.where(np.abs(a[..., :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
        axis = np.cross(a, helper)
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        half = 2.0 * axis[..., :, None] * axis[..., None, :] - np.eye(3)
        R = np.where(opposite[..., None, None], half, R)
    return np.where(degenerate[..., None, None], np.eye(3), R)
