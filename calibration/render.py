"""A calibration board as a calibrated camera sees it: exact geometry through the camera's lens model.

For trying ``ghcal`` without cameras and for its tests (a known rig in, the solved rig compared
with it), like ``sim://`` for the runtime. Each pixel's ray (``Camera.rays``, through the lens
model) is intersected with the board's plane and the board's texture sampled there, so corners land
where the rig says, distortion included.

Does not model: defocus beyond a small blur, motion blur, rolling shutter, glare, a board that is
not flat, or the printer's scale error (the thing ``square_m`` must be measured for).
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from calibration.board import BoardSpec
from calibration.errors import CalibrationError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig

__all__ = ["render_board", "board_pose_facing", "calibration_views", "example_rig", "synth_rig", "SYNTH_BOARD"]

#: Grey level around the board (the room) and of the quiet white margin printed around it.
BACKGROUND = 90
TEXTURE_PX_PER_SQUARE = 80


def render_board(camera: Camera, board: BoardSpec, R_board: np.ndarray, t_board: np.ndarray, *,
                 noise: float = 1.5, blur_sigma: float = 0.6, seed: int = 0) -> np.ndarray:
    """The ``(height, width)`` uint8 image ``camera`` takes of ``board`` at the pose (board -> rig frame).

    ``X_rig = R_board @ X_board + t_board``; the board frame has x along its width, y along its
    height, z = 0 on its face (``BoardSpec.corners_m``). The print carries a white margin of one
    square around the squares.
    """
    pps = TEXTURE_PX_PER_SQUARE
    texture = board.image(px_per_square=pps, margin_px=pps).astype(np.float32)
    # Sampled at a pixel per texel or fewer texels (a mip level), so a board seen small or edge-on is
    # prefiltered instead of aliased; aliasing would shift the detected corners by tenths of a pixel.
    # Per board axis (a board on the floor is foreshortened along one of them only).
    step_x, step_y = _smallest_square_px(camera, board, R_board, t_board, per_axis=True)
    h, w = texture.shape
    size = (w if step_x >= pps / 1.5 else max(int(round(w * max(step_x, 4.0) / pps)), 1),
            h if step_y >= pps / 1.5 else max(int(round(h * max(step_y, 4.0) / pps)), 1))
    if size != (w, h):
        texture = cv2.resize(texture, size, interpolation=cv2.INTER_AREA)
    sx, sy = size[0] / w, size[1] / h  # texels of this level per full-size texel, exact after rounding
    origins, dirs = camera.rays(camera.pixel_grid())
    normal = np.asarray(R_board, float)[:, 2]
    denom = dirs @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        s = ((np.asarray(t_board, float) - origins) @ normal) / denom
    hit = origins + s[..., None] * dirs
    local = (hit - np.asarray(t_board, float)) @ np.asarray(R_board, float)  # rig -> board frame
    ok = np.isfinite(s) & (s > 0) & (np.abs(denom) > 1e-9)
    # board metres -> texture pixels (pixel centres at integers), the margin one square wide
    # board metres -> full-size texel coordinates (the margin one square wide) -> this level's pixel centres
    map_x = np.where(ok, (local[..., 0] / board.square_m * pps + pps) * sx - 0.5, -1e6).astype(np.float32)
    map_y = np.where(ok, (local[..., 1] / board.square_m * pps + pps) * sy - 0.5, -1e6).astype(np.float32)
    image = cv2.remap(texture, map_x, map_y, cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=BACKGROUND)
    if blur_sigma > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur_sigma)
    if noise > 0:
        image = image + np.random.default_rng(seed).normal(0.0, noise, image.shape).astype(np.float32)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _smallest_square_px(camera: Camera, board: BoardSpec, R_board: np.ndarray, t_board: np.ndarray, *,
                        per_axis: bool = False):
    """The shortest side, in image pixels, of any square of the board as ``camera`` sees it (0 if not
    in front); ``per_axis``: the shortest along the board's x and along its y."""
    uv, _ = camera.project(board.corners_m() @ np.asarray(R_board, float).T + np.asarray(t_board, float))
    grid = uv.reshape(board.squares_y - 1, board.squares_x - 1, 2)
    along_x = np.linalg.norm(np.diff(grid, axis=1), axis=-1).ravel()
    along_y = np.linalg.norm(np.diff(grid, axis=0), axis=-1).ravel()
    sides = [float(np.min(a)) if a.size and np.all(np.isfinite(a)) else 0.0 for a in (along_x, along_y)]
    return tuple(sides) if per_axis else min(sides)


def board_pose_facing(board: BoardSpec, centre: np.ndarray, toward: np.ndarray, *, yaw_deg: float = 0.0,
                      pitch_deg: float = 0.0, spin_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A board pose (board -> rig) with its centre at ``centre``, its face turned toward ``toward``.

    The face is then turned by ``yaw_deg`` about the rig's vertical, tilted by ``pitch_deg`` and
    spun by ``spin_deg`` within its plane: the varied poses a calibration needs.
    """
    centre = np.asarray(centre, float)
    back = centre - np.asarray(toward, float)  # the board's z points away from the viewer
    z = back / np.linalg.norm(back)
    x = np.cross(np.array([0.0, 1.0, 0.0]), z)  # y down in the rig frame: x to the viewer's right
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z], axis=1)

    def rot(axis: np.ndarray, deg: float) -> np.ndarray:
        return cv2.Rodrigues(np.asarray(axis, float) * np.radians(deg))[0]

    R = rot(np.array([0.0, 1.0, 0.0]), yaw_deg) @ rot(R[:, 0], pitch_deg) @ R @ rot(np.array([0.0, 0.0, 1.0]),
                                                                                  spin_deg)
    w, h = board.size_m
    t = centre - R @ np.array([w / 2, h / 2, 0.0])
    return R, t


def board_poses_both_see(rig: Rig, board: BoardSpec, count: int, seed: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``count`` board poses (board -> rig) that both of the rig's pair see whole, 1-2.2 m in front of
    the pair and turned up to 35 degrees: views for pair solves in tests and benchmarks. Named
    ``"000"``...; the same ``seed`` gives the same poses."""
    rng = np.random.default_rng(seed)
    mid = 0.5 * (rig.pair[0].center + rig.pair[1].center)
    forward = rig.pair[0].R[2] + rig.pair[1].R[2]
    forward /= np.linalg.norm(forward)
    corners_board = board.corners_m()
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    while len(poses) < count:
        depth = rng.uniform(1.0, 2.2)
        centre = mid + depth * forward + np.array([rng.uniform(-0.4, 0.4) * depth, rng.uniform(-0.25, 0.25) * depth, 0])
        R, t = board_pose_facing(board, centre, mid, yaw_deg=rng.uniform(-35, 35), pitch_deg=rng.uniform(-35, 35),
                                 spin_deg=rng.uniform(-25, 25))
        corners = corners_board @ R.T + t
        inside = True
        for cam in rig.pair:
            uv, _ = cam.project(corners)
            inside &= bool(np.all(np.isfinite(uv)) and np.all((uv > 2) & (uv < [cam.width - 3, cam.height - 3])))
        if inside:
            poses[f"{len(poses):03d}"] = (R, t)
    return poses


def calibration_views(rig: Rig, board: BoardSpec, *, count: int = 20, edge_count: int = 6, seed: int = 0,
                      floor_view: bool = True, distance_m: tuple[float, float] = (1.0, 2.4)) \
        -> dict[str, dict[str, np.ndarray]]:
    """What a careful user captures: ``count`` board poses both of the rig's pair see, varied in
    distance, tilt and position; ``edge_count`` more per camera with the board in that camera's
    image corners (where the lens model is decided; the other camera may see part of it or none);
    and (``floor_view``) one of the board lying on the floor in front of the rig, named ``"floor"``.
    Returns camera name -> view name (``"000"``...) -> image; every view is in both cameras.

    Poses are drawn from ``seed`` and kept only when every corner is inside the image(s) they are for.
    """
    rng = np.random.default_rng(seed)
    cams = rig.pair
    mid = 0.5 * (cams[0].center + cams[1].center)
    forward = cams[0].R[2] + cams[1].R[2]
    forward = forward / np.linalg.norm(forward)
    right = np.cross(np.array([0.0, 1.0, 0.0]), forward)  # down x forward (rig frame: y down)
    right = right / np.linalg.norm(right)
    up = np.cross(right, forward)
    corners = board.corners_m()
    out: dict[str, dict[str, np.ndarray]] = {c.name: {} for c in cams}

    def visible(R: np.ndarray, t: np.ndarray, seen_by: tuple = cams) -> bool:
        for cam in seen_by:
            uv, z = cam.project(corners @ R.T + t)
            margin = 4.0
            if not (np.all(z > 0) and np.all(np.isfinite(uv)) and np.all(uv[:, 0] > margin)
                    and np.all(uv[:, 1] > margin) and np.all(uv[:, 0] < cam.width - 1 - margin)
                    and np.all(uv[:, 1] < cam.height - 1 - margin)):
                return False
        return True

    tries = 0
    while len(out[cams[0].name]) < count:
        tries += 1
        if tries > 200 * count:
            raise CalibrationError(f"could not place {count} board views both cameras see; is the rig's pair facing "
                             "the same way?")
        d = rng.uniform(*distance_m)
        lateral = rng.uniform(-0.35, 0.35) * d
        vertical = rng.uniform(-0.25, 0.25) * d
        centre = mid + d * forward + lateral * right + vertical * up
        R, t = board_pose_facing(board, centre, mid, yaw_deg=rng.uniform(-35, 35), pitch_deg=rng.uniform(-35, 35),
                                 spin_deg=rng.uniform(-25, 25))
        if not visible(R, t):
            continue
        name = f"{len(out[cams[0].name]):03d}"
        for k, cam in enumerate(cams):
            out[cam.name][name] = render_board(cam, board, R, t, seed=int(rng.integers(1 << 30)) + k)
    for cam in cams:  # views into this camera's image corners
        placed = 0
        for _ in range(400 * max(edge_count, 1)):
            if placed >= edge_count:
                break
            u = rng.uniform(0.12, 0.3) * cam.width
            v = rng.uniform(0.12, 0.3) * cam.height
            u = u if rng.random() < 0.5 else cam.width - 1 - u
            v = v if rng.random() < 0.5 else cam.height - 1 - v
            origin, ray = cam.rays(np.array([u, v]))
            centre = origin + rng.uniform(*distance_m) * ray
            R, t = board_pose_facing(board, centre, origin, yaw_deg=rng.uniform(-30, 30),
                                     pitch_deg=rng.uniform(-30, 30), spin_deg=rng.uniform(-20, 20))
            if not visible(R, t, (cam,)):
                continue
            name = f"{len(out[cams[0].name]):03d}"
            for k, other in enumerate(cams):
                out[other.name][name] = render_board(other, board, R, t, seed=int(rng.integers(1 << 30)) + k)
            placed += 1
    if floor_view:
        # Of the floor poses both cameras see, the one whose squares both see largest (a flat board is
        # foreshortened; its markers must stay readable).
        best, best_area = None, 0.0
        ahead = np.array([forward[0], 0.0, forward[2]]) / max(float(np.linalg.norm([forward[0], forward[2]])), 1e-9)
        for _ in range(60):
            centre = np.array([mid[0], 0.0, mid[2]]) + rng.uniform(0.5, 4.0) * ahead \
                + rng.uniform(-0.3, 0.3) * np.cross(np.array([0.0, 1.0, 0.0]), ahead)
            spin = math.radians(rng.uniform(-20, 20))
            x = math.cos(spin) * np.cross(np.array([0.0, 1.0, 0.0]), ahead) + math.sin(spin) * ahead
            z = np.array([0.0, 1.0, 0.0])  # face up: the board's z (into the board) along gravity
            R = np.stack([x, np.cross(z, x), z], axis=1)
            t = centre - R @ np.array([board.size_m[0] / 2, board.size_m[1] / 2, 0.0])
            if not visible(R, t):
                continue
            # the smallest projected square side decides whether the markers can be read
            area = min(_smallest_square_px(cam, board, R, t) for cam in cams)
            if area > best_area:
                best, best_area = (R, t), area
        if best is None:
            raise CalibrationError("no floor view both cameras see: are the cameras looking over the floor?")
        for k, cam in enumerate(cams):
            out[cam.name]["floor"] = render_board(cam, board, *best, seed=int(rng.integers(1 << 30)) + k)
    return out


def example_rig() -> Rig:
    """The known rig the calibration tests and benchmarks film (``ghcal synth``'s default until session 68, now
    :func:`synth_rig`): two 960x600 cameras (75 degrees, a mild barrel lens, principal points off centre) 0.6 m apart
    at 1.4 m, converging on a point 2.5 m ahead and 0.3 m up (pitched 24 degrees down: the floor in view from about
    1.2 m, a standing person's head cut nearer than 8 m)."""
    return _pair_of_960x600(1.4, -0.3, None, "ghcal-example")


#: ``ghcal synth``'s rig (:func:`synth_rig`, session 68): its cameras' height above the floor (metres) and pitch
#: (degrees below the horizon). At head height a standing person spans the least angle of the view, and pitched 23
#: degrees the 1.8 m person is whole in both images from 1.55 m ahead to past 5 m, where :func:`example_rig` (1.4 m
#: up, 24 degrees down) cut the head of anyone nearer than 8 m and lost 38 % of its pairs on 12 of the bench's
#: people, and the same cameras at 1.4 m lost 34-42 % pitched to frame the person (13 and 17 degrees):
#: ``benchmarks/measure_synth_framing.py``, docs/rig-file.md "`ghcal synth`'s rig since session 68".
SYNTH_CAMERA_HEIGHT_M = 1.8
SYNTH_PITCH_DEG = 23.0
#: How far ahead (metres) :func:`synth_rig`'s working volume starts: where its lens shows a standing person whole
#: with room to spare (``calibration.level.LEVEL_VOLUME``'s 0.5 m no aim of this lens frames: 1.88 m, pinhole).
#: Otherwise ``LEVEL_VOLUME``: 3 m wide, to 5 m ahead.
SYNTH_VOLUME_NEAR_M = 2.0
#: The board ``ghcal synth`` renders by default: 9x6 squares of 120 mm (markers of 90 mm). The floor comes into
#: :func:`synth_rig`'s view 1.6 m ahead, 2.4 m from its cameras, where the 80-mm default board lying there was read
#: by both cameras in 1 of 6 seeds, this one in all 6 (``benchmarks/measure_synth_framing.py --floor-seeds``;
#: docs/calibration.md: a rig that sees the floor only farther away needs a larger board).
SYNTH_BOARD = BoardSpec(square_m=0.12, marker_m=0.09)
#: Where the pair's optical axes cross, metres ahead of the cameras (x 0).
CONVERGE_AHEAD_M = 2.5


def synth_rig() -> Rig:
    """The rig ``ghcal synth`` films by default (session 68): :func:`example_rig`'s cameras raised to 1.8 m and
    pitched 23 degrees down, converging 2.5 m ahead (the floor in view from about 1.6 m), its working volume
    ``calibration.level.LEVEL_VOLUME`` from 2 m ahead: a 1.8 m person standing anywhere along its middle is whole in
    both images, and loading neither warns nor notes of it."""
    drop = CONVERGE_AHEAD_M * math.tan(math.radians(SYNTH_PITCH_DEG))
    return _pair_of_960x600(SYNTH_CAMERA_HEIGHT_M, drop - SYNTH_CAMERA_HEIGHT_M, SYNTH_VOLUME_NEAR_M, "ghcal-synth")


def _pair_of_960x600(height_m: float, target_y: float, near_m: float | None, rig_id: str) -> Rig:
    """Two 960x600 cameras (75 degrees, a mild barrel lens, principal points off centre) 0.6 m apart, ``height_m``
    above the floor, aimed at the point ``CONVERGE_AHEAD_M`` ahead at ``y = target_y``; their working volume
    ``LEVEL_VOLUME``, from ``near_m`` ahead where given (None: its own near edge, read from it rather than copied)."""
    from ghnerf_runtime.geometry.camera import intrinsics_from_fov, look_at
    from ghnerf_runtime.geometry.rig import WorkingVolume
    from calibration.level import LEVEL_VOLUME

    width, height = 960, 600
    cams = []
    for name, x, shift in (("left", -0.3, (6.0, -4.0)), ("right", 0.3, (-5.0, 3.0))):
        K = intrinsics_from_fov(width, height, 75.0)
        K[0, 2] += shift[0]
        K[1, 2] += shift[1]
        R, t = look_at([x, -height_m, 0.0], [0.0, target_y, CONVERGE_AHEAD_M])
        cams.append(Camera(name, width, height, K, [-0.12, 0.03, 0.001, -0.0005, 0.0], R, t))
    if near_m is None:
        return Rig(tuple(cams), LEVEL_VOLUME, rig_id=rig_id)
    near = LEVEL_VOLUME.min_corner.copy()
    near[2] = near_m
    return Rig(tuple(cams), WorkingVolume(near, LEVEL_VOLUME.max_corner.copy()), rig_id=rig_id)
