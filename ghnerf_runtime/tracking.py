"""Following one subject from pair to pair: where to crop, which box to sweep.

The first pair (and every pair after the track is lost) uses the rig's working
volume: the crop is the volume projected into each camera (``roi_from_volume``), and
the plane sweep's near/far span the volume. Once a pair yields enough confident 3D
joints, the next pair crops around those joints plus a margin (``roi_from_joints``) and
sweeps only the subject box (the joints' box grown by ``box_margin_m``). Training
built its crops the same two ways (``docs/dataset.md``).

The track holds the previous pair's joints only to *place* the next crop: they are never
reported again. When a pair yields fewer than ``min_joints`` confident joints, or an
implausible box, the track is dropped and the next pair starts from the volume.

A joint the pair did not find keeps its last place in the track, moved with the body (the median
step of the joints found in both pairs), for as long as the track holds. Where that place lies
outside the crop the pair used, in either camera, the joint could not have been found there: it is
*carried* (the crop and the box cover it) until it is found again. Before, a crop framed the joints
found alone: legs hidden for a few pairs (a table) shrank it to the upper body, and when they came
back they lay outside every later crop, never found again while the track held. A hidden joint
still inside the crop is not carried: the crop stays what the joints found make it.

A pair with one unusable camera (``frame_check.single_view_2d``) gives 2D joints in the other
camera only: there is no 3D track then, but that camera's next crop follows its 2D joints (a
*view track*), while the other camera and the sweep stay on the working volume. Where both frames passed (the
person seen by one camera only), the other camera's next crop frames where the seen joints' rays cross the working
volume instead (:func:`rays_in_box`): its whole-volume crop may draw a far person too small for the model to find.

Pure numpy; the :class:`SubjectTracker` is a small state holder around pure functions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ghnerf_runtime.config import RoiConfig, TrackingConfig
from ghnerf_runtime.errors import GeometryError, ShapeError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume
from ghnerf_runtime.preprocess import Roi, crop_camera, roi_from_joints, roi_from_volume
from ghnerf_runtime.rig_file import standing_person_px

__all__ = ["Track", "Regions", "SubjectTracker", "keep_roi", "plan_regions", "snap_roi", "track_from_joints",
           "volume_regions", "box_corners", "cold_person_share", "volume_tiles", "rays_in_box", "COLD_TILE_SPLITS",
           "COLD_TILE_OVERLAP_M"]

#: ``tracking.cold_tiles_below_share``: the working volume's tiles, this many along x (left/right) and along z
#: (near/far)
COLD_TILE_SPLITS = (2, 2)
#: and how far each tile reaches past its share of the volume where it meets another: the sim's people keep their
#: pelvis 0.3 m inside the volume, and a person straddling a cut is then wholly inside one tile
COLD_TILE_OVERLAP_M = 0.3


@dataclass(frozen=True, eq=False)
class Track:
    """The subject as last seen.

    Attributes:
        joints: ``(J, 3)`` rig-frame joints (metres); only ``valid`` rows mean anything.
        confidence: ``(J,)``.
        valid: ``(J,)`` bool, joints that count for the track (found, or carried).
        box: ``(2, 3)`` subject box ``(min, max)``, the valid joints' box grown by the margin.
        sequence: the pair number the joints came from.
        carried: ``(J,)`` bool, the valid joints this pair did not find (module docstring); ``None``: none.
        known: ``(J,)`` bool, the joints with a place in ``joints`` (valid, or remembered); ``None``: the valid.
    """

    joints: np.ndarray
    confidence: np.ndarray
    valid: np.ndarray
    box: np.ndarray
    sequence: int
    carried: np.ndarray | None = None
    known: np.ndarray | None = None

    @property
    def found(self) -> np.ndarray:
        """``(J,)`` the joints this track's pair found."""
        return self.valid if self.carried is None else self.valid & ~self.carried


@dataclass(frozen=True, eq=False)
class Regions:
    """What the model looks at for one pair.

    Attributes:
        rois: one :class:`Roi` per source camera (undistorted full-image pixels).
        box: ``(2, 3)`` the box the plane sweep spans (subject box, or the working volume).
        tracked: True when both came from a track, False for the working volume.
    """

    rois: tuple[Roi, ...]
    box: np.ndarray
    tracked: bool


def box_corners(box: np.ndarray) -> np.ndarray:
    """``(8, 3)`` corners of a ``(2, 3)`` ``(min, max)`` box."""
    lo, hi = np.asarray(box, dtype=np.float64)
    bits = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])
    return np.where(bits == 1, hi, lo)


def track_from_joints(joints: np.ndarray, confidence: np.ndarray, valid: np.ndarray, config: TrackingConfig,
                      sequence: int = 0, previous: Track | None = None,
                      unseen: np.ndarray | None = None) -> Track | None:
    """A :class:`Track` from one pair's 3D joints, or ``None`` when they cannot carry one.

    A track needs ``config.min_joints`` finite joints with confidence ``>= min_confidence``
    and a box no larger than ``max_box_size_m``. ``previous`` (the track before): the joints this pair
    did not find keep their places, moved with the body (module docstring); those ``unseen`` marks
    (``(J,)``: placed outside this pair's crop; ``None``: all), or carried before, are carried, unless
    that makes the box larger than ``max_box_size_m``.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 2 or joints.shape[1] != 3:
        raise ShapeError(f"joints must have shape (J, 3), got {joints.shape}")
    conf = np.asarray(confidence, dtype=np.float64).reshape(-1)
    found = np.asarray(valid, bool).reshape(-1)
    if conf.shape != found.shape or found.shape[0] != joints.shape[0]:
        raise ShapeError(f"confidence and valid must have shape ({len(joints)},), got {conf.shape} and "
                         f"{found.shape}")
    ok = found & (conf >= config.min_confidence) & np.all(np.isfinite(joints), axis=1)
    if int(ok.sum()) < config.min_joints:
        return None
    lo, hi = joints[ok].min(axis=0), joints[ok].max(axis=0)
    if np.any(hi - lo > config.max_box_size_m):
        return None
    points, known, carried = joints.copy(), ok.copy(), np.zeros_like(ok)
    if previous is not None and previous.joints.shape == joints.shape:
        both = ok & previous.found
        remembered = (previous.valid if previous.known is None else previous.known) & ~ok
        if both.any() and remembered.any():
            points[remembered] = previous.joints[remembered] + np.median(joints[both] - previous.joints[both], axis=0)
            remembered &= np.all(np.isfinite(points), axis=1)
            before = np.zeros_like(ok) if previous.carried is None else previous.carried
            carried = remembered & (before | (True if unseen is None else np.asarray(unseen, bool)))
            if carried.any():
                wide_lo, wide_hi = np.minimum(lo, points[carried].min(0)), np.maximum(hi, points[carried].max(0))
                if np.any(wide_hi - wide_lo > config.max_box_size_m):  # one far off (an outlier found once): forgotten
                    remembered &= ~carried
                    carried[:] = False
                else:
                    lo, hi = wide_lo, wide_hi
            known |= remembered
    box = np.stack([lo - config.box_margin_m, hi + config.box_margin_m])
    return Track(points, conf.astype(np.float32), ok | carried, box, int(sequence), carried, known)


def snap_roi(roi: Roi, step: int) -> Roi:
    """Round a ROI outwards to a grid of ``step`` pixels (it only grows), for remap-table reuse."""
    if step <= 1:
        return roi
    x0, y0 = roi.x0 // step * step, roi.y0 // step * step
    size = max(roi.x0 + roi.size - x0, roi.y0 + roi.size - y0)
    return Roi(x0, y0, -(-size // step) * step)


def keep_roi(previous: Roi | None, new: Roi, keep_frac: float) -> Roi:
    """``previous`` while ``new`` lies inside it and is at least ``1 - keep_frac`` of its size, else ``new``.

    Example:
        >>> keep_roi(Roi(0, 0, 100), Roi(10, 10, 85), 0.2), keep_roi(Roi(0, 0, 100), Roi(10, 10, 95), 0.2)
        (Roi(x0=0, y0=0, size=100), Roi(x0=10, y0=10, size=95))
    """
    if previous is None or keep_frac <= 0:
        return new
    inside = (new.x0 >= previous.x0 and new.y0 >= previous.y0 and new.x0 + new.size <= previous.x0 + previous.size
              and new.y0 + new.size <= previous.y0 + previous.size)
    return previous if inside and new.size >= (1.0 - keep_frac) * previous.size else new


def plan_regions(rig: Rig, track: Track | None, roi_config: RoiConfig,
                 previous: tuple[Roi, ...] | None = None, rolls: tuple[float, float] = (0.0, 0.0)) -> Regions:
    """Crop windows for both source cameras and the sweep box: from the track when it gives a
    crop in both cameras, else from the working volume. ``previous`` (the last tracked crops) are
    kept while the new ones fit inside them (:func:`keep_roi`). ``rolls``: each camera's crop
    rotation (``RoiConfig.upright``), which the windows are sized for.

    Raises:
        GeometryError: the working volume is not visible in a camera (a rig file error).
    """
    cams = rig.pair
    if track is not None:
        rois = []
        for k, cam in enumerate(cams):
            roi = roi_from_joints(cam, track.joints, np.where(track.valid, 1.0, 0.0), roi_config.joint_margin_frac,
                                  roi_config.min_size_px, min_confidence=0.5, min_joints=3, roll_deg=rolls[k],
                                  edge_crop=roi_config.edge_crop)
            if roi is None:
                break
            roi = snap_roi(roi, roi_config.snap_px)
            rois.append(keep_roi(previous[k] if previous else None, roi, roi_config.keep_frac))
        else:
            return Regions(tuple(rois), track.box.copy(), True)
    return volume_regions(rig, roi_config, rolls)


def volume_regions(rig: Rig, roi_config: RoiConfig, rolls: tuple[float, float] = (0.0, 0.0)) -> Regions:
    """The cold-start regions: the working volume (grown by ``volume_margin_m``) in each camera."""
    volume = rig.volume.grown(roi_config.volume_margin_m) if roi_config.volume_margin_m > 0 else rig.volume
    rois = []
    for cam, roll in zip(rig.pair, rolls):
        try:
            rois.append(roi_from_volume(cam, volume, roll_deg=roll))
        except GeometryError as e:
            raise GeometryError(f"rig {rig.rig_id!r}: the working volume is not visible in camera "
                                f"{cam.name!r} ({e})") from e
    return Regions(tuple(rois), np.stack([volume.min_corner, volume.max_corner]), False)


def cold_person_share(rig: Rig, regions: Regions) -> float:
    """The height of a person standing at the working volume's centre (``rig_file.standing_person``) as a share of
    the side of ``regions``' crops, the pair's worse camera: what a cold pass sees of them (the model learnt people of
    about 0.49 of its input and more, 63 of 128 pixels, at 2.2-4 m)."""
    return min(standing_person_px(cam, rig.volume) / roi.size for cam, roi in zip(rig.pair, regions.rois))


def volume_tiles(rig: Rig, roi_config: RoiConfig, rolls: tuple[float, float] = (0.0, 0.0)) -> tuple[Regions, ...]:
    """The working volume cut into :data:`COLD_TILE_SPLITS` sub-volumes (left/right, near/far), each grown by
    :data:`COLD_TILE_OVERLAP_M` into its neighbours, as cold-start regions (``tracking.cold_tiles_below_share``): each
    tile's crop is smaller than the whole volume's, so a person in it is larger in the model's input. A tile not
    visible in a camera is left out."""
    lo, hi = rig.volume.min_corner, rig.volume.max_corner
    xs = np.linspace(lo[0], hi[0], COLD_TILE_SPLITS[0] + 1)
    zs = np.linspace(lo[2], hi[2], COLD_TILE_SPLITS[1] + 1)
    tiles = []
    for i in range(COLD_TILE_SPLITS[0]):
        for k in range(COLD_TILE_SPLITS[1]):
            a = np.array([max(lo[0], xs[i] - COLD_TILE_OVERLAP_M), lo[1], max(lo[2], zs[k] - COLD_TILE_OVERLAP_M)])
            b = np.array([min(hi[0], xs[i + 1] + COLD_TILE_OVERLAP_M), hi[1],
                          min(hi[2], zs[k + 1] + COLD_TILE_OVERLAP_M)])
            try:
                tiles.append(volume_regions(Rig(rig.cameras, WorkingVolume(a, b), rig.rig_id), roi_config, rolls))
            except GeometryError:
                continue
    return tuple(tiles)


def rays_in_box(camera: Camera, pixels: np.ndarray, box: np.ndarray) -> np.ndarray:
    """``(2M, 3)``: where the rays of ``camera`` through ``pixels`` ``(N, 2)`` (distorted image pixels) enter and
    leave ``box`` ``(2, 3)`` (min and max corners, rig frame), for the ``M`` of them that cross it in front of the
    camera (a pixel the lens model cannot reach has no ray). The other camera of the pair sees each such ray's
    stretch as the segment between its two points' projections: all that a person seen in ``camera`` can be."""
    origins, dirs = camera.rays(np.asarray(pixels, dtype=np.float64).reshape(-1, 2))
    lo, hi = np.asarray(box, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):  # a ray along a face: +-inf, or NaN (dropped) on it
        t_lo, t_hi = (lo - origins) / dirs, (hi - origins) / dirs
        enter = np.maximum(np.minimum(t_lo, t_hi).max(axis=1), 0.0)
        leave = np.maximum(t_lo, t_hi).min(axis=1)
        crosses = np.isfinite(enter) & np.isfinite(leave) & (leave > enter)
    near = origins[crosses] + enter[crosses, None] * dirs[crosses]
    far = origins[crosses] + leave[crosses, None] * dirs[crosses]
    return np.concatenate([near, far])


class SubjectTracker:
    """Holds the current :class:`Track` (or none) and turns it into :class:`Regions`.

    Args:
        rig: the calibrated rig (its first two cameras are the sources).
        config: when to keep or drop the track.
        roi_config: crop margins.
        rolls: each source camera's crop rotation (``RoiConfig.upright``), degrees.
    """

    def __init__(self, rig: Rig, config: TrackingConfig, roi_config: RoiConfig,
                 rolls: tuple[float, float] = (0.0, 0.0)) -> None:
        self.rig = rig
        self.config = config
        self.roi_config = roi_config
        self.rolls = (float(rolls[0]), float(rolls[1]))
        self.track: Track | None = None
        #: ``(camera index, crop)`` of the one camera a single-view pair saw the subject in
        self.view_track: tuple[int, Roi] | None = None
        #: with a view track, the other camera's crop on the seen joints' rays (``update_view(other_on_rays=)``)
        self.view_other: Roi | None = None
        self._volume = volume_regions(rig, roi_config, self.rolls)
        self._last_rois: tuple[Roi, ...] | None = None
        self._used: Regions | None = None  # the regions of the pair being estimated (carried joints)
        self.drops = 0
        #: how many times :meth:`reset` ran: what was judged of the forgotten subject's crops is void past one (the
        #: estimator's cached whole-volume verdict of a rays crop, ``rays_recheck.VolumeVerdict``)
        self.resets = 0

    @property
    def volume_regions(self) -> Regions:
        """The whole working volume's regions (a cold pass's), whatever the track."""
        return self._volume

    def regions(self) -> Regions:
        if self.track is None or not self.config.enabled:
            self._last_rois = None
            self._used = None  # no track to carry joints from
            if self.view_track is not None:
                k, roi = self.view_track
                rois = list(self._volume.rois)
                rois[k] = roi
                if self.view_other is not None:
                    rois[1 - k] = self.view_other
                return Regions(tuple(rois), self._volume.box, False)
            return self._volume
        regions = plan_regions(self.rig, self.track, self.roi_config, self._last_rois, self.rolls)
        self._last_rois = regions.rois if regions.tracked else None
        self._used = regions
        return regions

    def update(self, joints: np.ndarray, confidence: np.ndarray, valid: np.ndarray, sequence: int = 0) -> bool:
        """Replace the track by this pair's joints; returns whether a track is held afterwards."""
        new = (track_from_joints(joints, confidence, valid, self.config, sequence, self.track, self._unseen(valid))
               if self.config.enabled else None)
        if new is None and self.track is not None:
            self.drops += 1
        self.track = new
        self.view_track = None
        self.view_other = None
        self._used = None  # the next pair's crop is known once regions() gives it
        return new is not None

    def _unseen(self, valid: np.ndarray) -> np.ndarray | None:
        """``(J,)`` the held track's places that lie outside the crop this pair used in either camera (what
        :meth:`regions` last gave), where the model could not have found them; ``None`` without a track; none
        when no crop is known (no :meth:`regions` since the track was made). Only the joints this pair did not
        report (``valid``) are looked at: the others are not carried."""
        if self.track is None:
            return None
        known = self.track.valid if self.track.known is None else self.track.known
        out = np.zeros(len(known), bool)
        ask = known & ~np.asarray(valid, bool).reshape(-1) if np.shape(valid) == known.shape else known
        if self._used is None or not ask.any():  # (every joint reported: nothing to carry, the usual pair)
            return out
        points = self.track.joints[ask]
        for cam, roi, roll in zip(self.rig.pair, self._used.rois, self.rolls):
            if roll == 0.0:  # the window itself, in undistorted pixels
                uv, depth = cam.project(points, distort=False)
                uv = uv - [roi.x0, roi.y0]
            else:  # the crop as the model saw it, rotated upright about its centre
                uv, depth = crop_camera(cam, roi, roi.size, roll).project(points, distort=False)
            out[ask] |= ~((depth > 0) & np.all((uv >= -0.5) & (uv <= roi.size - 0.5), axis=1))
        return out

    def update_view(self, camera: int, joints_2d: np.ndarray, confidence: np.ndarray,
                    other_on_rays: bool = False) -> bool:
        """A single-view pair: camera ``camera`` (rig order) saw ``(J, 2)`` joints (distorted image
        pixels; confidence 0 where missing). Its next crop follows them (as many confident joints as
        a 3D track needs); the 3D track is dropped. ``other_on_rays`` (both frames passed: the person is seen by
        that camera only): the other camera's next crop frames where those joints' rays cross the working volume
        (:meth:`_crop_on_rays`), not the whole volume. Returns whether a view track is held afterwards."""
        cfg, rc = self.config, self.roi_config
        self.track = None
        self._last_rois = None
        previous = self.view_track[1] if self.view_track is not None and self.view_track[0] == camera else None
        # a joint at exactly min_confidence counts, as for the 3D track (roi_from_joints asks for more than its
        # min_confidence; missing joints have confidence 0 and still do not count)
        conf = np.asarray(confidence, dtype=np.float64)
        counted = np.where(conf >= cfg.min_confidence, conf, 0.0)
        roi = roi_from_joints(self.rig.pair[camera], joints_2d, counted, rc.joint_margin_frac, rc.min_size_px,
                              min_confidence=0.0, min_joints=cfg.min_joints,
                              roll_deg=self.rolls[camera], edge_crop=rc.edge_crop) if cfg.enabled else None
        self.view_track = None if roi is None else (camera, keep_roi(previous, snap_roi(roi, rc.snap_px),
                                                                     rc.keep_frac))
        self.view_other = (self._crop_on_rays(camera, np.asarray(joints_2d, dtype=np.float64)[counted > 0])
                           if other_on_rays and self.view_track is not None else None)
        return self.view_track is not None

    def rays_camera(self, regions: Regions) -> int | None:
        """The camera whose crop in ``regions`` is :attr:`view_other` (on the rays of the joints the other camera
        saw alone), or None."""
        if self.view_track is None or self.view_other is None or regions.tracked:
            return None
        other = 1 - self.view_track[0]
        return other if regions.rois[other] == self.view_other else None

    def _crop_on_rays(self, camera: int, seen: np.ndarray) -> Roi | None:
        """The other camera's crop showing where the rays of ``camera`` through ``seen`` ``(N, 2)`` (the counted
        joints, distorted pixels) cross the working volume (grown as the cold crop's): the person is somewhere
        along them, and a far one is drawn larger than in the whole volume's crop, which may draw them too small for
        the model to find (docs/rig-file.md, session 69). None (the whole volume's crop) where fewer than
        ``tracking.min_joints`` rays cross it or their stretch is outside that camera's image."""
        rc, other = self.roi_config, 1 - camera
        points = rays_in_box(self.rig.pair[camera], seen, self._volume.box)
        if len(points) < 2 * self.config.min_joints:
            return None
        roi = roi_from_joints(self.rig.pair[other], points, np.ones(len(points)), rc.joint_margin_frac,
                              rc.min_size_px, roll_deg=self.rolls[other], edge_crop=rc.edge_crop)
        return None if roi is None else snap_roi(roi, rc.snap_px)

    def follow(self, track: Track) -> None:
        """Take ``track``, another tracker's (the same subject seen through crops turned otherwise: the estimator's
        ``roi.turn_search``), as this one's: the next :meth:`regions` plans this tracker's crops around it anew (the
        other's windows were sized for its own rolls)."""
        self.track = track
        self.view_track = None
        self.view_other = None
        self._last_rois = None
        self._used = None

    def reset(self) -> None:
        """Forget the subject (next pair starts from the working volume)."""
        self.resets += 1
        self.track = None
        self.view_track = None
        self.view_other = None
        self._last_rois = None
        self._used = None
