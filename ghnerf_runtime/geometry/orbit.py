"""An orbit between two cameras: the pivot their optical axes meet nearest, and a centre on an arc round it.

A virtual camera between two rig cameras that face each other across the subject (120-180 degrees apart)
must not move on the straight line between their centres: that line passes by or through the subject.
Round a pivot, the camera keeps its distance (lerped between the two cameras') and its view of the pivot
(:func:`orbit_centre`). The pivot is the point nearest both optical axes (:func:`axes_pivot`), where a
converging rig aims; with the subject known, the point nearest both axes and, along the direction the axes
fix badly (along them when they are near parallel or antiparallel), nearest the subject (:func:`subject_pivot`);
and where that point is not at the subject (side-by-side cameras toed in past 60 degrees cross their axes between
themselves and the subject), the subject's centre (:func:`orbit_pivot`).

Pure numpy; rig frame (metres), cameras as :class:`~ghnerf_runtime.geometry.camera.Camera`.
"""
from __future__ import annotations

import numpy as np

from ghnerf_runtime.errors import GeometryError
from ghnerf_runtime.geometry.camera import Camera

__all__ = ["AXES_PIVOT_HOLD_M", "AXES_PIVOT_DROP_M", "PARALLEL_AXES_DEG", "PIVOT_CONDITION_DEG", "axes_angle_deg",
           "axes_pivot", "subject_pivot", "orbit_pivot", "in_front", "orbit_centre"]

#: Optical axes within this angle of parallel (or of antiparallel: collinear cameras facing each other) have
#: no pivot. Nearer, the nearest point runs off along the axes (the solve divides by sin^2 of the angle,
#: 3e-6 here), and for converging axes it lies over 570 baselines away, where an orbit is the line to within
#: an eighth of the angle (radians) times the baseline (0.2 mm for a 1 m baseline).
PARALLEL_AXES_DEG = 0.1

#: :func:`subject_pivot`: optical axes this many degrees from parallel or antiparallel fix the pivot along them
#: as much as the subject does (half the way from the axes' nearest point to the subject along them); nearer,
#: the subject decides (94 % at 5 degrees), further, the axes (76 % at 13.3, 99 % at 30). Along them the axes'
#: nearest point moves by an axis's offset over the tangent of that angle (0.57 m for 1 cm at 1 degree), where
#: the subject's centre is known to centimetres.
PIVOT_CONDITION_DEG = 10.0

#: :func:`orbit_pivot`: the axes' point (:func:`subject_pivot`) within this of the subject's centre is the pivot as
#: it is. The rigs the docs measure put it at most 0.15 m off (docs/examples/rig.json 147 mm, cameras aimed at the
#: subject 75 mm: the volume's centre above the aim), and a person's pose moves their box's centre by a few tenths
#: (arms raised, a crouch), which must not move an orbit the calibration fixes.
AXES_PIVOT_HOLD_M = 0.5

#: :func:`orbit_pivot`: the axes' point this far or further from the subject's centre is not at the subject (a
#: standing adult's joints lie within about 0.9 m of their centre) and the subject's centre is the pivot; between
#: the two distances it moves from the one to the other (twice as fast as the subject), so a person walking off
#: the axes' crossing does not make the view jump. Side-by-side cameras toed in past 60 degrees cross their axes
#: 1.2 m or more in front of a subject 2.2 m or more away (the simulator's 1.2 m baseline; 2.4 m at 90 degrees
#: and 3 m).
AXES_PIVOT_DROP_M = 1.0


def _axis(camera: Camera) -> np.ndarray:
    """The optical axis (the camera's +z) in the rig frame, unit length."""
    return camera.R[2]


def axes_angle_deg(cam_a: Camera, cam_b: Camera) -> float:
    """The angle between the two cameras' optical axes (degrees, 0 to 180; a roll about an axis does not count).

    Example:
        >>> from ghnerf_runtime.geometry.camera import intrinsics_from_fov, look_at
        >>> K = intrinsics_from_fov(64, 64, 60.0)
        >>> a = Camera("a", 64, 64, K, [], *look_at((-3, 0, 0), (0, 0, 0)))
        >>> b = Camera("b", 64, 64, K, [], *look_at((0, 0, -3), (0, 0, 0)))
        >>> round(axes_angle_deg(a, b), 6)
        90.0
    """
    cos = float(np.clip(np.dot(_axis(cam_a), _axis(cam_b)), -1.0, 1.0))
    return float(np.degrees(np.arccos(cos)))


def axes_pivot(cam_a: Camera, cam_b: Camera) -> np.ndarray | None:
    """The point nearest both optical axes (least squares: the midpoint of their common perpendicular), or ``None``
    when the axes are within :data:`PARALLEL_AXES_DEG` of parallel or antiparallel (a whole line is nearest).

    The axes are whole lines: the point may lie behind a camera (diverging cameras); :func:`in_front` says.

    Example:
        >>> from ghnerf_runtime.geometry.camera import intrinsics_from_fov, look_at
        >>> K = intrinsics_from_fov(64, 64, 60.0)
        >>> a = Camera("a", 64, 64, K, [], *look_at((-1, -1.2, 0), (0, -1, 3)))
        >>> b = Camera("b", 64, 64, K, [], *look_at((1, -1.2, 0), (0, -1, 3)))
        >>> np.round(axes_pivot(a, b), 9).tolist()  # where both aim
        [0.0, -1.0, 3.0]
        >>> b = Camera("b", 64, 64, K, [], *look_at((1, -1.2, 0), (0, -0.8, 3)))  # aimed 20 cm higher: skew axes
        >>> np.round(axes_pivot(a, b), 3).tolist()  # halfway between them where they pass nearest
        [0.003, -0.903, 2.971]
    """
    da, db = _axis(cam_a), _axis(cam_b)
    ca, cb = cam_a.center, cam_b.center
    cos = float(np.dot(da, db))
    det = 1.0 - cos * cos  # sin^2 of the angle between the axes
    if det < np.sin(np.radians(PARALLEL_AXES_DEG)) ** 2:
        return None
    w = ca - cb
    d, e = float(np.dot(da, w)), float(np.dot(db, w))
    s = (cos * e - d) / det  # the nearest points ca + s da and cb + u db (the common perpendicular's feet)
    u = (e - cos * d) / det
    return 0.5 * (ca + s * da + cb + u * db)


def subject_pivot(cam_a: Camera, cam_b: Camera, subject: np.ndarray) -> np.ndarray:
    """The point nearest both optical axes where they fix it well, and nearest ``subject`` (rig frame) where not.

    The squared distances to the two axes sum to ``|A^(1/2) p - ...|^2`` with ``A = 2I - da da^T - db db^T``,
    whose eigenvalues are 2 (across both axes), ``1 + |cos|`` and ``1 - |cos|`` (along them, for axes near
    parallel or antiparallel): the least-squares point (:func:`axes_pivot`) divides by that last one, so there
    an axis aimed a centimetre off moves it by metres along them. Here ``A p = b`` is solved damped towards
    ``subject``: ``p = subject + (A^2 + k^2 I)^-1 A (b - A subject)``, ``k = 1 - cos(PIVOT_CONDITION_DEG)``.
    Each eigen-direction keeps ``e^2 / (e^2 + k^2)`` of the axes' answer and takes the rest from the subject:
    all but 0.02 % across the axes and for axes 90 degrees apart; half at :data:`PIVOT_CONDITION_DEG` from
    (anti)parallel; the subject's alone for exactly collinear or parallel axes. Never singular; the point may
    still lie behind a camera (:func:`in_front`).

    Example:
        >>> from ghnerf_runtime.geometry.camera import intrinsics_from_fov, look_at
        >>> K = intrinsics_from_fov(64, 64, 60.0)
        >>> a = Camera("a", 64, 64, K, [], *look_at((-3, -1, 3), (0, -1, 3)))  # facing each other across the subject
        >>> b = Camera("b", 64, 64, K, [], *look_at((3, -1, 3), (0, -1, 3.01)))  # aimed 1 cm off: 179.8 degrees
        >>> np.round(axes_pivot(a, b), 3).tolist()  # where the axes meet: at b
        [3.0, -1.0, 3.0]
        >>> np.round(subject_pivot(a, b, np.array([0.02, -1.0, 3.0])), 3).tolist()  # between them, at the subject
        [0.02, -1.0, 3.005]
    """
    subject = np.asarray(subject, dtype=np.float64)
    A, b = np.zeros((3, 3)), np.zeros(3)
    for camera in (cam_a, cam_b):
        across = np.eye(3) - np.outer(_axis(camera), _axis(camera))  # projects onto the plane across the axis
        A += across
        b += across @ camera.center
    k = 1.0 - np.cos(np.radians(PIVOT_CONDITION_DEG))
    return subject + np.linalg.solve(A @ A + k * k * np.eye(3), A @ (b - A @ subject))


def orbit_pivot(cam_a: Camera, cam_b: Camera, subject: np.ndarray) -> np.ndarray:
    """The pivot of an orbit between two cameras round ``subject`` (the subject's centre, rig frame): the axes'
    point (:func:`subject_pivot`) where it is at the subject, else the subject's centre.

    The orbit keeps the view as far from its pivot as the two cameras are and looks at it as they do; round a point
    away from the subject it swings the view about empty space (two cameras side by side toed in 90 degrees cross
    their axes 2.4 m in front of the subject, and the halfway view stood 6 % further from it than the cameras).
    Within :data:`AXES_PIVOT_HOLD_M` of ``subject`` the axes' point is kept (fixed by the calibration, not by the
    pose); from :data:`AXES_PIVOT_DROP_M` on, ``subject``; between, on the way from the one to the other, moved
    twice the subject's distance past :data:`AXES_PIVOT_HOLD_M` (continuous: a person walking off the crossing
    moves the pivot at most twice as fast, never by a jump). The point may lie behind a camera (:func:`in_front`).

    Example:
        >>> from ghnerf_runtime.geometry.camera import intrinsics_from_fov, look_at
        >>> K = intrinsics_from_fov(64, 64, 60.0)
        >>> a = Camera("a", 64, 64, K, [], *look_at((-0.6, -1, 0), (0, -1, 0.6)))  # toed in 90 degrees
        >>> b = Camera("b", 64, 64, K, [], *look_at((0.6, -1, 0), (0, -1, 0.6)))
        >>> np.round(subject_pivot(a, b, np.array([0.0, -1.0, 3.0])), 2).tolist()  # near where the axes cross
        [0.0, -1.0, 0.6]
        >>> np.round(orbit_pivot(a, b, np.array([0.0, -1.0, 3.0])), 2).tolist()  # that is 2.4 m from the subject
        [0.0, -1.0, 3.0]
        >>> np.round(orbit_pivot(a, b, np.array([0.0, -1.0, 1.4])), 2).tolist()  # 0.8 m: moved 2 x 0.3 m
        [0.0, -1.0, 1.2]
        >>> np.round(orbit_pivot(a, b, np.array([0.0, -1.0, 0.9])), 2).tolist()  # 0.3 m: the axes' point
        [0.0, -1.0, 0.6]
    """
    subject = np.asarray(subject, dtype=np.float64)
    point = subject_pivot(cam_a, cam_b, subject)
    off = float(np.linalg.norm(point - subject))
    if not off > AXES_PIVOT_HOLD_M:  # (also a subject on the point: no direction to move in)
        return point
    # the pivot leaves the point by DROP / (DROP - HOLD) (2) times the subject's distance past HOLD: the steadiest
    # way from standing still (at HOLD) to the subject itself (at DROP)
    moved = AXES_PIVOT_DROP_M * (off - AXES_PIVOT_HOLD_M) / (AXES_PIVOT_DROP_M - AXES_PIVOT_HOLD_M)
    return point + min(moved / off, 1.0) * (subject - point)


def in_front(camera: Camera, point: np.ndarray) -> bool:
    """Whether a finite rig-frame ``point`` lies in front of ``camera`` (positive depth along its axis)."""
    point = np.asarray(point, dtype=np.float64)
    return bool(np.all(np.isfinite(point)) and np.dot(_axis(camera), point - camera.center) > 0.0)


def _slerp_unit(a: np.ndarray, b: np.ndarray, alpha: float) -> np.ndarray:
    """Spherical interpolation of two unit vectors less than 180 degrees apart (``alpha`` may extrapolate)."""
    omega = float(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0)))
    if omega < 1e-9:  # the same direction: the formula would divide 0 by 0
        v = a + alpha * (b - a)
    else:
        v = (np.sin((1.0 - alpha) * omega) * a + np.sin(alpha * omega) * b) / np.sin(omega)
    return v / np.linalg.norm(v)


def orbit_centre(cam_a: Camera, cam_b: Camera, R: np.ndarray, alpha: float, pivot: np.ndarray) -> np.ndarray:
    """The centre of the camera with rotation ``R`` (rig -> camera; the two cameras' slerped) on the orbit round
    ``pivot``, ``alpha`` of the way from ``cam_a`` to ``cam_b``.

    Each camera sees the pivot at ``q = R (pivot - centre)`` in its own frame; the virtual camera sees it in the
    direction slerped between the two and at the distance lerped between them, so it is as far from the pivot as
    the lerp of the two cameras' distances and looks at it as they do (straight at it when both do). At
    ``alpha`` 0 and 1 this is ``cam_a``'s and ``cam_b``'s centre (when ``R`` is theirs).

    Raises:
        GeometryError: the pivot is not in front of both cameras (a caller's error: :func:`in_front` first), or
            the extrapolated distance to it is not positive (``alpha`` too far out for two cameras at very
            different distances).
    """
    pivot = np.asarray(pivot, dtype=np.float64)
    if not (in_front(cam_a, pivot) and in_front(cam_b, pivot)):
        raise GeometryError(f"orbit pivot {pivot.tolist()} is not in front of cameras {cam_a.name!r} and "
                            f"{cam_b.name!r}")
    qa, qb = cam_a.R @ (pivot - cam_a.center), cam_b.R @ (pivot - cam_b.center)
    ra, rb = float(np.linalg.norm(qa)), float(np.linalg.norm(qb))
    r = (1.0 - alpha) * ra + alpha * rb
    if not r > 0.0:
        raise GeometryError(f"novel-view alpha {alpha} (--novel-alpha, NovelViewRequest.alpha) extrapolates the "
                            f"distances of cameras {cam_a.name!r} and {cam_b.name!r} to their orbit's pivot "
                            f"({ra:.3f}, {rb:.3f} m) to {r:.3f} m; keep it nearer [0, 1]")
    return pivot - np.asarray(R, dtype=np.float64).T @ (r * _slerp_unit(qa / ra, qb / rb, alpha))
