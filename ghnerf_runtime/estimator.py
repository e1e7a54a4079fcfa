"""``Estimator``: a frame pair and the rig -> 25 BODY_25 joints in 3D and in both images.

Per pair (stage names are the keys of ``PairResult.timing_ms``):

1. ``preprocess`` -- the crop window of each camera comes from the tracked subject (previous
   pair's joints plus a margin) or, cold, from the rig's working volume
   (:mod:`ghnerf_runtime.tracking`); one ``cv2.remap`` per camera undistorts, crops and resizes
   to the model resolution (remap tables cached per window); RGB float in [0, 1]. Each crop is
   checked: a flat (black, saturated) or noise crop skips the model, and every joint comes back
   missing (``PairResult.frame_reason`` says which camera, and why).
2. ``encoder`` -- image and human features of both views.
3. ``volume`` -- plane-sweep cost volume and depth of each source view (the sources are the
   targets), between near/far of the subject box (the working volume when cold).
4. ``render_heat`` -- joint heatmaps of each source view on the heatmap grid, rendered only on
   the rays covering the projected subject box (tracked) or the whole crop (cold); the colour
   branch is never computed here. With ``heatmaps.source = "encoder"`` the heatmaps are the
   encoder graph's own 2D output instead, and stages 3-4 run only when the 3D method needs the
   rendered depth (``depth_centroid``, or triangulation's ``single_view_fallback`` where no skeleton
   prior runs); ``volumetric`` runs stage 3 alone, then its ``query`` graph.
5. ``decode_2d`` -- OpenPose-style peaks with subpixel refinement and peak-value confidence
   (:func:`ghnerf_runtime.keypoints.decode_keypoints`), mapped back to the original
   (distorted) image pixels.
6. ``joints_3d`` -- triangulation (default), volumetric query or depth centroid
   (:mod:`ghnerf_runtime.joints3d`; comparison in docs/runtime.md); with triangulation and a
   model folder that has one, the learnt skeleton prior then gives the whole skeleton
   (:mod:`ghnerf_runtime.skeleton_prior`, ``joints3d.skeleton_prior``); then the track is updated
   (or dropped when too few joints were found). A pair that shows nobody in 3D but someone in one
   view's own encoder heatmaps (a person seen by one camera only) reports that view's 2D joints
   (``frame_check.single_view_2d``, ``PairResult.single_view``), and that camera's next crop follows them.
7. on request, ``novel_volume`` / ``novel_render`` / ``novel_compose`` -- the novel view. On a
   tracked pair it is rendered in a worker thread during stages 5-6 (``novel_view.overlap``),
   so these stage times overlap the keypoint stages and ``total`` is less than their sum. Then, in
   this thread once the joints are known, over the body proxy of this pair's joints: with a model
   folder that has one, ``novel_paint`` repaints it with the learnt painter
   (:mod:`ghnerf_runtime.novel_painter`, ``novel_view.painter``); with ``novel_view.proxy_blend``,
   ``novel_proxy`` recolours it from the source crops (:mod:`ghnerf_runtime.proxy_blend`); with
   ``novel_view.matte``, ``novel_matte`` fades it to the background away from the proxy
   (:mod:`ghnerf_runtime.proxy_matte`).

Every output is finite; a missing joint has coordinates 0, confidence 0 and ``missing`` set.
Joints are only ever this pair's: the track only places the next crop.

The :class:`~ghnerf_runtime.session.ModelSession` is injected (or built by
:meth:`Estimator.from_config`); the estimator never touches onnxruntime itself.
"""
from __future__ import annotations

import functools
import logging
import math
import numbers
import time
from collections import OrderedDict, abc
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import cv2
import numpy as np
# np.median (_median_confidence, every pair; the decoding's medians are joints3d.sorted_median) imports numpy.ma on its
# first call: 10-70 ms on session 58's host, paid by the first pair a daemon streams unless imported here, at load
import numpy.ma  # noqa: F401

from ghnerf_runtime.body25 import BODY_PARTS, FEET, FLOOR_JOINTS, JOINT_NAMES
from ghnerf_runtime.body_lie import another_turn_may_hold, body_axis, degrees_short_of_lying, lies_as_kept_turn, \
    lies_as_turned, reads_flipped
from ghnerf_runtime.config import EstimatorConfig, FrameCheckConfig, RoiConfig
from ghnerf_runtime.body_proxy import BodyProxy, proxy_body, proxy_depth
from ghnerf_runtime.contract import Normalisation, near_far_from_box, source_centers, source_projections, \
    target_inputs, target_projections
from ghnerf_runtime.errors import FrameError, GeometryError, ModelError
from ghnerf_runtime.frame_reasons import FLAT, NOISE, NON_FINITE, REASONS
from ghnerf_runtime.flip_test import flip_averaged, joint_peaks, mirror_images, mirror_projections, presence_peak, \
    ranked_peak
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig
from ghnerf_runtime.geometry.triangulation import TwoViewCameras, TwoViewSolution, triangulate_midpoint
from ghnerf_runtime.handedness import handedness
from ghnerf_runtime.joints3d import Joints3D, ViewAgreement, depth_centroid_joints, gate_presence, gate_to_box, \
    lower_foot_m, near_the_body, sorted_median, \
    query_grid, solve_two_view_peaks, triangulate_joints, triangulate_joints_checked, volumetric_joints
from ghnerf_runtime.keypoints import Keypoints2D, decode_blocks, decode_keypoints, heatmap_to_model_pixels
from ghnerf_runtime.novel_view import NovelView, NovelViewRequest, check_strides, heatmap_overlay, interpolate_camera, \
    novel_pivot, novel_target, render_novel_view, skeleton_overlay
from ghnerf_runtime.novel_painter import FILE_NAME as PAINTER_FILE
from ghnerf_runtime.novel_painter import NovelPainter, angle_from_sources_deg
from ghnerf_runtime.others_scan import ScanClock, box_cells, someone_else, subject_box
from ghnerf_runtime.plain_values import converts_to_finite_float, is_true_false, plain_scalar, whole_number_or_none
from ghnerf_runtime.proxy_blend import model_input_to_rgb, proxy_blend, subject_region
from ghnerf_runtime.proxy_matte import proxy_matte
from ghnerf_runtime.preprocess import (
    CropMaps,
    Roi,
    build_undistort_crop_maps,
    camera_normalized,
    crop_camera,
    preprocess_image,
    upright_roll_deg,
)
from ghnerf_runtime.skeleton_prior import FILE_NAME as PRIOR_FILE
from ghnerf_runtime.skeleton_prior import PriorCameras, disagreement_m
from ghnerf_runtime.rays import block_ray_uv, box_block, common_blocks, full_block, scatter_block
from ghnerf_runtime.rays_recheck import VolumeVerdict, mean_level
from ghnerf_runtime.scene_change import (CALM_AFTER_PASSES, ONE_VIEW_NOT_VAIN_PAIRS, RESTLESS_AFTER_WAKES, SceneCopy,
                                         changed_masks, masks_wake, pair_copies, restless_with_neighbours)
from ghnerf_runtime.smoothing import OneEuroJoints
from ghnerf_runtime.tracking import Regions, SubjectTracker, Track, box_corners, cold_person_share, volume_tiles
from ghnerf_runtime.subject import STILL_SEVERAL_MIN_JOINTS, SubjectSelector, guessed_joints, joints_shown_twice, \
    picks_subject
from ghnerf_runtime.two_people import TORSO_LIMBS_M, reads_as_two_people, torso_excess

__all__ = ["Estimator", "PairResult", "check_crop", "crop_statistics", "coarse_detail_share", "check_model_files",
           "load_session", "KEYPOINT_STAGES", "NOVEL_STAGES", "NOVEL_PROXY_STAGE", "NOVEL_PAINT_STAGE",
           "NOVEL_MATTE_STAGE", "joints_shown_twice"]

log = logging.getLogger(__name__)

#: Skeleton prior: confidence = exp(-expected error / this).
_PRIOR_CONFIDENCE_SCALE_M = 0.1
#: A source camera's picture rolled more than this from upright is said in the log (rotated or not).
_NOTED_ROLL_DEG = 1.0
#: Skeleton prior: the crop follows the prior's joints expected within this (m), whatever is reported.
_PRIOR_FOLLOW_MAX_ERROR_M = 0.25
#: The floor check's foot joints (PairResult.lowest_foot_m) lie at least this share of the crop window's side inside
#: each frame: with the feet cut off by the frame's edge the model still puts their peaks at that edge, both views
#: agree, and the "feet" triangulate far above the floor (on a simulated take whose frames were cut at 60-70 % of
#: their height such peaks lay 0-35 px inside the edge, the crops 176-250 px: tests/ghnerf_runtime/
#: test_view_agreement.py keeps them out).
_FLOOR_EDGE_FRAC = 0.2
#: The floor check counts a person on their feet only: a pair whose torso joints triangulated from strong peaks (their
#: median height; none such: no figure) are less than this (m) above the lower foot gives no figure. A
#: handstand's feet are 1.6-1.9 m up and those of a person lying about 0.2 m (benchmarks/measure_lying_rendered.py
#: --turned-crops); standing the torso is about 1.1 m above the feet, squatting or sat on a chair 0.7 m or more.
_FLOOR_MIN_TORSO_M = 0.5
#: The floor check's foot height (PairResult.lowest_foot_m) is the median height of a foot's triangulated joints (at
#: least _FLOOR_MIN_FOOT_JOINTS of its ankle, toes and heel) less ``joints3d.foot_standing_m`` (config.FOOT_STANDING_M
#: by default, the simulated bare feet), that median on a foot flat on the floor. A foot lifted reads higher: the lower
#: foot is the one measured.
_FLOOR_MIN_FOOT_JOINTS = 2
#: The floor check's foot joints lie within this (m, across the floor) of the median of the person's triangulated
#: joints, which replaces the working volume's box gates for it (a camera panned far takes the whole person out of
#: the box). On the true rig the shipped model's foot joints the box gates kept lay a median 0.16 m off it, 99 % within
#: 0.62 m, all within 0.98 m; 17 of the 20 they dropped 1.8-6.5 m off (a wrong pair of peaks), 3 at 0.93-0.98 m
#: (benchmarks/measure_foot_spread.py; docs/calibration.md, "A camera panned far"). A dropped foot of a kick or a
#: lunge costs one joint, not the pair's figure; stray ones kept would pull their foot's median down (two of its four
#: joints, or one of a foot with two seen: tests/ghnerf_runtime/test_floor_big_pan.py).
_FLOOR_BODY_M = 1.0
#: A cold tile's find (refined on its subject) whose lower foot (PairResult.lowest_foot_m) stands over
#: ``tracking.cold_tiles_max_foot_m`` (0.4 m) above the floor is refused: a person the frame's bottom edge cuts near
#: the cameras, whom the tile's crop reads whole and shrunk, the same in both views, so that the skeleton triangulates
#: too far and too high (394 mm MPJPE, its foot 0.69 m up, then tracked for frames), where the whole volume's crop
#: found them on the next pair (the example rig's sequence 1, 1.2 m ahead; benchmarks/measure_baseline.py
#: --tile-finds, docs/runtime.md, "The first tile"). Session 72, 48 sequences on each of three rigs with no refusal:
#: 56 good finds' feet -0.16 to 0.07 m, one floating bad one (that 0.69 m); any bound from 0.3 to 0.5 m refuses the
#: same (--tile-find-max-foot inf). The floor read is :func:`_tile_find_floor_y`'s.
_TORSO = BODY_PARTS["torso"]
#: Stage keys of the keypoint path, in order.
KEYPOINT_STAGES = ("preprocess", "encoder", "encoder_flip", "turn_search", "volume", "render_heat", "decode_2d",
                   "joints_3d", "scan")
#: Stage keys of the novel view.
NOVEL_STAGES = ("novel_volume", "novel_render", "novel_compose")
#: With ``novel_view.proxy_blend`` only.
NOVEL_PROXY_STAGE = "novel_proxy"
#: With the learnt painter (``novel_view.painter``) only.
NOVEL_PAINT_STAGE = "novel_paint"
#: With ``novel_view.matte`` only.
NOVEL_MATTE_STAGE = "novel_matte"


@dataclass(frozen=True, eq=False)
class PairResult:
    """The joints of one frame pair.

    Attributes:
        sequence: the pair's number (as passed to :meth:`Estimator.estimate`).
        joint_names: BODY_25 names, the order of every joint axis.
        joints_3d: ``(25, 3)`` rig frame, metres; 0 where missing.
        confidence: ``(25,)`` float32; 0 where missing. Triangulation: the geometric mean of the
            views' peak values; with the skeleton prior, ``exp(-expected error / 0.1 m)``.
        missing: ``(25,)`` bool.
        joints_2d: camera name -> ``(25, 2)`` pixels of the original (distorted) image; 0 where
            missing in that camera.
        confidence_2d: camera name -> ``(25,)`` peak values; 0 where missing.
        missing_2d: camera name -> ``(25,)`` bool.
        timing_ms: stage -> milliseconds (``total`` included).
        tracked: the crops came from the track (False: from the working volume).
        frame_ok: camera name -> False when the frame check rejected the crop (model not run).
        frame_reason: camera name -> ``None`` when the crop passed the frame check, else why it was
            rejected: one of :data:`ghnerf_runtime.frame_reasons.REASONS` (``"flat"``, ``"noise"``,
            ``"non-finite"``). Left out, every camera whose frame passed gets ``None``.
        rois: camera name -> the crop window used (undistorted pixels).
        method: the 3D method used.
        novel_view: the rendered novel view when requested, else ``None`` (also when requested for a
            pair that has no subject to view: a frame rejected, or nobody found).
        prior_disagreement_m: the skeleton prior's distance from the triangulation (the median over the
            triangulated joints, :func:`ghnerf_runtime.skeleton_prior.disagreement_m`); ``None`` where the prior
            did not run, too few joints were triangulated to tell, or nobody is reported (also a ``several_people``
            pair whose subject's peaks make nobody, since session 55: the prior's first run there was fed both
            people's). A ``several_people`` pair whose subject was picked or tracked measures the prior fed that
            subject's peaks against the subject's pairings.
        prior_fallback: the prior ran but its skeleton disagreed with the triangulation by more than
            ``joints3d.max_prior_disagreement_m``, so the joints are the triangulated ones (as without the prior);
            never on a pair that reports nobody.
        someone_else: ``presence.scan_every_s`` set (off by default, since session 64): the latest scan of the whole
            working volume, at most that long ago, showed someone besides the tracked subject in both views
            (:mod:`~ghnerf_runtime.others_scan`); ``None``: no scan since the track began (the option off, a pair
            without a track, the track's cold pair: the first scan is ``scan_every_s`` after it). Unlike ``several_people`` it looks outside the subject's crop; it misses a person
            hidden behind the subject in a view or inside the subject's box.
        several_people: at least ``joints3d.second_person_min_joints`` joint maps showed a second strong peak in
            both views (two people in view; fewer, down to one, while the pairs follow a flagged pair's subject),
            or, on a tracked pass with ``joints3d.behind_min_joints`` set (off by default), in one view alone (one
            person behind the other as the other camera sees them, since session 56: without a track the person
            that camera sees is reported, whatever the rule), or, on a tracked pass (since session 58), the peaks
            strong in both views make a torso no one body has (:func:`~ghnerf_runtime.two_people.mixed_torso`: one
            person's mid-hip, the other's hip): only
            the joints within ``joints3d.max_track_step_m`` of the tracked subject's are reported (3D and
            2D); without a track, the joints of the person ``joints3d.pick_subject`` names, whom the track then
            follows (none with ``pick_subject: none``; docs/two-people.md, "Two people in the working volume").
            With the triangulation each is the pairing of the views' peaks and runner-ups nearest the track (or
            the subject's, where the two people are separated), and each camera's 2D joint the peak it came
            from; with the skeleton prior (since session 55) the 3D joints are then the prior's, fed those peaks
            alone (:meth:`Estimator._subject_prior`), and a joint the prior places without a pairing of the
            subject's has no 2D joint (neither view's peak of it is known to be the subject's).
        single_view: the camera whose 2D joints alone are the pair's answer (``frame_check.single_view_2d``):
            a person seen by that camera only, or the other camera's frame rejected. Every 3D joint is then
            missing, and so is every 2D joint of the other camera. ``None``: a pair with 3D joints, or nobody.
        reprojection_px_median: how far apart the two views' confident peaks are from meeting in 3D, before the
            ``joints3d.max_reprojection_px`` gate: the median over the joints with a peak of at least the presence
            threshold in both views (at least ``presence.min_joints`` of them) of the larger of the views'
            reprojection errors, in model-input pixels (:class:`ghnerf_runtime.joints3d.ViewAgreement`), whatever
            ``joints3d.method``. It grows when a camera has moved since calibration (the daemon watches it:
            docs/daemon.md). ``None``: too few such joints, or a frame rejected. A ``several_people`` pair measures
            the reported subject's own pairings (each view's peak may be the other person's), those the gate kept
            (:meth:`SubjectSelector.subject_figures`); where they give none (nobody picked: a camera knocked past the
            gate leaves no pairing to pick from; ``pick_subject: none``), since session 56 both people's peaks paired
            one to one, before the gate (:meth:`SubjectSelector.matched_px`).
        lowest_foot_m: the height above the floor (the rig frame's ``-y``, metres) of the lower foot (since session 56:
            the median height of its ankle, heel and toes, :data:`ghnerf_runtime.body25.FEET`, at least two of them,
            less ``joints3d.foot_standing_m``, their median on a foot flat on the floor, 0.04 m by default; before,
            the lowest such joint),
            of the joints triangulated from peaks of at least the presence threshold in both views, kept by the
            reprojection gate, within 1 m across the floor of the median of the person's triangulated joints (since
            session 56 in place of the working volume's box gates, which a camera panned far takes the whole person
            out of: docs/calibration.md) and shown by both frames at least a fifth of the crop window's side inside
            their edges (a foot cut off by the frame gets a peak at its edge), whatever ``joints3d.method`` and the
            skeleton prior report (the prior keeps its feet near the floor): near 0 for a person standing or walking
            (a foot lifted is the higher one), it moves when a camera turned since calibration (a pan, which
            ``reprojection_px_median`` does not show: docs/calibration.md). ``None``: no foot with two such joints
            (feet out of view or near a frame's edge), nobody by the peaks (the presence gate; since session 56 a
            person the box gates leave nobody of still counts), a frame rejected, two people in view not told apart (a
            ``several_people`` pair measures the reported subject's own pairings:
            :meth:`SubjectSelector.subject_figures`; where they give none, since session 57 each person's own feet,
            both people's pairings split into two people before the box gates: :meth:`SubjectSelector.matched_foot`),
            or a person not on their feet (the torso joints triangulated likewise less than 0.5 m above that foot, or
            none: upside down, lying).
        handedness: since session 65, whether the triangulated person is a person (+1) or a mirror image (-1)
            (:func:`ghnerf_runtime.handedness.handedness`: the nose and toes ahead of the neck and ankles along the
            facing direction that the body's left and up axes give), of the joints the floor check reads (triangulated
            from peaks of at least the presence threshold in both views, near the body), not the skeleton prior's
            (which answers a person whatever the triangulation). Negative over a window when the two cameras' inputs are
            exchanged on a symmetric rig (the daemon watches it: docs/calibration.md, "Cameras exchanged").
            ``None``: too few torso joints or no nose or toes so found, a heel so found (since session 66: the
            person's back to the rig, where the model may read a back as a front, a mirror image), nobody, a frame
            rejected, or two people in view (``several_people``: the joints may be both people's). Not in
            :meth:`to_json` (not streamed).
    """

    sequence: int
    joint_names: tuple[str, ...]
    joints_3d: np.ndarray
    confidence: np.ndarray
    missing: np.ndarray
    joints_2d: dict[str, np.ndarray]
    confidence_2d: dict[str, np.ndarray]
    missing_2d: dict[str, np.ndarray]
    timing_ms: dict[str, float]
    tracked: bool
    frame_ok: dict[str, bool]
    rois: dict[str, Roi]
    method: str
    novel_view: NovelView | None = None
    frame_reason: dict[str, str | None] = field(default_factory=dict)
    prior_disagreement_m: float | None = None
    prior_fallback: bool = False
    several_people: bool = False
    single_view: str | None = None
    reprojection_px_median: float | None = None
    lowest_foot_m: float | None = None
    someone_else: bool | None = None
    handedness: float | None = None

    def __post_init__(self) -> None:
        reasons = self.frame_reason
        if not reasons:  # built without reasons: a passing frame has none, a rejected one must say why
            reasons = {name: None for name in self.frame_ok}
            object.__setattr__(self, "frame_reason", reasons)
        if list(reasons) != list(self.frame_ok):
            raise ValueError(f"PairResult.frame_reason: cameras {list(reasons)} are not frame_ok's "
                             f"{list(self.frame_ok)}")
        for name, why in reasons.items():
            if why is not None and why not in REASONS:
                raise ValueError(f"PairResult.frame_reason[{name!r}]: {why!r} is not one of {list(REASONS)}")
            if (why is None) != bool(self.frame_ok[name]):
                raise ValueError(f"PairResult.frame_reason[{name!r}] is {why!r} but frame_ok[{name!r}] is "
                                 f"{bool(self.frame_ok[name])}")
        if self.single_view is not None and not self.frame_ok.get(self.single_view, False):
            # the answer is the joints of a camera whose frame the model ran on
            raise ValueError(f"PairResult.single_view: {self.single_view!r} is not a camera whose frame passed "
                             f"(frame_ok {dict(self.frame_ok)})")
        if self.single_view is not None and self.several_people:
            # one view's joints are no one's in particular when two people are in view (the estimator keeps none)
            raise ValueError(f"PairResult.single_view {self.single_view!r} with several_people: one view's joints "
                             "of two people are no one's in particular")
        px = self.reprojection_px_median
        if px is not None and not (isinstance(px, numbers.Real) and math.isfinite(px) and px >= 0):
            # to_json promises JSON without NaN: a median of pixel distances is a finite number >= 0, or null
            raise ValueError(f"PairResult.reprojection_px_median must be a finite number >= 0 or None, got {px!r}")
        foot = self.lowest_foot_m
        if foot is not None and not (isinstance(foot, numbers.Real) and math.isfinite(foot)):
            raise ValueError(f"PairResult.lowest_foot_m must be a finite number or None, got {foot!r}")
        hand = self.handedness
        if hand is not None and not (isinstance(hand, numbers.Real) and -1.0 <= hand <= 1.0):
            raise ValueError(f"PairResult.handedness must be a number in [-1, 1] or None, got {hand!r}")

    @property
    def num_found(self) -> int:
        return int((~self.missing).sum())

    def to_json(self) -> dict:
        """The documented per-frame JSON object (docs/runtime.md): plain lists and numbers, no NaN."""
        def r(x: float, nd: int) -> float:
            return round(float(x), nd)

        return {
            "sequence": int(self.sequence),
            "joint_names": list(self.joint_names),
            "joints_3d": [[r(x, 5), r(y, 5), r(z, 5), r(c, 4)]
                          for (x, y, z), c in zip(self.joints_3d, self.confidence)],
            "joints_2d": {name: [[r(u, 2), r(v, 2), r(c, 4)] for (u, v), c in zip(uv, self.confidence_2d[name])]
                          for name, uv in self.joints_2d.items()},
            "missing": [bool(m) for m in self.missing],
            # the 2D joints' own flags (a camera's 2D joint may be missing where the 3D one is not, and back)
            "missing_2d": {name: [bool(m) for m in self.missing_2d[name]] for name in self.joints_2d},
            "tracked": bool(self.tracked),
            "frame_ok": {k: bool(v) for k, v in self.frame_ok.items()},
            "frame_reason": dict(self.frame_reason),  # null: the frame passed (since session 51)
            "method": self.method,
            # the skeleton prior's check (since session 52): null where the prior did not run or could not be checked
            "prior_disagreement_m": None if self.prior_disagreement_m is None else r(self.prior_disagreement_m, 4),
            "prior_fallback": bool(self.prior_fallback),
            "several_people": bool(self.several_people),  # since session 53
            # the camera whose 2D joints alone are the answer (since session 53): null for 3D joints or nobody
            "single_view": self.single_view,
            # the views' agreement before the reprojection gate (since session 53): null where not measured
            "reprojection_px_median": None if self.reprojection_px_median is None
            else r(self.reprojection_px_median, 3),
            # the lower triangulated foot's height (since session 54): null where none was triangulated
            "lowest_foot_m": None if self.lowest_foot_m is None else r(self.lowest_foot_m, 4),
            # anyone besides the subject in the working volume (since session 64): null where not scanned
            "someone_else": None if self.someone_else is None else bool(self.someone_else),
            "timing_ms": {k: r(v, 3) for k, v in self.timing_ms.items()},
        }


# ------------------------------------------------------------------ frame check
def _levels_per_unit(norm: Normalisation) -> float:
    lo, hi = (float(v) for v in norm.value_range)
    scale = 255.0 / (hi - lo)
    if not norm.mean_std_in_graph:
        scale *= float(np.mean(norm.std))
    return scale


def _detail_share(plane: np.ndarray, inside: np.ndarray | None, var: float) -> float:
    """``var(x - box3(x)) / var`` over the pixels whose 3x3 box lies ``inside`` (all of them when ``None``)."""
    detail = plane - cv2.blur(plane, (3, 3), borderType=cv2.BORDER_REFLECT)
    if inside is not None:  # pixels whose 3x3 box shows the frame: the padding's edge is no detail
        core = cv2.erode(inside.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        detail = detail[core if core.any() else inside]
    return float(detail.var()) / var


def crop_statistics(plane: np.ndarray, levels_per_unit: float,
                    inside: np.ndarray | None = None) -> tuple[float, float] | None:
    """The frame check's two measures of a finite model-input plane ``(S, S)``: its standard deviation in 8-bit
    levels and the share of its variance that is pixel-to-pixel detail (``var(x - box3(x)) / var(x)``), both over
    the pixels ``inside`` marks (``CropMaps.inside``; every pixel when ``None``). ``None`` where no pixel shows the
    frame; the share is ``inf`` for a plane with no variance. Apart from :func:`check_crop` so that
    ``benchmarks/measure_frame_check.py`` prints what the check compares with its thresholds."""
    shown = plane if inside is None else plane[inside]
    if shown.size == 0:
        return None
    var = float(shown.var())
    if var <= 0.0:
        return 0.0, float("inf")
    return float(np.sqrt(var) * levels_per_unit), _detail_share(plane, inside, var)


def _halved(plane: np.ndarray, inside: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """The plane's 2x2 block means (an odd last row or column dropped) and the blocks wholly ``inside``
    (cv2's area resize: NumPy's reductions over a reshaped plane cost 0.4 ms each at 128 x 128)."""
    h, w = plane.shape[0] // 2, plane.shape[1] // 2
    half = cv2.resize(plane[:2 * h, :2 * w], (w, h), interpolation=cv2.INTER_AREA)
    if inside is None:
        return half, None
    shown = cv2.resize(inside[:2 * h, :2 * w].astype(np.uint8) * 255, (w, h), interpolation=cv2.INTER_AREA)
    return half, shown == 255  # a block with a pixel outside averages to 191 or less


def coarse_detail_share(plane: np.ndarray, inside: np.ndarray | None = None) -> float:
    """The detail share of :func:`crop_statistics` measured on the plane's 2x2 block means, over the blocks wholly
    ``inside``. Averaging 2x2 pixels keeps a scene's structure and quarters the variance of pixel-to-pixel sensor
    noise, so a dim scene shot at high gain measures as a scene here, while noise, whether per pixel, in 2x2 blocks
    or smoothed, stays noise (``benchmarks/measure_frame_check.py``). ``inf`` where no block shows the frame or the
    blocks do not vary."""
    half, shown = _halved(plane, inside)
    values = half if shown is None else half[shown]
    var = float(values.var()) if values.size else 0.0
    if var <= 0.0:
        return float("inf")
    return _detail_share(half, shown, var)


def check_crop(plane: np.ndarray, levels_per_unit: float, config: FrameCheckConfig,
               inside: np.ndarray | None = None) -> tuple[bool, str]:
    """Is a model-input plane ``(S, S)`` (one channel, float) worth running the model on?

    Returns ``(ok, reason)``, the reason a word of :mod:`ghnerf_runtime.frame_reasons`: ``"flat"``
    when its standard deviation is below ``min_std`` 8-bit levels (black, saturated, covered lens),
    ``"noise"`` when more than ``max_noise_ratio`` of its variance is pixel-to-pixel detail
    (``x - box3(x)``) and so is more than ``max_coarse_noise_ratio`` of its 2x2 block means'
    (:func:`coarse_detail_share`; of the crops the fine share rejects, garbage measures 0.64 or more there, a
    scene under sensor noise of 60 levels 0.44 at most: ``benchmarks/measure_frame_check.py --sequences 30``);
    ``"non-finite"`` for NaN/inf, else ``""``.

    ``inside`` (``CropMaps.inside``) limits the statistics to the pixels that show the frame: the
    padding of a crop reaching past the frame's edge (zeros, or the faded edge of ``roi.pad_fill``) would
    otherwise give a saturated frame the contrast of a real one. A crop with no such pixel is ``"flat"``.
    """
    if not config.enabled:
        return True, ""
    if not np.all(np.isfinite(plane)):
        return False, NON_FINITE
    measured = crop_statistics(plane, levels_per_unit, inside)
    if measured is None:
        return False, FLAT
    std_levels, detail_share = measured
    if std_levels <= 0.0 or std_levels < config.min_std:  # (min_std 0 lets a flat crop this far)
        return False, FLAT
    # the coarse share only where the fine one fails: it spares noisy scenes and costs good frames nothing
    if detail_share > config.max_noise_ratio and coarse_detail_share(plane, inside) > config.max_coarse_noise_ratio:
        return False, NOISE
    return True, ""


# ------------------------------------------------------------------ estimator
#: Imported calibrations whose frame is the tool's own (its first camera's, the board's), not gravity-down.
_TOOL_FRAMES = ("opencv-stereo-calib", "anipose-toml")


def _tile_find_floor_y(rig: Rig) -> float:
    """The floor's y (y down) that the refusal of floating tile finds (``tracking.cold_tiles_max_foot_m``) reads:
    y = 0, or the working volume's floor-side bound (its largest y) where that lies higher. A rig whose frame's origin
    lies under the floor (its volume ends above y = 0) reads every foot too high by as much, and from y = 0 every tile
    find was refused; the volume is the one hint of the floor there. Never lower than y = 0: where the floor is not
    known the guard refuses less, never more (the example rig's and ``ghcal synth``'s volumes reach y = 0: 0.0)."""
    return min(0.0, float(rig.volume.max_corner[1]))


def _warn_if_not_levelled(rig: Rig) -> None:
    source = rig.metadata.get("source") if isinstance(rig.metadata, dict) else None
    fmt = source.get("format") if isinstance(source, dict) else None
    if fmt in _TOOL_FRAMES and "levelled" not in rig.metadata:
        log.warning("rig %r comes from %s and keeps that tool's frame; the runtime reads the rig frame as y down "
                    "(gravity) with the floor at y = 0 (the skeleton prior, upright crops, the working volume): level "
                    "it first with calibration.level.level_rig (docs/rig-file.md)", rig.rig_id, fmt)


#: The coarsest step (seconds) a capture time may be held in at its value: a float32 stamp of a clock 1.7e9 s from
#: its origin (the epoch) steps by 128 s, so every pair of a stream came with one time (the smoothing took each as
#: the last pair again, the track's gap test passed every pair), and one past 16384 s (4.5 hours of a monotonic
#: clock) by 2 ms or more; nanoseconds given as seconds (1.7e18) step by 256 s as a float64.
MAX_TIME_STEP_S = 1e-3


def _time_step_s(value) -> float:
    """The spacing of the float type ``value`` is held in, at its value: a NumPy float narrower than float64 in
    its own type, any other number as the float64 the runtime reads it as."""
    held = np.asarray(value)
    kind = held.dtype if held.dtype.kind == "f" and held.dtype.itemsize < 8 else np.dtype(np.float64)
    return float(np.spacing(np.abs(held.astype(kind))))


def _finite_time(value) -> bool:
    """Whether ``value`` is a finite number (a capture time): an integer past the float range (10**400) is not,
    nor is what is no number (a string): ``math.isfinite`` raised OverflowError or TypeError for them, which the
    daemon's loop (it skips a pair on a FrameError) did not expect. True/False is no time (it was read as 1 s), nor
    is a 0-d array holding one (``math.isfinite`` takes it; the rest of the runtime reads a 0-d array as its value,
    :func:`~ghnerf_runtime.plain_values.plain_scalar`)."""
    return not is_true_false(plain_scalar(value)) and converts_to_finite_float(value)


def _whole_sequence(value) -> int:
    """``estimate``'s ``sequence`` as a Python int (numpy integers too). A float was truncated in ``to_json`` (2.7 went
    out as 2, and the running count went on 3.7, 4.7...), True was pair 1, and text failed with a bare TypeError.

    :raises FrameError: not a whole number."""
    number = whole_number_or_none(value)
    if number is None:
        raise FrameError(f"sequence must be a whole number (a Python or numpy integer), got {value!r}")
    return number


def _add_ms(timing: dict[str, float], stage: str, t0: float) -> None:
    """Add the milliseconds since ``t0`` to ``timing[stage]`` (a cold start's second pass adds to the first)."""
    timing[stage] = timing.get(stage, 0.0) + 1e3 * (time.perf_counter() - t0)


@dataclass
class _Pass:
    """What one pass over a pair produced (``j3`` is ``None`` when the frame check stopped it)."""

    regions: Regions
    frame_reason: dict  # camera name -> None (the crop passed the frame check) or why it was rejected
    env: dict | None = None
    j3: Joints3D | None = None
    joints_2d: dict | None = None
    conf_2d: dict | None = None
    missing_2d: dict | None = None
    novel: "_NovelJob | None" = None  # the novel view rendering in the worker (overlap)
    crops: list | None = None  # the source crop cameras (the novel view's proxy blend reads them)
    someone: bool = False  # the presence gate found someone (always, with the gate off)
    prior_disagreement_m: float | None = None  # the skeleton prior's check (PairResult's fields of that name)
    prior_fallback: bool = False
    several_people: bool = False  # two people in view: only the tracked subject's joints kept (PairResult's)
    single_view: str | None = None  # the camera whose 2D joints alone are the answer (PairResult.single_view)
    reprojection_px_median: float | None = None  # the views' agreement before the gate (PairResult's)
    lowest_foot_m: float | None = None  # the lower triangulated foot's height (PairResult's)
    handedness: float | None = None  # a person (+1) or a mirror image (-1) by the triangulation (PairResult's)
    peaks: Keypoints2D | None = None  # both views' decoded peaks (a cold pass's faint ones pick its tile)

    @property
    def frame_ok(self) -> dict:
        return {name: why is None for name, why in self.frame_reason.items()}


@dataclass(frozen=True)
class _NovelJob:
    """A novel view rendering in the worker thread: its camera (known before the picture) and the future that
    gives ``(NovelView, timing)``."""

    camera: Camera
    future: Future

    def abandon(self) -> None:
        """Leave no render running behind: cancel it, or wait for it to end (its error is dropped)."""
        self.future.cancel() or self.future.exception()


@dataclass(frozen=True, eq=False)
class _ProxyInputs:
    """What the painter, the proxy blend and the matte read that depends on the pair's joints and the view's
    camera but not on the rendered picture (:meth:`Estimator._proxy_inputs`): built while the worker renders."""

    body: BodyProxy  # not empty
    paint: bool  # the painter runs on this view
    rgb: np.ndarray | None  # the source crops, RGB in [0, 1] (painter, blend)
    src_depth: list | None  # the proxy's depth in each source crop (painter, blend)
    depth: np.ndarray | None  # the proxy's depth in the view (painter, matte)
    ms: float  # the time it took (it counts in the first stage that reads it)


@dataclass(frozen=True, eq=False)
class _CropTerms:
    """The current crop cameras' own terms (inverses, conditioning, centres, heading): the two-view solver's and
    the skeleton prior's (None without a prior). A tracked crop keeps its cameras for many pairs, and the
    triangulation, a flagged pair's pairings and the prior's inputs read them every pair
    (:meth:`Estimator._crop_terms_for`)."""

    two_view: TwoViewCameras
    prior: PriorCameras | None

    @classmethod
    def of(cls, P: np.ndarray, with_prior: bool) -> "_CropTerms":
        """The terms of the ``(2, 3, 4)`` crop matrices ``P``: the prior's built from the two-view solver's (the
        inverses and determinants' signs computed once, and the prior's own solves made in them)."""
        two_view = TwoViewCameras.from_P(P)
        return cls(two_view, PriorCameras.from_two_view([two_view]) if with_prior else None)


@dataclass
class _CameraState:
    """Per source camera and crop turn: remap tables and crop camera per crop window and turn (LRU)."""

    camera: Camera
    roll_deg: float = 0.0  # the crops' rotation that shows them upright (RoiConfig.upright)
    turn_deg: float = 0.0  # and the turn search's on top of it (RoiConfig.turn_search: a person lying, upside down)
    # one camera's turns share it (Estimator._use_turns), so roi.map_cache_size bounds the tables per camera
    cache: "OrderedDict[tuple[Roi, float], tuple[CropMaps, Camera]]" = field(default_factory=OrderedDict)
    # the working volume's window (a cold pass's), built with the estimator and kept outside the LRU: the first pair
    # and a cold pair after a long track (whose windows pushed it out of the cache) find it built
    cold: "dict[tuple[Roi, float], tuple[CropMaps, Camera]]" = field(default_factory=dict)

    @property
    def crop_roll_deg(self) -> float:
        """The crops' whole rotation, counterclockwise degrees (:func:`build_undistort_crop_maps`' ``roll_deg``)."""
        return self.roll_deg + self.turn_deg

    @property
    def upright_pinhole(self) -> Camera:
        """The camera without its lens, turned by the quarter turns nearest upright (what a virtual camera
        between the sources follows, so that it does not spin from one to the other)."""
        turns = round(self.roll_deg / 90.0) % 4
        if not turns:
            return self.camera
        pinhole = self.camera.without_distortion()
        # a skewed camera cannot be quarter-turned exactly: rotated about its centre, its size kept
        return pinhole.rotated(90.0 * turns) if turns % 2 and pinhole.K[0, 1] != 0.0 else pinhole.quarter_turned(turns)


#: roi.turn_search: how much more a turned crop's view score (:func:`_view_score`) must be than upright's, and a
#: turned pass's median joint confidence than the upright pass's, to be taken. In a one-off look at the first four
#: bench scenes' view scores, lying across the view a quarter turn scored 0.25-0.5 higher than upright, upside down
#: a half turn 0.15-0.25; benchmarks/measure_lying_rendered.py --turn-search measures the search as a whole.
_TURN_MARGIN = 0.1
#: roi.turn_search: an early search (Estimator._searches_early) that refused a body nearly lying again lets the next
#: weak pair search too when the body lies at least this many degrees nearer the lying window than at the search
#: before (rolling in: at most TURN_NEAR_LIE_DEG / this many such searches in a row; one that stays, none). Lying down
#: at 3 degrees a pair, the pair after a failed search is still short of the window (docs/turn-search.md, "A body
#: nearly lying").
_NEAR_LIE_STEP_DEG = 2.0
#: roi.turn_search: a weak cold pair searches only when one view's ``presence.min_joints``-th strongest joint peak
#: (:func:`~ghnerf_runtime.flip_test.presence_peak` of that view) reaches this: upright crops of people lying or
#: upside down reached 0.16-0.7 in a one-off look at four bench scenes, textured empty rooms stay at or under 0.022
#: (both views together, 100 rooms: benchmarks/measure_presence.py --rooms 100 --flip-test; with --time
#: --turn-search it counts the empty-room pairs that still search: none of 88).
_TURN_SEARCH_FLOOR = 0.1


def _view_score(heat: np.ndarray) -> np.ndarray:
    """Per view of ``(2, J, h, w)`` heatmaps, the median over the joints of each joint's map maximum (clipped to
    0..1; a non-finite map counts 0): how much of a body the view's crop shows strongly, a few phantom peaks
    aside. What ``roi.turn_search`` compares the turns with."""
    maps = np.asarray(heat, np.float64).reshape(heat.shape[0], heat.shape[1], -1)
    peaks = np.where(np.isfinite(maps).all(-1), np.clip(maps.max(-1), 0.0, 1.0), 0.0)
    return np.median(peaks, axis=1)


def _median_confidence(j3: Joints3D) -> float:
    """The median confidence of ``j3``'s found joints (0 with none)."""
    return float(np.median(j3.confidence[j3.valid])) if j3.valid.any() else 0.0


def _finds_better(q: "_Pass", p: "_Pass") -> bool:
    """Whether ``q``, a pass through other crop turns (:meth:`Estimator._turn_search`, :meth:`Estimator._turn_check`),
    is kept over ``p``: it finds someone where ``p`` did not, or at a median joint confidence :data:`_TURN_MARGIN`
    higher."""
    return q.j3 is not None and q.someone and (
        not p.someone or _median_confidence(q.j3) >= _median_confidence(p.j3) + _TURN_MARGIN)


def _is_image_sequence(images: object) -> bool:
    """Whether ``images`` holds the pair's images in order: a list, tuple or array (of one dimension or more: a
    0-d array has no length), not text or a mapping."""
    if isinstance(images, np.ndarray):
        return images.ndim > 0
    return isinstance(images, abc.Sequence) and not isinstance(images, (str, bytes))


def _as_array_or_none(image: object) -> np.ndarray | None:
    """``np.asarray(image)``, or None where numpy cannot make one array of it (nested lists of unequal lengths)."""
    try:
        return np.asarray(image)
    except ValueError:
        return None


class Estimator:
    """Frame pair -> joints, with an injected :class:`~ghnerf_runtime.session.ModelSession`.

    Args:
        session: loaded model (must hold ``config.required_graphs()``); any object with the
            same ``contract`` / ``run`` / ``has`` interface works.
        rig: the calibrated rig; its first two cameras are the sources, in the pair's order.
        config: the estimator configuration (its ``session`` part is not used here).
        log_settings: log, at info, how the settings were resolved against the model where that is not what they
            say (a ``roi.pad_fill`` not the model's own; ``single_view_fallback`` turned off by the prior). The
            daemon passes False for the rig's estimator: its settings check, built on the same config, said it.

    Raises:
        ModelError: the session lacks a graph the configuration needs.
        ConfigError: a novel-view stride does not divide the model's resolution.
        GeometryError: the rig's two cameras stand at one point (no baseline to triangulate over).
    """

    def __init__(self, session: Any, rig: Rig, config: EstimatorConfig | None = None, *,
                 log_settings: bool = True) -> None:
        if problem := rig.baseline_problem():  # a rig file says so on load; a camera's own readback may not
            raise GeometryError(f"rig {rig.rig_id!r}: {problem}")
        config = config or EstimatorConfig()
        self.config = config.beside_prior(getattr(session, "skeleton_prior", None) is not None)
        if self.config is not config and log_settings:
            log.info("joints3d.single_view_fallback is off: the skeleton prior places the joints it would")
        # an unset roi.pad_fill pads the crops as the model's training crops were (its contract says how); an unset
        # roi.turn_search searches where the model has the encoder heatmaps that score the turns
        padding = getattr(session.contract, "frame_padding", "none")
        self.config = self.config.beside_model(padding, getattr(session.contract, "encoder_heatmaps", False))
        learnt = RoiConfig.model_fill(padding)
        if self.config.roi.pad_fill != learnt and log_settings:
            log.info("roi.pad_fill %r as configured; the model's own would be %r (trained with frame padding %r)",
                     self.config.roi.pad_fill, learnt, padding)
        self.session = session
        self.rig = rig
        self.contract = session.contract
        # The keypoint-only graph when the session has it (a model of contract >= 1.2.0).
        self._human_graph = self.config.uses_human_graph(session.has("human"))
        missing = [g for g in self.config.required_graphs(self._human_graph) if not session.has(g)]
        if missing:
            raise ModelError(f"the session lacks graph(s) {missing} that this configuration needs "
                             f"(loaded: {list(getattr(session, 'graphs', []))})")
        if self.contract.height != self.contract.width:
            raise ModelError(f"the runtime crops square inputs; the model is {self.contract.width}x"
                             f"{self.contract.height}")
        self.size = self.contract.height
        if self.config.novel_view.enabled:  # said at load, not by the first novel view
            check_strides(self.config.novel_view, self.size)
        self.grid = self.size // self.contract.heatmap_stride
        if self.config.heatmaps.source == "encoder":
            if not getattr(self.contract, "encoder_heatmaps", False):
                raise ModelError("heatmaps.source = 'encoder' needs a model exported with encoder heatmaps (the human "
                                 "encoder's auxiliary head; contract key ghnerf.encoder_heatmaps); this one has none: "
                                 "use heatmaps.source = 'rendered'")
            if self.contract.strides.get("human_feat") != self.contract.heatmap_stride:
                raise ModelError(f"encoder heatmaps at stride {self.contract.strides.get('human_feat')} do not match "
                                 f"the heatmap grid's stride {self.contract.heatmap_stride}")
        if self.config.presence.scan_every_s > 0 and not getattr(self.contract, "encoder_heatmaps", False):
            # said at load: the scan reads these maps of the working volume's crops
            raise ModelError(f"presence.scan_every_s = {self.config.presence.scan_every_s} reads the encoder "
                             "heatmaps of the working volume's crops (contract key ghnerf.encoder_heatmaps); this "
                             "model has none: set presence.scan_every_s = 0")
        if self.config.roi.turn_search and not getattr(self.contract, "encoder_heatmaps", False):
            # said at load: the search scores each turn by these maps, and a weak pair found them missing
            raise ModelError("roi.turn_search scores the turned crops by the encoder heatmaps (the human encoder's "
                             "auxiliary head; contract key ghnerf.encoder_heatmaps); this model has none: set "
                             "roi.turn_search = false")
        self.skeleton_prior = self._prior_of(session)
        self.novel_painter = self._painter_of(session)
        # the flip test's two human-graph runs side by side on tracked pairs (heatmaps.flip_test_side_by_side)
        self._flip_lanes = (self._human_graph and self.config.flips_encoder_heatmaps
                            and self.config.heatmaps.flip_test_side_by_side and hasattr(session, "open_lane")
                            and session.open_lane("human"))
        # a tracked pair's novel view renders in the worker on one-thread sessions (novel_view.overlap), and the
        # flip test's run beside it on one thread too: two threads on two cores, not four
        nv_cfg = self.config.novel_view
        self._novel_lanes = (nv_cfg.enabled and nv_cfg.overlap and nv_cfg.lanes and hasattr(session, "open_lane")
                             and all(session.open_lane(g) for g in ("volume", "render" if nv_cfg.heatmaps else
                                                                    "render_rgb"))
                             and (not (self._human_graph and self.config.flips_encoder_heatmaps)
                                  or session.open_lane("human")))
        self._prior_follow: Joints3D | None = None
        self._prior_check: tuple[float | None, bool] = (None, False)  # this pair's (disagreement, fell back)
        self._agreement: ViewAgreement | None = None  # this pair's, set by _joints_3d
        self._lowest_foot: float | None = None  # this pair's, set by _joints_3d
        self._handedness: float | None = None  # this pair's, set by _joints_3d
        self._crop_terms: _CropTerms | None = None  # the last crop cameras' (_crop_terms_for)
        self._torso_mixed = False  # this pass's, set by _joints_3d (_finish_pass)
        # and its torso limbs' excess over one body's, as measured and as mixed_torso reads it (benchmarks)
        self._torso_excess = np.full((2, len(TORSO_LIMBS_M)), np.nan)
        _warn_if_not_levelled(rig)
        self._cams = [_CameraState(c, self._upright_roll(c)) for c in rig.pair]
        # the two cameras' centres, (2, 3): the lines of sight of the turn rules and the torso rule's depth (a crop's
        # turn or roll changes no camera's centre)
        self._centres = np.stack([c.center for c in rig.pair]).astype(np.float64)
        self.tracker = SubjectTracker(rig, self.config.tracking, self.config.roi,
                                      (self._cams[0].roll_deg, self._cams[1].roll_deg))
        self._build_cold_crops()
        # and their crop cameras' terms, which every cold pass solves in (_crop_terms_for)
        self._volume_terms = _CropTerms.of(np.stack([np.asarray(st.cold[roi, st.turn_deg][1].P, np.float64)
                                                     for st, roi in zip(self._cams, self.tracker.volume_regions.rois)]),
                                           self.skeleton_prior is not None)
        # tracking.cold_tiles_below_share: the working volume's tiles (none where its whole crop frames a person well
        # enough), one searched per cold pair that finds nobody: where its faint peaks meet, else in turn
        self._cold_tiles = self._tiles_for_small_people(rig)
        self._next_tile = 0
        self._tiles_tried: frozenset[int] = frozenset()  # the tiles the current round searched and found nobody in
        self._tiles_missed = 0  # tile passes in a row that found nobody (a whole round of them: the search rests)
        self._tile_rest_wait = 0  # cold pairs left that do not search a tile (tracking.cold_tiles_rest_every)
        # each camera's scene copy at the last tile pass that found nobody (tracking.cold_tiles_wake_levels)
        self._rest_scene: tuple[SceneCopy, ...] | None = None
        # the cells that woke the search now awake, per camera, until a pair reports a joint or its round ends
        self._woke_on: tuple[np.ndarray, ...] | None = None
        # the camera that alone saw a person on the last pairs, and on how many in a row (ONE_VIEW_NOT_VAIN_PAIRS)
        self._one_view_run: tuple[str | None, int] = (None, 0)
        # per camera, each cell's wakes whose round of tiles then found nobody (a screen, a curtain: a restless cell)
        self._vain_wakes: tuple[np.ndarray, ...] | None = None
        # per camera, each cell's tile passes unchanged in a row
        self._still_passes: tuple[np.ndarray, ...] | None = None
        self.cold_tile_passes = 0  # cold pairs that searched a tile, and those whose tile found someone
        self.cold_tiles_found = 0
        self.tile_finds_floating = 0  # tile finds refused for feet far above the floor (cold_tiles_max_foot_m)
        self._tile_floor_y = _tile_find_floor_y(rig)  # the floor that refusal reads
        self._tile_find_foot: float | None = None  # the last pair's tile find's foot as judged (tile_find_foot_m)
        self.cold_tile_wakes = 0  # resting searches a scene change woke (tracking.cold_tiles_wake_levels)
        # roi.turn_search: each camera's crop turn (degrees on top of roi.upright's) and, per turn, the camera
        # state (its own remap tables) and per pair of turns a tracker (volume crops sized for that turn)
        self._turns: tuple[int, int] = (0, 0)
        self._turned_cams: dict[tuple[int, int], _CameraState] = {(i, 0): st for i, st in enumerate(self._cams)}
        self._turned_trackers: dict[tuple[int, int], SubjectTracker] = {(0, 0): self.tracker}
        self.turn_searches = 0  # weak passes that searched the turns, and those whose turned pass was kept
        self.turns_kept = 0
        # turned passes that lay as no turn rights: a search's that found someone better than upright
        # (lies_as_turned), and a kept turn's passes of someone found (lies_as_kept_turn, _turn_misreads)
        self.turns_refused = 0
        self._turn_search_wait = 0  # weak pairs left that do not search (roi.turn_search_every)
        # whether the upright pass the last search that kept no turn was run after found someone (_searches_early)
        self._failed_search_found = False
        # how far short of lying the body lay that the last search that kept no turn refused (degrees_short_of_lying;
        # None: none such) while it may still make the next weak pair search (_searches_early)
        self._failed_search_short: float | None = None
        self._search_refused_short: float | None = None  # the same, of the search now running
        self.turn_checks = 0  # tracked passes through a kept turn run again upright, and those that left the turn
        self.turns_left = 0
        self._turn_check_wait = 0  # strong tracked turned pairs left before the next check (_turn_check)
        # the body axis of the last pair's pass kept through a turn, None if it kept none (_kept_turn_axis)
        self._kept_axis: np.ndarray | None = None
        # smooths what is reported; the tracker follows the raw joints
        self._smoother = OneEuroJoints(self.config.smoothing) if self.config.smoothing.enabled else None
        self._levels = _levels_per_unit(self.contract.normalisation)
        self._volume_box = np.stack([rig.volume.min_corner, rig.volume.max_corner])
        # two people in view: the flag and the subject's joints and figures, through this estimator's box gates and
        # floor check (the subject's pairings pass them as one person's joints do)
        self.subject_selector = SubjectSelector(self.config, rig, self.grid, self.size, self._gate_to_boxes,
                                                self._lowest_foot_m, _FLOOR_BODY_M)
        self._sequence = 0
        self._last_timestamp_s: float | None = None
        self._after_gap = False  # this pair came over tracking.max_gap_s after the last, or before it
        self._last_pair_cold = False
        self._scan_clock = ScanClock(self.config.presence.scan_every_s)  # presence.scan_every_s
        self._someone_else: bool | None = None  # the latest scan's answer while this track lasts
        # the track is a several_people pass's subject (SubjectSelector.several_people's hysteresis)
        self._several_track = False
        self._behind_track: int | None = None  # and the view that showed one peak, where that pass was behind_view's
        # the track is a cold pass's that was not several_people but showed a joint twice, or a torso of two people
        # (two_people.mixed_torso): two people in its crop (the working volume's, too coarse to tell them apart) may
        # have left both people's joints mixed in it (SubjectSelector.keep_tracked_subject)
        self._track_unsorted = False
        # the whole-volume verdict of a rejected crop on the rays, reused pair after pair
        # (frame_check.volume_recheck_every)
        self._volume_verdict: VolumeVerdict | None = None
        self._pair_on_rays = False  # a pass of the last (or this) pair had a crop on the rays (_verdict_for_pair)
        self.volume_rechecks = 0  # whole-volume crops preprocessed for a rejected crop on the rays
        self._rays_cache: dict[tuple, np.ndarray] = {}
        self._grid_points: dict[tuple, tuple[np.ndarray, tuple[int, int, int]]] = {}
        self._between: dict[tuple, Camera] = {}  # (alpha, pivot) -> interpolated camera (the rig does not move)
        self._between_pair: tuple[Camera, Camera] | None = None  # the cameras a view between them turns with
        self._worker: ThreadPoolExecutor | None = None  # novel views during the keypoint stages
        # 2D joints of the good camera when the other's frame fails the check (needs encoder heatmaps)
        self._single_view_2d = self.config.frame_check.single_view_2d and bool(
            getattr(self.contract, "encoder_heatmaps", False))
        # where the flip test's skip looks for someone: the pair, and each view alone when a person seen by one
        # camera only is reported (its view gets the mirrored run as a rejected frame's other view does)
        self._presence_views = ((0, 1), (0,), (1,)) if self._single_view_2d else ((0, 1),)

    def _upright_roll(self, camera: Camera) -> float:
        """The rotation that shows ``camera``'s crops upright (``roi.upright``; 0 when off), said in the log."""
        roll = upright_roll_deg(camera)
        if abs(roll) > _NOTED_ROLL_DEG:
            if self.config.roi.upright:
                log.info("camera %r is mounted rolled %.1f degrees from upright: its crops are rotated upright",
                         camera.name, -roll)
            else:
                log.warning("camera %r is mounted rolled %.1f degrees from upright and roi.upright is off: the model "
                            "was trained on upright views, so expect fewer and worse joints", camera.name, -roll)
        return roll if self.config.roi.upright else 0.0

    def _prior_of(self, session: Any):
        """The session's skeleton prior when the configuration uses it (``joints3d.skeleton_prior``)."""
        cfg = self.config.joints3d
        prior = getattr(session, "skeleton_prior", None)
        if cfg.skeleton_prior == "on" and prior is None:
            raise ModelError("joints3d.skeleton_prior = 'on' but the session has no skeleton prior (the model folder "
                             "has no skeleton_prior.onnx; make one with python -m training.skeleton_prior, or set "
                             "joints3d.skeleton_prior = 'auto' or 'off')")
        return prior if cfg.uses_skeleton_prior(prior is not None) else None

    def _painter_of(self, session: Any):
        """The session's novel-view painter when the configuration uses it (``novel_view.painter``)."""
        cfg = self.config.novel_view
        painter = getattr(session, "novel_painter", None)
        if cfg.enabled and cfg.painter == "on" and painter is None:
            raise ModelError("novel_view.painter = 'on' but the session has no painter (the model folder has no "
                             "novel_painter.onnx; make one with python -m training.learnt_fill export, or set "
                             "novel_view.painter = 'auto' or 'off')")
        return painter if cfg.uses_painter(painter is not None) else None

    @classmethod
    def from_config(cls, rig: Rig, config: EstimatorConfig | None = None) -> "Estimator":
        """Load the model named by ``config.session`` (only the graphs needed) and build the estimator."""
        config = config or EstimatorConfig()
        return cls(load_session(config), rig, config)

    @property
    def tile_find_foot_m(self) -> float | None:
        """The lower foot (m) of the last pair's cold tile find, refined on its subject, above the floor that the
        refusal of floating feet reads (y = 0, or the working volume's floor-side bound where that lies higher): what
        the refusal judged, the find kept or refused (``tile_finds_floating``). None where the last pair found no one
        by a tile or the find gave no foot figure. Not ``PairResult.lowest_foot_m``: a refused find's pair answers
        nobody, with no foot (``benchmarks/measure_baseline.py --tile-finds`` prints this)."""
        return self._tile_find_foot

    @property
    def camera_names(self) -> tuple[str, str]:
        return self._cams[0].camera.name, self._cams[1].camera.name

    def reset(self) -> None:
        """Forget the tracked subject (the next pair starts from the working volume, through upright crops: a kept
        crop turn goes with the track, ``roi.turn_search``), the smoothing and the cold tiles' rest and round (the next
        cold pair that finds nobody searches a tile: its faint peaks', else the first). The counters are statistics
        over the estimator's life and stay: ``cold_tile_passes``, ``cold_tiles_found``, ``tile_finds_floating``,
        ``cold_tile_wakes``, ``turn_searches``, ``turns_kept``, ``turns_refused``, ``turn_checks``, ``turns_left``
        and ``volume_rechecks``."""
        self.tracker.reset()  # the kept turn's tracker (the upright one is reset as the crops return upright)
        self._use_turns((0, 0))
        self._several_track = False
        self._behind_track = None
        self._track_unsorted = False
        self._volume_verdict = None
        self._turn_search_wait = 0
        self._failed_search_found = False
        self._failed_search_short = None
        self._turn_check_wait = 0
        self._kept_axis = None
        self._crop_terms = None
        self._next_tile = 0
        self._wake_tiles()
        self._woke_on = None  # (a wake outlives _wake_tiles: a reset judges none)
        self._one_view_run = (None, 0)
        self._vain_wakes = None  # the scene may be another now (a camera moved): its restless cells with it
        self._still_passes = None
        self._forget_scan()
        if self._smoother is not None:
            self._smoother.reset()

    def close(self) -> None:
        """Stop the novel-view worker thread, if one was started (an estimator left to the garbage
        collector stops it too)."""
        if self._worker is not None:
            self._worker.shutdown(wait=True)
            self._worker = None

    def __enter__(self) -> "Estimator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -------------------------------------------------------------- helpers
    def _crop(self, state: _CameraState, roi: Roi) -> tuple[CropMaps, Camera]:
        """Remap tables and the pinhole crop camera of one window: the working volume's built with the estimator
        (:meth:`_build_cold_crops`), the others on their first use and kept in the camera's LRU."""
        key = (roi, state.turn_deg)
        entry = state.cold.get(key)
        if entry is not None:
            return entry
        entry = state.cache.get(key)
        if entry is None:
            entry = self._build_crop(state, roi)
            state.cache[key] = entry
            while len(state.cache) > self.config.roi.map_cache_size:
                state.cache.popitem(last=False)
        else:
            state.cache.move_to_end(key)
        return entry

    def _build_crop(self, state: _CameraState, roi: Roi) -> tuple[CropMaps, Camera]:
        """Build one window's remap tables and pinhole crop camera (both cost ~0.7 ms for a lens without
        distortion, ~3 ms for the example rig's: session 62, 128 px crops)."""
        maps = build_undistort_crop_maps(state.camera, roi, self.size, roll_deg=state.crop_roll_deg,
                                         supersample=self.config.roi.supersample, pad_fill=self.config.roi.pad_fill,
                                         pad_fade=self.config.roi.pad_fade).compact()
        return maps, crop_camera(state.camera, roi, self.size, state.crop_roll_deg)

    def _build_cold_crops(self) -> None:
        """The working volume's window in each camera, built now rather than by the first pair (a device builds its
        estimator before its first frame): the same tables for every cold pair of this rig and configuration, about
        2 ms of the estimator's build on session 68's host (``ghnerf-bench runtime``'s startup line)."""
        for state, roi in zip(self._cams, self.tracker.volume_regions.rois):
            state.cold[roi, state.turn_deg] = self._build_crop(state, roi)

    def _ray_uv(self, blocks: tuple, stride: int) -> np.ndarray:
        """``(2, R, 2)`` rays of the two views' blocks (cached: blocks recur while tracking)."""
        rays = self._rays_cache.get(blocks)
        if rays is None:
            rays = np.stack([block_ray_uv(b, stride) for b in blocks])
            if len(self._rays_cache) > 256:
                self._rays_cache.clear()
            self._rays_cache[blocks] = rays
        return rays

    def _crop_terms_for(self, crops: Sequence[Camera]) -> _CropTerms:
        """The two crop cameras' terms: the working volume's, built with the estimator, or the last ones while the
        crops' matrices are the same (compared by value: a crop window's camera is rebuilt when the window returns
        after leaving the map cache), else new ones."""
        P = np.stack([np.asarray(c.P, np.float64) for c in crops])
        if self._volume_terms.two_view.is_for(P):
            return self._volume_terms
        if self._crop_terms is None or not self._crop_terms.two_view.is_for(P):
            self._crop_terms = _CropTerms.of(P, self.skeleton_prior is not None)
        return self._crop_terms

    def _check_images(self, images: Sequence[np.ndarray]) -> None:
        if not _is_image_sequence(images):  # a dict gave its keys' "<U4 ()"; None or a generator a TypeError
            raise FrameError(f"expected 2 images in the rig's camera order {list(self.camera_names)} (a list, "
                             f"tuple or array), got {type(images).__name__}")
        if len(images) != 2:
            raise FrameError(f"expected 2 images (cameras {list(self.camera_names)}), got {len(images)}")
        for img, st in zip(images, self._cams):
            arr = _as_array_or_none(img)
            w, h = st.camera.size
            if arr is None:  # ragged nested lists: numpy's ValueError named no camera
                raise FrameError(f"camera {st.camera.name!r}: expected a ({h}, {w}, 3) uint8 BGR image (the rig "
                                 f"file's {w}x{h}), got a {type(img).__name__} that is no array (ragged)")
            if arr.dtype != np.uint8 or arr.shape != (h, w, 3):
                # (a missing frame read "got object ()"; a camera reconfigured to another size names both sizes)
                got = "None (no frame)" if img is None else f"{arr.dtype} {arr.shape}"
                raise FrameError(f"camera {st.camera.name!r}: expected a ({h}, {w}, 3) uint8 BGR image (the rig "
                                 f"file's {w}x{h}), got {got}")

    def _empty_result(self, sequence: int, regions: Regions, frame_reason: dict, timing: dict) -> PairResult:
        J = len(JOINT_NAMES)
        names = self.camera_names
        return PairResult(sequence, JOINT_NAMES, np.zeros((J, 3)), np.zeros(J, np.float32), np.ones(J, bool),
                          {n: np.zeros((J, 2)) for n in names}, {n: np.zeros(J, np.float32) for n in names},
                          {n: np.ones(J, bool) for n in names}, timing, regions.tracked,
                          {n: why is None for n, why in frame_reason.items()}, dict(zip(names, regions.rois)),
                          self.config.joints3d.method, frame_reason=dict(frame_reason))

    # -------------------------------------------------------------- main
    def estimate(self, images: Sequence[np.ndarray], *, sequence: int | None = None,
                 novel_view: NovelViewRequest | None = None, timestamp_s: float | None = None) -> PairResult:
        """Joints of one synchronised pair.

        Args:
            images: the two BGR uint8 frames, in the rig's camera order, at the cameras' sizes.
            sequence: the pair's number (default: a running count).
            timestamp_s: the pair's capture time, seconds (any origin), for ``smoothing``. Without one
                the pair's joints are reported unsmoothed and the filter restarts: the host's clock would
                count processing jitter as motion, so a caller that wants smoothing passes the time.
            novel_view: render a novel view too (needs ``novel_view.enabled`` in the config). A
                pair whose frames fail the frame check, or that the presence gate says shows nobody,
                has none (``PairResult.novel_view`` is ``None``): nothing is rendered.

        Raises:
            FrameError: an image has the wrong size or type for its camera; ``timestamp_s`` is not a finite number.
            ModelError: a novel view was requested but not enabled; a graph failed.
            A call refused for its arguments leaves the estimator as it was (the running count too).
        """
        result, finish = self.estimate_then_view(images, sequence=sequence, novel_view=novel_view,
                                                 timestamp_s=timestamp_s)
        return result if finish is None else finish()

    def estimate_then_view(self, images: Sequence[np.ndarray], *, sequence: int | None = None,
                           novel_view: NovelViewRequest | None = None, timestamp_s: float | None = None
                           ) -> tuple[PairResult, Callable[[], PairResult] | None]:
        """:meth:`estimate` in two steps: the pair's joints now, and the novel view later.

        Returns the pair's result without its novel view and, when one was requested and the pair has one,
        a function that finishes the view (waits for its rendering, recolours and mattes it, draws the
        overlay) and returns the whole result, the one :meth:`estimate` returns. Every state the next pair
        reads (the track, the smoothing) is updated before this returns: the function reads only this pair's
        own data, so it may run in another thread while the next pair is estimated
        (:class:`~ghnerf_runtime.pipeline.NovelViewPipeline`), one such function at a time. Its ``total``
        runs from this call to the view's end. Arguments and errors as :meth:`estimate`'s.
        """
        t_start = time.perf_counter()
        sequence = self._sequence if sequence is None else _whole_sequence(sequence)
        self._check_images(images)
        if timestamp_s is not None and not _finite_time(timestamp_s):
            # NaN compares false with every time: the track and the smoothing would restart on this pair and the next
            raise FrameError(f"timestamp_s must be a finite capture time (seconds), got {timestamp_s!r}")
        if timestamp_s is not None and _time_step_s(timestamp_s) > MAX_TIME_STEP_S:
            raise FrameError(f"timestamp_s {timestamp_s!r} ({np.asarray(timestamp_s).dtype}) is held in steps of "
                             f"{_time_step_s(timestamp_s):.3g} s at that value, coarser than {MAX_TIME_STEP_S:g} s "
                             "(MAX_TIME_STEP_S): pairs would share one time; give seconds as a float64 (a Python "
                             "float), from a nearer origin")
        if novel_view is not None and not self.config.novel_view.enabled:
            raise ModelError("a novel view was requested but novel_view.enabled is false (the colour graph is "
                             "not loaded)")
        if novel_view is not None and novel_view.overlay == "heatmap" and not self.config.novel_view.heatmaps:
            raise ModelError("overlay='heatmap' needs novel_view.heatmaps = true (the 'render' graph)")
        self._sequence = sequence + 1  # after the checks: a refused call leaves the running count as it was
        self._tile_find_foot = None
        timing: dict[str, float] = {}
        self._forget_a_stale_track(timestamp_s)
        self._verdict_for_pair()
        # the kept turn this pair may lose, and the last pass kept through it (_turn_lost_flipped)
        rolled_from = (self._turns, self._kept_axis) if self._turns != (0, 0) and self._kept_axis is not None else None
        if self.tracker.track is None and self.tracker.view_track is None:
            self._use_turns((0, 0))  # a turned track was lost: a cold pass looks upright first (and searches again)
        p = self._pass(images, self.tracker.regions(), sequence, timing, novel_view)
        if self._lost_on_a_tracked_pass(p):
            # The tracked crop found nobody: the subject may have left it. Look at the working volume now.
            if p.novel is not None:
                p.novel.abandon()
            self._use_turns((0, 0))
            # a tracked pass that showed two people and reported nobody of them: the working volume's crop shows the
            # same two, maybe too small to tell apart, and its joints would be both people's mixed
            p = self._pass(images, self.tracker.regions(), sequence, timing, novel_view,
                           cold_several=True if p.several_people else None)
        elif p.regions.tracked and self._turns != (0, 0) and self._turn_misreads(p):
            self.turns_refused += 1
            # A tracked pass through a kept turn whose body lies as the turn does not right (lies_as_kept_turn: the
            # person rolled onto a line of sight): the search would not keep it, nor is it kept here, nor is its
            # track, which the crops would follow. The pair is read as after a lost track: cold, upright first, then
            # searched when weak (the upright pass on this track's crops read a skeleton about 1 m off, tracked, in
            # bench scene 10).
            if p.novel is not None:
                p.novel.abandon()
            self._use_turns((0, 0))
            p = self._pass(images, self.tracker.regions(), sequence, timing, novel_view)
        cold_pass = not p.regions.tracked  # (the refined pass below is tracked: the subject was found cold)
        turns_read = self._turns  # the crops' turns this pair's tracked pass read (a change resets the smoothing)
        p = self._refined(images, p, sequence, timing, novel_view)
        if cold_pass and self._turns == (0, 0) and self._cold_tiles:
            if not self._finds_nobody(p):
                if self._sees_anyone(p):
                    self._wake_tiles()
            else:
                # the pair's scene copies, built once where both the wake check and a missed tile pass read them
                copies = functools.cache(lambda: pair_copies(images))
                if self._tiles_awake(images, copies):
                    p = self._tile_search(images, p, sequence, timing, novel_view, copies)
        leave_turn = cold_pass and self._turns != (0, 0) and self._weak_pass(p)
        if cold_pass and self._turns != (0, 0) and not leave_turn and self._turn_misreads(p):
            self.turns_refused += 1
            leave_turn = True
        if leave_turn:
            # A cold pass through a kept turn's crops (a single-view track keeps the turn) that is weak: the subject
            # may have got up. Upright first, as after a lost track: the search below scores its turns against the
            # upright crops, and took these for them (a standing person kept through upside-down crops). So too
            # when its body lies as no turn rights (the person rolled onto a line of sight): not kept over upright.
            if p.novel is not None:
                p.novel.abandon()
            self._use_turns((0, 0))
            p = self._refined(images, self._pass(images, self.tracker.regions(), sequence, timing, novel_view),
                              sequence, timing, novel_view)
        if not (cold_pass and self._turns == (0, 0) and rolled_from is not None
                and self._turn_lost_flipped(p, *rolled_from)):
            rolled_from = None  # the pair kept its turn, or its upright pass does not read the body turned over
        if cold_pass and (self._weak_pass(p) or rolled_from is not None):
            # A cold pair that found nobody, or someone weakly (refined or not): someone lying or upside down? Or
            # strongly, turned over against the turn this pair lost (_turn_lost_flipped).
            if self._turn_search_wait > 0 and not self._searches_early(p):
                self._turn_search_wait -= 1  # a search found no turn lately: someone no turn rights, most likely
            else:
                turned = self._turn_search(images, p, sequence, timing, novel_view, rolled_from=rolled_from)
                if turned is not p:
                    self._end_wait()
                    p = self._refined(images, turned, sequence, timing, novel_view)
                else:
                    self._wait_after_search(p)
        elif not cold_pass and self._turns != (0, 0):
            # tracked through a kept turn: the person may have got up (_turn_check)
            p = self._turn_check(images, p, sequence, timing, novel_view)
        elif not cold_pass and self._weak_pass(p) and self.tracker.track is not None:
            # tracked upright and weak: the person may have lain down or be upside down, read as someone standing
            # (a strong pass, the usual tracked pair, pays nothing); the turns are tried on the track's crops
            if self._turn_search_wait > 0 and not self._searches_early(p):
                self._turn_search_wait -= 1
            else:
                turned = self._turn_search(images, p, sequence, timing, novel_view, self.tracker.track)
                if turned is p:
                    self._wait_after_search(p)
                else:
                    self._end_wait()
                p = turned
        elif p.someone:
            self._end_wait()  # someone found well: the next weak pair searches at once
        stays = self._stays_in_one_view(p)  # (read on every pair: the run of one-view pairs)
        if self._sees_in_3d(p) or stays:
            self._woke_on = None  # someone found: the wake awake, if any, was not in vain
        self._kept_axis = self._kept_turn_axis(p)
        if p.j3 is None:
            self._forget_scan()
            if self._smoother is not None:
                self._smoother.reset()
            timing["total"] = 1e3 * (time.perf_counter() - t_start)
            return self._empty_result(sequence, p.regions, p.frame_reason, timing), None
        points = p.j3.points
        if self._smoother is not None:
            if timestamp_s is None:
                self._smoother.reset()  # no time to filter on: a still image, as far as smoothing goes
            else:
                if p.regions.tracked and self._last_pair_cold:
                    # The pair before was cold (cropped from the whole working volume): crude. The filter starts
                    # again on this first tracked pair rather than pulling it back there. (Without tracking
                    # every pair is cold, and smoothing runs on them all.)
                    self._smoother.reset()
                elif cold_pass and not self._last_pair_cold:
                    # The track was lost since the last reported pair (retry_cold: the subject left the tracked
                    # crop): whoever the working volume shows now (refined or not) is not pulled toward where the
                    # track was.
                    self._smoother.reset()
                elif self._turns != turns_read:
                    # a tracked pair whose crops turned (_turn_check, a tracked search): the pairs before were read
                    # through the other turn (a standing person upside down, 1.2 m off), not to be pulled toward
                    self._smoother.reset()
                points = self._smoother(float(timestamp_s), p.j3.points, p.j3.valid)  # missing joints stay 0
        self._last_pair_cold = not p.regions.tracked
        self._scan_for_others(images, p, timestamp_s, timing, cold_pass)
        timing["total"] = 1e3 * (time.perf_counter() - t_start)
        names = self.camera_names
        result = PairResult(sequence, JOINT_NAMES, points, p.j3.confidence, ~p.j3.valid, p.joints_2d, p.conf_2d,
                            p.missing_2d, timing, p.regions.tracked, p.frame_ok, dict(zip(names, p.regions.rois)),
                            self.config.joints3d.method, frame_reason=dict(p.frame_reason),
                            prior_disagreement_m=p.prior_disagreement_m, prior_fallback=p.prior_fallback,
                            several_people=p.several_people,
                            single_view=p.single_view, reprojection_px_median=p.reprojection_px_median,
                            lowest_foot_m=p.lowest_foot_m, someone_else=self._someone_else,
                            handedness=p.handedness)
        if novel_view is None or not all(p.frame_ok.values()) or not p.someone:
            # A single-view pair has no novel view, nor has a pair that found nobody: there is no subject to
            # view, and rendering the working volume's box for nothing was the dearest part of an empty room.
            if p.novel is not None:  # (a tracked pass that lost the subject started one in the worker)
                p.novel.abandon()
            return result, None

        def finish() -> PairResult:
            view_timing = dict(timing)
            nv = self._finish_novel(novel_view, p, view_timing)
            view_timing["total"] = 1e3 * (time.perf_counter() - t_start)
            return replace(result, timing_ms=view_timing, novel_view=nv)

        return result, finish

    def _finish_novel(self, request: NovelViewRequest, p: "_Pass", timing: dict) -> NovelView:
        """The pair's novel view: rendered in the worker (a tracked pair) or here, then repainted, recoloured and
        matted over the body proxy of its joints, with the requested overlay."""
        cfg = self.config.novel_view
        over_proxy = self.novel_painter is not None or cfg.proxy_blend or cfg.matte
        if p.novel is not None:  # rendering in the worker, on the tracked box
            # the proxy's depth maps need the joints and the view's camera, not its picture: cast them meanwhile
            inputs = self._proxy_inputs(p, p.novel.camera) if over_proxy else None
            nv, novel_timing = p.novel.future.result()
            timing.update(novel_timing)
        else:
            self._add_features(p.env, timing)
            nv = self._render_novel(request, p.env, self._novel_box(p.regions, p.j3), timing)
            inputs = self._proxy_inputs(p, nv.camera) if over_proxy else None
        if inputs is not None:
            nv = self._over_proxy(nv, p, timing, inputs)
        return self._compose_novel(request, nv, p.j3, timing)

    # -------------------------------------------------------------- turned crops (roi.turn_search)
    def _use_turns(self, turns: tuple[int, int], fresh: bool = True) -> None:
        """Crop camera ``i`` turned ``turns[i]`` degrees (counterclockwise) more than ``roi.upright`` does, with a
        tracker of those turns, reset (a track's crops are sized for the turn it was found with) unless not
        ``fresh`` (back to the tracker as the turn search found it)."""
        if turns == self._turns:
            return
        for i, turn in enumerate(turns):
            if (i, turn) not in self._turned_cams:
                st = self._turned_cams[i, 0]
                # the upright state's cache: a turn's tables count in the camera's roi.map_cache_size
                self._turned_cams[i, turn] = _CameraState(st.camera, st.roll_deg, float(turn), st.cache)
        self._cams = [self._turned_cams[i, turn] for i, turn in enumerate(turns)]
        tracker = self._turned_trackers.get(turns)
        if tracker is None:
            tracker = SubjectTracker(self.rig, self.config.tracking, self.config.roi,
                                     tuple(st.crop_roll_deg for st in self._cams))
            self._turned_trackers[turns] = tracker
        if fresh:
            tracker.reset()
            self._several_track = False
            self._track_unsorted = False
        self.tracker = tracker
        self._turns = turns

    def _forget_scan(self) -> None:
        """No track: the scan's answer was about the lost subject's surroundings, and the next track scans at once."""
        self._scan_clock.reset()
        self._someone_else = None

    def _scan_for_others(self, images: Sequence[np.ndarray], p: "_Pass", timestamp_s: float | None,
                         timing: dict, cold_pass: bool) -> None:
        """``presence.scan_every_s``: on a tracked pair whose scan is due, the keypoint graph once on the working
        volume's crops, and whether both views show someone outside the reported subject's box
        (:mod:`~ghnerf_runtime.others_scan`). Time: ``scan``. The pair's joints are not touched. A pair that began
        ``cold_pass`` (refined to a tracked one or not) starts the scan clock instead of scanning."""
        now = time.monotonic() if timestamp_s is None else float(timestamp_s)
        if cold_pass or not p.regions.tracked:
            self._forget_scan()
            self._scan_clock.cold_start(now)
            return
        if not self._scan_clock.due(now):  # (first: most tracked pairs are not due, and need no box)
            return
        box = subject_box(p.j3.points, p.j3.valid)
        if box is None:
            return
        t = time.perf_counter()
        heat, crops = self._volume_heatmaps(images)
        if heat is not None:
            stride = self.contract.heatmap_stride
            cells = [box_cells(np.asarray(c.P, np.float64), box, stride) for c in crops]
            pres = self.config.presence
            self._someone_else = someone_else(heat, cells, pres.threshold("encoder"), pres.min_joints)
        self._scan_clock.ran(now)
        _add_ms(timing, "scan", t)

    def _volume_heatmaps(self, images: Sequence[np.ndarray]) -> tuple[np.ndarray | None, list[Camera]]:
        """The encoder heatmaps ``(2, J, H, W)`` of the working volume's upright crops (the cold pass's) and their
        crop cameras; ``None`` where a crop fails the frame check (the answer stays the last scan's)."""
        batch, crops, maps = self._crop_batch(images, self.tracker.volume_regions.rois)
        if not all(check_crop(batch[i, 1], self._levels, self.config.frame_check, m.inside)[0]
                   for i, m in enumerate(maps)):
            return None, crops
        return self._crop_heatmaps(batch, crops), crops

    def _crop_batch(self, images: Sequence[np.ndarray], rois: Sequence[Roi]) \
            -> tuple[np.ndarray, list[Camera], list[CropMaps]]:
        """The preprocessed crops ``(2, 3, S, S)`` of ``rois``, their crop cameras and crop maps."""
        batch = np.empty((2, 3, self.size, self.size), np.float32)
        crops, maps_used = [], []
        for i, (img, st, roi) in enumerate(zip(images, self._cams, rois)):
            maps, crop = self._crop(st, roi)
            crops.append(crop)
            maps_used.append(maps)
            batch[i] = preprocess_image(img, maps, self.contract.normalisation)
        return batch, crops, maps_used

    def _crop_heatmaps(self, batch: np.ndarray, crops: list[Camera]) -> np.ndarray:
        """The encoder heatmaps ``(2, J, H, W)`` of ``batch``: one run of the keypoint graph (``human`` where the
        session has it), no flip test."""
        graph = "human" if self.session.has("human") else "encoder"
        feeds = {"images": batch, "src_P": source_projections(crops, self.size, self.size)}
        return self.session.run(graph, feeds)["encoder_heatmaps"]

    def _refined(self, images: Sequence[np.ndarray], p: "_Pass", sequence: int, timing: dict,
                 novel_view: NovelViewRequest | None) -> "_Pass":
        """``p``, or after a cold start that found the subject (``tracking.refine_cold_start``) the pass run again
        on its crop and box, in this pair (which two people stay: :meth:`_finish_pass`'s cold_several)."""
        if (p.j3 is not None and not p.regions.tracked and self.config.tracking.refine_cold_start
                and self.tracker.track is not None):
            return self._pass(images, self.tracker.regions(), sequence, timing, novel_view,
                              cold_several=p.several_people)
        return p

    # -------------------------------------------------------------- cold tiles (tracking.cold_tiles_below_share)
    def _tiles_for_small_people(self, rig: Rig) -> tuple[Regions, ...]:
        """The working volume's tiles (``tracking.volume_tiles``) where the whole volume's crop shows a person
        standing at its centre under ``tracking.cold_tiles_below_share`` of the crop's side tall (a volume wide and
        near the cameras, whose crop covers the image); none otherwise (then the option costs nothing) or with
        tracking off."""
        t = self.config.tracking
        if not t.enabled or t.cold_tiles_below_share <= 0:
            return ()
        if cold_person_share(rig, self.tracker.volume_regions) >= t.cold_tiles_below_share:
            return ()
        return volume_tiles(rig, self.config.roi, self.tracker.rolls)

    def _finds_nobody(self, p: "_Pass") -> bool:
        """Whether ``p`` passed both frames and found nobody, not even in one view: a tile may show someone the
        whole volume's crop drew too small (a rejected frame or a person seen by one camera is no such case)."""
        return p.j3 is not None and all(p.frame_ok.values()) and not self._sees_anyone(p)

    def _tile_search(self, images: Sequence[np.ndarray], p: "_Pass", sequence: int, timing: dict,
                     novel_view: NovelViewRequest | None, copies: Callable[[], tuple[SceneCopy, ...]]) -> "_Pass":
        """After ``p``, a cold pass that found nobody: the pass through one working-volume tile (one a pair), the one
        where ``p``'s faint peaks meet (:meth:`_tile_by_evidence`), else the next in turn that this round has not
        searched; refined on its subject when it finds someone (and then that tile is next in turn when the track is
        lost again); a person the tile shows one camera only is that pass's answer too (the tracker follows that
        view from it, and the other camera's next crop lies on the seen joints' rays: ``update_view(other_on_rays=)``);
        else ``p``, so too where the refined find's feet float (:meth:`_feet_float`: the track is dropped)."""
        k = self._tile_by_evidence(p)
        if k is None:
            k = self._next_untried_tile()
        self.cold_tile_passes += 1
        q = self._pass(images, self._cold_tiles[k], sequence, timing, novel_view)
        found = self._sees_anyone(q)
        if found:
            q = self._refined(images, q, sequence, timing, novel_view)
            self._tile_find_foot = self._above_tile_floor(q.lowest_foot_m)
            if self._feet_float(self._tile_find_foot):
                self.tile_finds_floating += 1
                self.tracker.reset()  # the next pair starts cold, as after a tile that found nobody
                if q.novel is not None:  # the refined pass is tracked: its novel view may be rendering in the worker
                    q.novel.abandon()
                found = False
        if not found:
            self._next_tile = k + 1
            self._tiles_tried = self._tiles_tried | {k}
            if len(self._tiles_tried) >= len(self._cold_tiles):
                self._tiles_tried = frozenset()  # a whole round: the next one may search any tile again
            self._tile_missed(copies)
            return p
        self.cold_tiles_found += 1
        self._next_tile = k
        self._wake_tiles()
        return q

    def _above_tile_floor(self, foot_m: float | None) -> float | None:
        """``foot_m`` (a pass's ``lowest_foot_m``, above y = 0) above the floor the tile finds' refusal reads
        (:func:`_tile_find_floor_y`); None stays None."""
        return None if foot_m is None else foot_m + self._tile_floor_y

    def _feet_float(self, foot_m: float | None) -> bool:
        """Whether a tile find's lower foot, ``foot_m`` above the refusal's floor (:meth:`_above_tile_floor`), stands
        over ``tracking.cold_tiles_max_foot_m`` (no figure, or no bound: no)."""
        bound = self.config.tracking.cold_tiles_max_foot_m
        return foot_m is not None and bound is not None and foot_m > bound

    def _next_untried_tile(self) -> int:
        """The fixed order: the next tile from ``_next_tile`` on that this round has not searched."""
        n = len(self._cold_tiles)
        return next((k % n for k in range(self._next_tile, self._next_tile + n) if k % n not in self._tiles_tried),
                    self._next_tile % n)

    def _tile_by_evidence(self, p: "_Pass") -> int | None:
        """The tile this round has not searched that holds the weak evidence of ``p``, a cold pass that found nobody
        (:meth:`_weak_evidence_point`), the one whose centre is nearest it where tiles overlap: where a person too
        small to find in the whole volume's crop may stand. None where there is no such point or no untried tile
        holds it (the fixed order then)."""
        point = self._weak_evidence_point(p)
        if point is None:
            return None
        held = [k for k, tile in enumerate(self._cold_tiles) if k not in self._tiles_tried
                and np.all(point >= tile.box[0]) and np.all(point <= tile.box[1])]
        if not held:
            return None
        return min(held, key=lambda k: float(np.linalg.norm(self._cold_tiles[k].box.mean(axis=0) - point)))

    def _weak_evidence_point(self, p: "_Pass") -> np.ndarray | None:
        """``(3,)``: the median, over the joints ``p`` decoded in both views (a peak over ``decoder.threshold``, 0.1,
        under the presence threshold in a pass that found nobody: a person too small to find may leave such peaks where
        they stand), of where the two views' rays through those peaks pass nearest each other (``triangulate_midpoint``;
        sub-cell peaks: the views' disparity at 4 m, a pixel or two of the model's input, is under a heatmap cell);
        None without such a joint, decoded peaks or a point in front of both cameras."""
        kp = p.peaks
        if kp is None or p.crops is None:
            return None
        both = np.flatnonzero(np.all(kp.valid, axis=0))
        if not len(both):
            return None
        uv = heatmap_to_model_pixels(kp.uv[:, both], self.grid, self.size)  # (2, M, 2)
        met = triangulate_midpoint(uv, p.crops)  # (rays near parallel, or meeting behind a camera: not valid)
        return np.median(met.points[met.valid], axis=0) if met.valid.any() else None

    @staticmethod
    def _sees_anyone(p: "_Pass") -> bool:
        """Whether ``p`` reported anyone: a joint, or a person's 2D joints in one view."""
        return p.single_view is not None or Estimator._sees_in_3d(p)

    @staticmethod
    def _sees_in_3d(p: "_Pass") -> bool:
        """Whether ``p`` reported a joint: someone both views saw, not a person's 2D joints in one view alone."""
        return p.j3 is not None and p.someone and bool(p.j3.valid.any())

    def _stays_in_one_view(self, p: "_Pass") -> bool:
        """Whether ``p`` is the :data:`ONE_VIEW_NOT_VAIN_PAIRS`-th pair in a row (or later) whose person one camera
        alone saw, the same camera each: a person who stays, not a screen's picture read as one now and then. Counts
        the run, so every pair is read once. A pair over ``tracking.max_gap_s`` after the last (dropped pairs, a
        stalled camera), or before it, starts a run, as it drops a track: pairs apart in time are no stay (session 72;
        before, four one-view pairs a minute apart counted in a row)."""
        name, run = self._one_view_run
        if p.single_view is None:
            self._one_view_run = (None, 0)
        else:
            goes_on = p.single_view == name and not self._after_gap
            self._one_view_run = (p.single_view, run + 1 if goes_on else 1)
        return self._one_view_run[1] >= ONE_VIEW_NOT_VAIN_PAIRS

    def _tiles_awake(self, images: Sequence[np.ndarray],
                     copies: Callable[[], tuple[SceneCopy, ...]] | None = None) -> bool:
        """Whether this cold pair that found nobody searches a tile: always, until a whole round of tiles found
        nobody; then only every ``tracking.cold_tiles_rest_every``-th such pair (an empty room stays empty), or
        this one where a camera's scene changed since the last tile pass (``tracking.cold_tiles_wake_levels``: someone
        may have walked in), which wakes the search. ``copies``: the pair's scene copies, built at most once (the
        wake check and a tile pass that then finds nobody both read them), made here where not given."""
        copies = copies or functools.cache(lambda: pair_copies(images))
        woke_on = self._cells_that_wake(copies) if self._tiles_missed >= len(self._cold_tiles) else None
        if woke_on is not None:
            self.cold_tile_wakes += 1
            self._wake_tiles()  # also on a resting search's own pair: its tile may not be the walker's
            self._woke_on = woke_on
            return True
        if self._tile_rest_wait > 0:
            self._tile_rest_wait -= 1
            return False
        return True

    def _cells_that_wake(self, copies: Callable[[], tuple[SceneCopy, ...]]) -> tuple[np.ndarray, ...] | None:
        """Each camera's changed cells where the pair (``copies()``, its scene copies) differs from the scene kept at
        the last tile pass that found nobody, leaving out the restless cells (:meth:`_restless_cells`); None where that
        is no change (never a change with ``tracking.cold_tiles_wake_levels`` 0 or None, or nothing kept)."""
        levels = self.config.tracking.cold_tiles_wake_levels
        if not levels or self._rest_scene is None:
            return None
        changed = changed_masks(copies(), self._rest_scene, levels)
        return changed if masks_wake(changed, self._restless_cells()) else None

    def _restless_cells(self) -> tuple[np.ndarray, ...] | None:
        """Each camera's cells that woke :data:`RESTLESS_AFTER_WAKES` searches whose round then found nobody (since
        they last calmed, :meth:`_calm_restless_cells`), and their neighbours: they no longer wake one (a scene that
        keeps moving would wake every rest, and the rest would save nothing; the edge cells of a screen, partly
        covered, change less and not every time)."""
        if self._vain_wakes is None:
            return None
        return tuple(restless_with_neighbours(counts >= RESTLESS_AFTER_WAKES) for counts in self._vain_wakes)

    def _count_vain_wake(self) -> None:
        """A woken search's whole round found nobody (a person in one view alone on a pair or a few restarted it, no
        more): the cells that woke it count one vain wake each."""
        if self._vain_wakes is None:
            self._vain_wakes = tuple(np.zeros(m.shape, np.int32) for m in self._woke_on)
            self._still_passes = tuple(np.zeros(m.shape, np.int32) for m in self._woke_on)
        for counts, woke in zip(self._vain_wakes, self._woke_on):
            counts += woke
        self._woke_on = None

    def _tile_missed(self, copies: Callable[[], tuple[SceneCopy, ...]]) -> None:
        """A tile pass found nobody in the pair (``copies()``, its scene copies): after a whole round of such passes,
        the next pairs rest, and the cells that woke that round's search count a vain wake (:meth:`_count_vain_wake`);
        the scene is kept for the resting pairs to wake on (``tracking.cold_tiles_wake_levels``; not with
        ``cold_tiles_rest_every`` 1), its still cells counted towards calming (:meth:`_calm_restless_cells`)."""
        self._tiles_missed += 1
        if self._tiles_missed >= len(self._cold_tiles):
            self._tile_rest_wait = self.config.tracking.cold_tiles_rest_every - 1
            if self._woke_on is not None:
                self._count_vain_wake()
        levels = self.config.tracking.cold_tiles_wake_levels
        if levels and self.config.tracking.cold_tiles_rest_every > 1:  # with no rest there is nothing to wake
            now = copies()
            self._calm_restless_cells(now, levels)
            self._rest_scene = now

    def _calm_restless_cells(self, now: tuple[SceneCopy, ...], levels: float) -> None:
        """A cell unchanged over :data:`CALM_AFTER_PASSES` tile passes in a row that found nobody forgets its vain
        wakes: a screen switched off, a curtain now still, wakes the rest again rather than never (a long-running
        device would otherwise stay blind there until a reset). One still pass is not enough: a screen's next picture
        may match its last in a cell by chance, and the cell would wake the rest again at once."""
        if self._vain_wakes is None or self._rest_scene is None:
            return
        for counts, still, changed in zip(self._vain_wakes, self._still_passes,
                                          changed_masks(now, self._rest_scene, levels)):
            still[changed] = 0
            still[~changed] += 1
            counts[still >= CALM_AFTER_PASSES] = 0

    def _wake_tiles(self) -> None:
        """Someone was seen, the scene changed (a wake) or the estimator reset: every cold pair that finds nobody
        searches a tile again. The wake awake, if any, stays to be judged: a person seen in one view only may be a
        screen the model reads as one (a moving picture woke the rest again and again, docs/runtime.md), so only a
        pair that reports a joint (:meth:`_sees_in_3d`), or a person one camera alone saw over several pairs in a row
        (:meth:`_stays_in_one_view`), makes it not vain; else the round that ends in nobody counts it
        (:meth:`_tile_missed`)."""
        self._tiles_missed = 0
        self._tiles_tried = frozenset()
        self._tile_rest_wait = 0
        self._rest_scene = None
        if self._still_passes is not None:  # nothing kept to compare with now: a cell's still passes start again
            for still in self._still_passes:
                still[:] = 0

    def _weak_pass(self, p: "_Pass") -> bool:
        """Whether ``roi.turn_search`` tries turned crops after ``p``, a cold pair's pass (refined or not) or a
        tracked pass through upright crops (the caller sees to which): two frames that passed the frame check, and
        nobody found, or someone at a median joint confidence under ``roi.turn_search_below`` (an upside-down
        person read as an upright one); and a view whose ``presence.min_joints``-th strongest joint peak reaches
        :data:`_TURN_SEARCH_FLOOR` (someone may be there: an empty room does not search); and not a person seen by
        one camera only whom no turn can help (:meth:`_one_view_needs_no_search`); nor two people in view with nobody
        to pick (:meth:`_two_people_report_nobody`)."""
        roi = self.config.roi
        if not roi.turn_search or p.j3 is None or p.env is None or not all(p.frame_ok.values()):
            return False
        if p.someone and _median_confidence(p.j3) >= roi.turn_search_below:
            return False
        if self._one_view_needs_no_search(p) or self._two_people_report_nobody(p):
            return False
        rank = self.config.presence.min_joints
        peaks = joint_peaks(p.env["encoder_heatmaps"])  # once for both views
        return any(ranked_peak(peaks, (v,), rank) >= _TURN_SEARCH_FLOOR for v in (0, 1))

    def _one_view_needs_no_search(self, p: "_Pass") -> bool:
        """Whether ``p`` is a person seen by one camera only (``p.single_view``: nobody in 3D, one view's own 2D
        joints) that no crop turn can help: a kept turn must find someone in 3D, so the other view must show the
        body. Not when that view reads them well (its found joints' median confidence at ``roi.turn_search_below``
        or above, the bar a 3D pass's joints clear): a body a view sees well upright is upright, or lies along its
        line of sight, which :func:`lies_as_turned` refuses. Nor when the other view's ``presence.min_joints``-th
        strongest joint peak is under :data:`_TURN_SEARCH_FLOOR` (nobody there for a turn to find, as an empty
        room's views). Before, such a pair searched every ``roi.turn_search_every``-th time for nothing: three
        encoder runs and up to two passes (docs/runtime.md, "A person seen by one camera only"). A weakly read
        view beside another that may show someone is the misread the search exists for (someone lying across
        both views, one under the per-view rule), and still searches."""
        if p.single_view is None:
            return False
        found = ~p.missing_2d[p.single_view]
        if found.any() and float(np.median(p.conf_2d[p.single_view][found])) >= self.config.roi.turn_search_below:
            return True
        other = 1 - self.camera_names.index(p.single_view)
        return presence_peak(p.env["encoder_heatmaps"], (other,), self.config.presence.min_joints) < _TURN_SEARCH_FLOOR

    def _two_people_report_nobody(self, p: "_Pass") -> bool:
        """Whether ``p`` is a ``several_people`` pass that reports nobody where no subject is picked
        (``pick_subject: none``, or another 3D method than the triangulation: :func:`picks_subject`), both views
        reading bodies strongly (each :func:`_view_score` at ``roi.turn_search_below`` or above): two people upright,
        nobody reported by design until one is alone. No turn changes that: a turned pass of the same working
        volume that is flagged reports nobody too, and one that is not (a turn that reads one of them weakly) would
        report and track one of two people, or both mixed, which that rule refuses. Before, every
        ``roi.turn_search_every``-th such pair searched for nothing (three encoder runs; docs/turn-search.md,
        "Searching the crop turns"). A weakly read view still searches: one person lying across the view shows
        joints twice through upright crops and is flagged (bench scene 11, views at 0.30 and 0.26), and the turned
        crops find them. Where a subject is picked, a flagged pair whose pick made nobody may be someone lying, and
        searches as before."""
        if not p.several_people or p.someone or picks_subject(self.config.joints3d):
            return False
        return bool((_view_score(p.env["encoder_heatmaps"]) >= self.config.roi.turn_search_below).all())

    def _turn_scores(self, images: Sequence[np.ndarray], turn: int, timing: dict,
                     track: Track | None = None) -> np.ndarray:
        """Per view, :func:`_view_score` of the encoder heatmaps of its working-volume crop (``track``'s crop
        when given) turned ``turn`` degrees more than upright (one encoder run for both views, no flip test)."""
        self._use_turns((turn, turn))
        if track is not None:
            self.tracker.follow(track)
        t = time.perf_counter()
        batch, crops, _ = self._crop_batch(images, self.tracker.regions().rois)
        heat = self._crop_heatmaps(batch, crops)
        _add_ms(timing, "turn_search", t)
        return _view_score(heat)

    def _turn_candidates(self, images: Sequence[np.ndarray], base: np.ndarray, timing: dict,
                         track: Track | None = None) -> list[tuple[int, int]]:
        """The views' turns for :meth:`_turn_search` to try, given the upright crops' :func:`_view_score`
        ``base``: each view's best turn that scores :data:`_TURN_MARGIN` above upright (0 where none does; per
        view, as two cameras facing each other see a body's roll opposite ways), then, when the views differ
        (one view's peaks are not clearly stronger turned), the one turn for both whose summed score is best and
        :data:`_TURN_MARGIN` above upright's (cameras facing one way see the body rolled alike). ``track``: the
        crops are that track's (a tracked pass's search), else the working volume's."""
        scores = {0: base}
        for turn in (90, 180, 270):
            scores[turn] = self._turn_scores(images, turn, timing, track)
        per_view = tuple(max((t for t in scores if scores[t][v] >= base[v] + _TURN_MARGIN),
                             key=lambda t: scores[t][v], default=0) for v in (0, 1))
        candidates = [per_view] if per_view != (0, 0) else []
        both = max((90, 180, 270), key=lambda t: scores[t].sum())
        if scores[both].sum() >= base.sum() + _TURN_MARGIN and (both, both) not in candidates:
            candidates.append((both, both))
        return candidates

    def _turn_search(self, images: Sequence[np.ndarray], p: "_Pass", sequence: int, timing: dict,
                     novel_view: NovelViewRequest | None, track: Track | None = None,
                     rolled_from: tuple[tuple[int, int], np.ndarray] | None = None) -> "_Pass":
        """``roi.turn_search`` after the weak pass ``p`` through upright crops: the views' turns to try
        (:meth:`_turn_candidates`), each a pass with those crops, the first kept that finds someone where ``p``
        did not, or at a median confidence :data:`_TURN_MARGIN` higher, and lies as a turn rights a body
        (:func:`lies_as_turned`; else it counts in ``turns_refused``); else ``p`` and its track stand. The passes
        are cold (the working volume's crops) after a cold ``p``; after a tracked one, ``track`` (what ``p`` left)
        is followed through the turned crops, the same window about the person as ``p``'s. ``rolled_from``: the kept
        turn this pair lost and the last pass kept through it, which ``p`` reads turned over
        (:meth:`_turn_lost_flipped`); a pass through another turn that rolled on from that pass is kept too
        (:meth:`_rolls_on_from_lost_turn`), more confident than ``p`` or not."""
        self.turn_searches += 1
        self._search_refused_short = None
        held = self._several_track, self._behind_track, self._track_unsorted
        for turns in self._turn_candidates(images, _view_score(p.env["encoder_heatmaps"]), timing, track):
            self._use_turns(turns)
            if track is not None:
                self.tracker.follow(track)
                # the same subject through other crops: a flagged track's hold (SubjectSelector.several_people,
                # .behind_view) goes with it, or the turned pass lets the other person's peaks into the joints and
                # the track
                self._several_track, self._behind_track, self._track_unsorted = held
            q = self._pass(images, self.tracker.regions(), sequence, timing, novel_view)
            rolled_on = self._rolls_on_from_lost_turn(q, turns, rolled_from)
            if rolled_on or _finds_better(q, p):
                if rolled_on or self._lies_as_turned(q.j3):
                    if p.novel is not None:
                        p.novel.abandon()
                    self.turns_kept += 1
                    self._turn_check_wait = self.config.roi.turn_search_every - 1  # just compared with upright
                    log.debug("pair %d: crops turned %s degrees found the subject", sequence, turns)
                    return q
                # the encoder's guess at a body no turn rights (lying along the line of sight): not taken
                self.turns_refused += 1
                # or a person lying down, a few degrees short of the window: _searches_early
                short = degrees_short_of_lying(q.j3, self._centres)
                if short is not None and (self._search_refused_short is None or short < self._search_refused_short):
                    self._search_refused_short = short
                log.debug("pair %d: crops turned %s degrees found a body that does not lie as turned", sequence, turns)
            if q.novel is not None:
                q.novel.abandon()
        # upright stands, with the track its pass left
        self._use_turns((0, 0), fresh=False)
        self._several_track, self._behind_track, self._track_unsorted = held
        return p

    def _turn_lost_flipped(self, p: "_Pass", lost: tuple[int, int], last_axis: np.ndarray) -> bool:
        """Whether ``p``, the cold upright pass of a pair that lost the kept turn ``lost``, found someone (both frames
        passing the frame check) whose body reads turned over against ``last_axis``, the last pass kept through the
        turn (:func:`reads_flipped`): a misread, however strong; and another turn could keep the body rolled on from
        that pass (:func:`another_turn_may_hold`; else the search could keep only what it keeps after a weak pass,
        and someone upside down who got up searched for nothing, once a scene in
        benchmarks/measure_lying_rendered.py --poses upside_down --then upright). A cartwheel kept through the
        quarter turn past 135 degrees loses it, and the upright crops read the body nearly upside down as someone
        standing, at a median joint confidence of 0.50 (bench scene 10), so no weak pass searched, and a weak one
        later kept no turn: the half turn read it at 0.53, not 0.1 higher (docs/turn-search.md, "A turn lost past
        135 degrees")."""
        if not self.config.roi.turn_search or p.j3 is None or not p.someone or p.env is None:
            return False
        return (all(p.frame_ok.values()) and another_turn_may_hold(last_axis, lost)
                and reads_flipped(p.j3, last_axis))

    def _rolls_on_from_lost_turn(self, q: "_Pass", turns: tuple[int, int],
                                 rolled_from: tuple[tuple[int, int], np.ndarray] | None) -> bool:
        """Whether ``q``, a search's pass through ``turns``, found the body rolled on from the last pass kept through
        the turn this pair lost (``rolled_from``: that turn and that pass's axis; :func:`lies_as_kept_turn`, the rule
        a kept turn's passes are asked) into another turn's sector: the same body, read through the turn that now
        shows it nearer upright. Not through the lost turn itself: a person getting up from it reads turned over
        upright, and through that turn as they lay."""
        if rolled_from is None or turns == rolled_from[0] or q.j3 is None or not q.someone:
            return False
        return lies_as_kept_turn(q.j3, self._centres, turns, rolled_from[1])

    def _wait_after_search(self, p: "_Pass") -> None:
        """After a search that kept no turn over ``p``, its weak upright pass: the next ``roi.turn_search_every - 1``
        weak pairs do not search (someone no turn rights, most likely: a person lying along a line of sight reads
        weakly pair after pair, three encoder runs and up to two passes a search for nothing), unless one loses the
        person ``p`` found (:meth:`_searches_early`). A search such a pair makes early lets the wait run on as it
        would have: it never puts off the search the wait would have made, nor makes another early one, but for a
        body nearly lying that rolled nearer the window since the search before (:data:`_NEAR_LIE_STEP_DEG`)."""
        early = self._turn_search_wait > 0
        if early:
            self._turn_search_wait -= 1
        else:
            self._turn_search_wait = self.config.roi.turn_search_every - 1
        self._failed_search_found = not early and bool(p.someone)
        self._failed_search_short = self._near_lie_trigger(early)

    def _near_lie_trigger(self, early: bool) -> float | None:
        """After a search that kept no turn: how far short of lying the body it refused lay, when that lets the next
        weak pair search (:meth:`_searches_early`): after the wait's own search, any body nearly lying; after an
        early one, only one at least :data:`_NEAR_LIE_STEP_DEG` nearer the window than at the search before (rolling
        in; else the early searches end, as session 59's did after one)."""
        now, before = self._search_refused_short, self._failed_search_short
        if not early:
            return now
        if now is not None and before is not None and now <= before - _NEAR_LIE_STEP_DEG:
            return now
        return None

    def _end_wait(self) -> None:
        """Someone found well, upright or through a turn a search just kept: the wait after a failed search
        (:meth:`_wait_after_search`) is over, and the next weak pair searches at once. A search the wait let through
        early (:meth:`_searches_early`) that kept a turn left the wait running, and with it the early search's
        trigger: the tracked pairs through the turn never end it, so the search after the turn was lost counted as
        an early one, and the wait it set ran from the old search (the cartwheel past 150 degrees, a one-off look
        with benchmarks/measure_lying_rendered.py --rolls: docs/turn-search.md, "A body nearly lying")."""
        self._turn_search_wait = 0
        self._failed_search_found = False
        self._failed_search_short = None

    def _searches_early(self, p: "_Pass") -> bool:
        """Whether ``p``, a weak pass in the wait after a search that kept no turn (:meth:`_wait_after_search`),
        searches all the same: the search's upright pass found someone and ``p`` finds nobody. A person lying down
        or turning a cartwheel is read weakly by upright crops up to 60-70 degrees from upright, then lost, about
        where a quarter turn begins to read them; the search on the weak pass before found no turn, and the wait
        put the next off by up to four pairs (docs/turn-search.md, "An early search after a failed one"). Once for
        each such search: the early search's own pass found nobody, so the passes after it wait (at most one
        early search for each search the wait follows). A body that stays found or stays lost waits as before.
        (A body axis turned more than 10-15 degrees since the failed search was tried as a trigger too: more
        searches in the rolls, no turn found sooner.) Or, found or not, when the failed search refused a turned
        pass of a body a few degrees short of lying (:func:`nears_a_turned_lie`): its upright pass had found
        nobody, but the turn read the body rolling toward the window (docs/turn-search.md, "A body nearly lying");
        once too, unless the early search's turned pass read the body rolled nearer the window
        (:meth:`_near_lie_trigger`)."""
        return (self._failed_search_found and not p.someone) or self._failed_search_short is not None

    def _lies_as_turned(self, j3: Joints3D) -> bool:
        """:func:`lies_as_turned` of ``j3`` seen by this rig's two cameras (the turn search's rule; a kept turn's passes
        are asked :func:`lies_as_kept_turn`, :meth:`_turn_misreads`)."""
        return lies_as_turned(j3, self._centres)

    def _turn_misreads(self, p: "_Pass") -> bool:
        """Whether ``p``, a pass through a kept turn's crops, found someone whose body lies as the turn does not
        right (:func:`lies_as_kept_turn`, rolled on from the last pair's kept pass, :meth:`_kept_turn_axis`): a
        person who lay across the view and rolled onto a view's line of sight is read through the turned crops as
        the encoder's upright person across the picture, the skeleton the search refuses. Geometry only: no model
        run, and no state changed (the caller that refuses ``p`` counts it in ``turns_refused``; the axis the next
        pass rolls on from is set where the pair's pass is kept)."""
        if p.j3 is None or not p.someone:
            return False
        return not lies_as_kept_turn(p.j3, self._centres, self._turns, self._kept_axis)

    def _kept_turn_axis(self, p: "_Pass") -> np.ndarray | None:
        """The body axis (:func:`body_axis`) that the next pair's pass through a kept turn rolls on from
        (:func:`lies_as_kept_turn`): that of ``p``, the pass this pair keeps, when it was read through a turn and
        found someone; else ``None``. A pair that keeps no such pass (a view's frame rejected, nobody found, the
        turn left) breaks the roll: the rule's step limit (:data:`~ghnerf_runtime.body_lie.KEPT_TURN_STEP_DEG`)
        is one pair's, and against an axis some pairs old a real roll looks like a jump, while a limit grown with
        the pairs would let the jump through (docs/turn-search.md, "Gradual rolls"); the next pass through the turn is
        asked the search's rule instead."""
        if self._turns == (0, 0) or p.j3 is None or not p.someone:
            return None
        return body_axis(p.j3)

    def _turn_check(self, images: Sequence[np.ndarray], p: "_Pass", sequence: int, timing: dict,
                    novel_view: NovelViewRequest | None) -> "_Pass":
        """After ``p``, a tracked pass through a kept turn's crops: when it is weak (a median joint confidence
        under ``roi.turn_search_below``), or ``roi.turn_search_every`` tracked turned pairs after the last check,
        the pass again through upright crops of the track ``p`` left, kept when it finds someone at a median
        confidence :data:`_TURN_MARGIN` higher (the person got up: through the turned crops a standing person is
        read upside down, 1.1-1.3 m off, at 0.44-0.57; upright at 0.7-0.9, in a one-off look at four bench
        scenes), the turn dropped with it; else ``p`` and the turned track stand. The tracked turned passes of
        someone still lying reach confidences as low as the misread's, so the weak ones compare rather than drop;
        the periodic check catches a misread over the bar. One pass more on a checked pair (docs/turn-search.md,
        "Getting up and lying down while tracked"). A ``p`` whose body lies as the turn does not right (neither as
        the search keeps a turn nor rolled on from the last pass kept through it, :func:`lies_as_kept_turn`) does not
        come here (:meth:`_turn_misreads`: the pair is read cold instead)."""
        track = self.tracker.track
        if track is None or p.j3 is None:
            return p  # no track: the next pair is cold, and upright first
        weak = not p.someone or _median_confidence(p.j3) < self.config.roi.turn_search_below
        if not weak and self._turn_check_wait > 0:
            self._turn_check_wait -= 1
            return p
        self._turn_check_wait = self.config.roi.turn_search_every - 1
        self.turn_checks += 1
        turns, held = self._turns, (self._several_track, self._behind_track, self._track_unsorted)
        self._use_turns((0, 0))
        self.tracker.follow(track)
        # the same subject: a flagged track's hold goes with it
        self._several_track, self._behind_track, self._track_unsorted = held
        q = self._pass(images, self.tracker.regions(), sequence, timing, novel_view)
        if _finds_better(q, p):
            if p.novel is not None:
                p.novel.abandon()
            self.turns_left += 1
            log.debug("pair %d: upright crops found the subject better than crops turned %s degrees", sequence, turns)
            return q
        if q.novel is not None:
            q.novel.abandon()
        self._use_turns(turns, fresh=False)  # the turn stands, with the track its pass left
        self._several_track, self._behind_track, self._track_unsorted = held
        return p

    def _lost_on_a_tracked_pass(self, p: "_Pass") -> bool:
        """Whether ``tracking.retry_cold`` runs the pair again from the working volume: a tracked pass that
        dropped the track and reported nobody. That includes a crop the frame check rejected: a subject who
        left shows the crop a flat wall, and the working volume's crop may show them (a view whose 2D joints
        were reported, the single-view pass, is no loss: its next crop follows them). A person seen by one
        camera only is retried (the other camera's tracked crop may have lost them), from that camera's view track
        and, both frames having passed, the other camera's crop on the seen joints' rays (session 69; before, its
        working volume's crop)."""
        if not (self.config.tracking.retry_cold and p.regions.tracked and self.tracker.track is None):
            return False
        if all(p.frame_ok.values()):
            return p.j3 is None or not p.j3.valid.any()
        return p.missing_2d is None or all(m.all() for m in p.missing_2d.values())

    def _forget_a_stale_track(self, timestamp_s: float | None) -> None:
        """Drop the track when the pair comes more than ``tracking.max_gap_s`` after the last one, or before it
        (a pair of the same instant, the same frames estimated again, keeps it); such a pair is ``_after_gap``
        (a pair without a time, or after none, is not)."""
        self._after_gap = False
        if timestamp_s is None:
            return
        t, last = float(timestamp_s), self._last_timestamp_s
        self._last_timestamp_s = t
        if last is not None and not (last <= t <= last + self.config.tracking.max_gap_s):
            self._after_gap = True
            self.tracker.reset()

    def _pass(self, images: Sequence[np.ndarray], regions: Regions, sequence: int, timing: dict,
              novel_view: NovelViewRequest | None = None, cold_several: bool | None = None) -> "_Pass":
        """Stages 1-6 on one set of regions; stage times are added to ``timing``; updates the track.

        ``novel_view``: compute the image features too (``encoder`` rather than ``human``) for a novel
        view; on a tracked pair with ``novel_view.overlap`` the view is started in the worker once the
        graphs of the keypoint path have run (``_Pass.novel``). ``cold_several``: this pass refines this pair's
        cold pass, which was ``several_people`` or not (:meth:`_finish_pass`); or (``True`` only) it is the cold pass
        that ``tracking.retry_cold`` runs after a tracked pass that was; ``None``: neither.
        """
        cfg = self.config
        S = self.size
        # the novel view reads the image features of the pair (a cold pass may leave them for later)
        features = novel_view is not None and not self._features_may_wait(regions)

        # 1. preprocess + frame check
        t = time.perf_counter()
        batch = np.empty((2, 3, S, S), np.float32)
        frame_reason, crops = {}, []  # camera name -> None, or why the frame check rejected its crop
        on_rays = self.tracker.rays_camera(regions)
        self._pair_on_rays = self._pair_on_rays or on_rays is not None
        for i, (img, st, roi) in enumerate(zip(images, self._cams, regions.rois)):
            maps, crop = self._crop(st, roi)
            crops.append(crop)
            batch[i] = preprocess_image(img, maps, self.contract.normalisation)
            ok, why = check_crop(batch[i, 1], self._levels, cfg.frame_check, maps.inside)
            if i == on_rays:
                # a plain part of a working camera's view (a wall, a panel hiding the person from it), not a covered
                # lens: rejected, the next crop went back to the whole volume and the one after to the rays, pair
                # after pair, and the camera was reported rejected every other pair (session 70)
                ok, why = self._rays_crop_verdict(img, i, batch[i, 1], maps.inside, why if not ok else None)
            frame_reason[st.camera.name] = None if ok else why
        _add_ms(timing, "preprocess", t)
        passed = [why is None for why in frame_reason.values()]
        if not all(passed):
            if any(passed) and self._single_view_2d:
                return self._single_view_pass(batch, crops, regions, frame_reason, timing)
            self.tracker.reset()  # nothing seen: the next pair starts cold
            return _Pass(regions, frame_reason)

        # 2-4. encoder, volume (sources as targets), heatmaps on the subject's rays
        # src_P with the images: a keypoint graph that reads the cameras (the benchmarks' oracle session) is fed them
        env: dict[str, np.ndarray] = {"images": batch, "src_P": source_projections(crops, S, S)}
        if self._builds_a_volume(novel_view):
            env.update(self._volume_feeds(crops, regions))
        t = time.perf_counter()
        # onnxruntime runs a whole graph whatever is asked of it: without a volume to build, the
        # human-only graph skips the image feature network.
        encoder = "human" if self._human_graph and not features else "encoder"
        flipped = self._flip_lanes and encoder == "human" and regions.tracked
        if flipped:
            # someone was there: the mirrored crops beside the crops, not after them (the same heatmaps, sooner)
            out, mirrored = self.session.run_both("human", env, self._mirrored_feeds(batch, env["src_P"]))
            env.update(out)
            env["encoder_heatmaps"] = flip_averaged(out["encoder_heatmaps"], mirrored["encoder_heatmaps"])
            _add_ms(timing, "encoder", t)
        else:
            env.update(self.session.run(encoder, env))
            _add_ms(timing, "encoder", t)
        job = None
        if novel_view is not None and cfg.novel_view.overlap and regions.tracked and self._novel_lanes:
            # The view reads the image features and the tracked box, nothing that the flip test or the stages
            # below change: it starts now, on one thread, and the flip test's run goes beside it on the other.
            job = self._start_novel(novel_view, env, regions.box)
        try:
            if not flipped and cfg.flips_encoder_heatmaps and self._views_may_show_someone(env["encoder_heatmaps"]):
                env["encoder_heatmaps"] = self._flip_test(batch, env["encoder_heatmaps"], timing, env["src_P"],
                                                          beside=job is not None)
            stride, g = self.contract.heatmap_stride, self.grid
            blocks = [full_block(g, g)] * 2
            out: dict[str, np.ndarray] = {}
            if cfg.runs_source_volume:
                t = time.perf_counter()
                env.update(self.session.run("volume", env))
                _add_ms(timing, "volume", t)
            if cfg.renders_source_heatmaps:
                t = time.perf_counter()
                if cfg.rays.restrict_to_subject and regions.tracked:
                    blocks = common_blocks([box_block(c, regions.box, stride, cfg.rays.margin_cells) for c in crops],
                                           g, g, cfg.rays.align_cells)
                env["ray_uv"] = self._ray_uv(tuple(blocks), stride)
                out = self.session.run("render_heat", env)
                _add_ms(timing, "render_heat", t)
            if novel_view is not None and cfg.novel_view.overlap and regions.tracked and job is None:
                job = self._start_novel(novel_view, env, regions.box)  # once the keypoint graphs have run
            return self._finish_pass(env, out, blocks, crops, regions, frame_reason, sequence, timing, job,
                                     cold_several)
        except BaseException:
            if job is not None:  # leave no render running behind an error
                job.abandon()
            raise

    def _verdict_for_pair(self) -> None:
        """Void the cached whole-volume verdict where the last pair ran no pass on the rays: it answers pair after pair
        on them. A pair's own passes off the rays (a turn search's, a refined or a cold retry's) leave it: the next
        pair's crop on the rays is the same camera's, through the tracker and camera state the verdict names (session
        72; before, they voided it and that pair checked the camera again)."""
        if not self._pair_on_rays:
            self._volume_verdict = None
        self._pair_on_rays = False

    def _rays_crop_verdict(self, image: np.ndarray, camera: int, plane: np.ndarray, inside: np.ndarray | None,
                           rejected: str | None) -> tuple[bool, str]:
        """The frame check's ``(ok, reason)`` of camera ``camera``'s crop on the rays, model-input ``plane`` (its
        ``inside`` pixels show the frame), which the check ``rejected`` for that reason (None: passed): rejected, it
        passes where the camera's whole-volume crop of ``image`` passes, asked again only where the cached verdict
        no longer holds (:class:`~ghnerf_runtime.rays_recheck.VolumeVerdict`, ``frame_check.volume_recheck_every``)."""
        if rejected is None:
            self._volume_verdict = None
            return True, ""
        state, level = self._cams[camera], mean_level(plane, inside, self._levels)
        kept = self._volume_verdict
        if kept is not None and kept.holds(state, self.tracker, rejected, level):
            self._volume_verdict = kept.reused()
            return True, ""
        self.volume_rechecks += 1
        if not self._volume_crop_passes(image, camera):
            self._volume_verdict = None
            return False, rejected
        check = self.config.frame_check
        self._volume_verdict = VolumeVerdict(state, self.tracker, self.tracker.resets, rejected, level,
                                             check.volume_recheck_every - 1, check.volume_recheck_levels)
        return True, ""

    def _volume_crop_passes(self, image: np.ndarray, camera: int) -> bool:
        """Whether camera ``camera``'s crop of the whole working volume in ``image`` passes the frame check: the
        camera works, whatever part of its view another crop shows."""
        maps, _ = self._crop(self._cams[camera], self.tracker.volume_regions.rois[camera])
        plane = preprocess_image(image, maps, self.contract.normalisation)[1]
        return check_crop(plane, self._levels, self.config.frame_check, maps.inside)[0]

    def _builds_a_volume(self, novel_view: NovelViewRequest | None) -> bool:
        """Whether a pass may run a graph of the cost volume (``volume``, ``render_heat``, ``query``: each pair
        with ``runs_source_volume``) or the novel view, which builds its volume from the pass's ``src_centers`` (a
        cold pass's view too, rendered after :meth:`_add_features`): the graphs that read :meth:`_volume_feeds`.
        The default keypoint path runs none, and building those feeds took about 0.2 ms a pass for nothing."""
        return novel_view is not None or self.config.runs_source_volume

    def _volume_feeds(self, crops: list[Camera], regions: Regions) -> dict[str, np.ndarray]:
        """The crop cameras as the volume and rendering graphs read them, besides ``src_P``: ``src_centers``, the
        sources as targets (``tgt_K_inv``, ``tgt_c2w``) and each camera's ``near_far`` of the pass's sweep box."""
        margin = self.config.tracking.near_far_margin_m
        return {
            "src_centers": source_centers(crops),
            **target_inputs(crops, self.size, self.size),
            "near_far": np.stack([near_far_from_box(c, box_corners(regions.box), margin) for c in crops]),
        }

    def _finish_pass(self, env: dict, out: dict, blocks, crops: list[Camera], regions: Regions, frame_reason: dict,
                     sequence: int, timing: dict, job: _NovelJob | None, cold_several: bool | None = None
                     ) -> "_Pass":
        """Stages 5-6 of :meth:`_pass`. ``cold_several`` (a pass refining this pair's cold pass): that pass was
        ``several_people``, so this one is, whatever its own maps show (its crop frames the picked subject and
        may show fewer of the other's joints twice, the same two people in view); or it was not, but this one is:
        the cold pass, whose crop is the whole working volume, showed two people too small to tell, its skeleton
        (the track) is both people's, and a subject is picked as without a track."""
        cfg = self.config
        S, g = self.size, self.grid

        # 5. decode 2D
        t = time.perf_counter()
        if cfg.heatmaps.source == "encoder":
            heat = np.ascontiguousarray(env["encoder_heatmaps"], dtype=np.float32)  # (2, J, g, g), whole crop
            kp = decode_keypoints(heat, cfg.decoder)
        else:
            heat = np.stack([scatter_block(out["heatmaps"][i], blocks[i], g, g) for i in range(2)])  # (2, g, g, J)
            heat = np.ascontiguousarray(heat.transpose(0, 3, 1, 2))  # (2, J, g, g), for the 3D stage
            kp = decode_blocks(out["heatmaps"], blocks, self.config.decoder)
        uv_model = heatmap_to_model_pixels(kp.uv, g, S)
        joints_2d, conf_2d, missing_2d = self._image_joints(kp, uv_model, crops)
        _add_ms(timing, "decode_2d", t)

        # 6. 3D, then the track
        t = time.perf_counter()
        j3 = self._joints_3d(env, out, blocks, heat, kp, uv_model, crops, regions)
        j3 = self._gate_to_boxes(j3, regions)
        selector = self.subject_selector
        held = self._several_track and self.tracker.track is not None  # the track is a flagged pass's subject
        several = selector.several_people(kp, held and self._behind_track is None) or cold_several is True
        # one person behind the other in this view (a cold pass's crop, the whole working volume, draws two people
        # too small to tell one peak hidden from two merged: the pass refining it decides)
        held_view = self._behind_track if held else None  # (the one-peak view where one view alone flagged it)
        behind = None if several or not regions.tracked else selector.behind_view(kp, held_view)
        several |= behind is not None
        # a torso of two people (both views read one person's mid-hip and the other's hip): two people too near
        # for the maps to show a joint twice, or the views' peaks agreeing on the wrong person (docs/two-people.md,
        # "A torso of two people"); the two-people check off (second_person_min_joints 0) leaves it out too. A cold
        # pass's crop (the whole working volume) draws them too small to split: its track is both people's, unsorted
        # (below), and the pass refining it decides, as after a cold pass that showed a joint twice
        torso = self._torso_mixed and cfg.joints3d.second_person_min_joints > 0
        several |= torso and regions.tracked
        subject = j3  # a several_people pair's joints of the tracked subject that the views' peaks gave
        chosen = None  # and the peaks each of them was triangulated from (SubjectSelector.keep_tracked_subject)
        guessed = None  # a flagged pair's joints not reported: no pairing of the subject's gave them (below)
        if several:  # before the presence gate: the subject's joints alone must make someone
            # one solve of each joint's four pairings, in the crop cameras' kept terms: the subject's pairings and,
            # where they give no figures, both people's (below) check it (every flagged pass asks one or both)
            terms = self._crop_terms_for(crops).two_view
            pairings = selector.solve_pairings(kp, uv_model, crops, terms=terms)
            j3, chosen, subject = selector.keep_tracked_subject(j3, kp, uv_model, crops, regions, self.tracker.track,
                                                                self._track_unsorted, cold_several, behind,
                                                                solution=pairings)
            if chosen is not None:  # a view's 2D joint is the peak its 3D joint was triangulated from
                joints_2d, conf_2d, missing_2d = self._image_joints(*chosen, crops)
                guessed = guessed_joints(subject, kp)
        nobody = False  # (the presence gate off: nothing decides that nobody is there)
        seen_by = None  # the one view that shows someone when the pair shows nobody in 3D
        if cfg.presence.enabled:
            if self.skeleton_prior is None:
                # the gate counts what the pair reports: on a flagged pair not the joints left out below (guessed),
                # so the subject's own pairings, as with the prior. Counted, 4 pairings and 3 joints of the decoded
                # peaks near the track passed presence.min_joints 6 and reported 4 (before session 59's review)
                counted = j3 if guessed is None else Joints3D(j3.points, j3.confidence, j3.valid & ~guessed,
                                                              j3.reprojection_px)
                if not gate_presence(counted, cfg.presence.min_joints,
                                     cfg.presence.threshold(cfg.heatmaps.source)).valid.any():
                    j3 = Joints3D.missing(len(j3.valid), j3.reprojection_px.shape[-1])
                nobody = not j3.valid.any()
            else:  # decided on the triangulation (_joints_3d); the prior's error gate may still leave no joint
                nobody = self._prior_follow is None
                # two people: that triangulation was both people's peaks, and the prior places a whole skeleton
                # near the track from them; the subject's own peaks must make someone, as j3 must without the prior
                strong = cfg.presence.threshold(cfg.heatmaps.source)
                if several and not nobody and not gate_presence(subject, cfg.presence.min_joints, strong).valid.any():
                    nobody = True
                    j3 = Joints3D.missing(len(j3.valid), j3.reprojection_px.shape[-1])
            if nobody and several:  # two people in view: one view's joints alone would be no one's in particular
                # nor is the prior's first run, on both people's peaks, a verdict on anyone reported (one person's
                # empty pair carries none either: _joints_3d skips the prior)
                self._prior_check = (None, False)
                for name in joints_2d:
                    joints_2d[name] = np.zeros_like(joints_2d[name])
                    conf_2d[name] = np.zeros_like(conf_2d[name])
                    missing_2d[name] = np.ones_like(missing_2d[name])
            elif nobody:
                joints_2d, conf_2d, missing_2d, seen_by = self._seen_by_one_view(env, kp, uv_model, crops,
                                                                                 (joints_2d, conf_2d, missing_2d))
        if several and not nobody and self.skeleton_prior is not None and chosen is not None:
            j3 = self._subject_prior(j3, subject, chosen, crops, regions)
        framed = j3  # what the crop follows on a several_people pair: the subject's skeleton, guesses and all
        if guessed is not None:  # (several, and the subject's pairings were looked for: subject.guessed_joints)
            j3 = Joints3D(j3.points, j3.confidence, j3.valid & ~guessed, j3.reprojection_px).sanitised()
        if several:
            # a camera's peak of a dropped joint may be the other person's: the 2D joints go with the 3D ones
            for name in joints_2d:
                missing_2d[name] = missing_2d[name] | ~j3.valid
                joints_2d[name] = np.where(missing_2d[name][:, None], 0.0, joints_2d[name])
                conf_2d[name] = np.where(missing_2d[name], 0.0, conf_2d[name]).astype(np.float32)
        # two people: the crop follows the subject's joints (the prior's skeleton and the encoder's peaks are both
        # people's), the guessed ones not reported among them, and the next pair looks for the subject's pairings
        # near them all, as before: a track without the guesses framed the subject without the side the other
        # person hides, and a track that held them for the crop only found fewer of the subject's joints (tried,
        # two people a metre apart: 62 % of the pairs flagged instead of 50 %, the joints 27.8 and 27.2 mm off
        # instead of 23.8; docs/two-people.md, "Fewer, right joints")
        follow = framed if several else self._track_joints(env, crops, regions, j3)
        self.tracker.update(follow.points, follow.confidence, follow.valid, sequence)
        self._several_track = several and self.tracker.track is not None
        self._behind_track = behind if self._several_track else None
        # a cold pass not flagged that showed a joint twice in both views (one person alone through the shipped
        # model: 15 of 330 passes), or a torso of two people: maybe two people too small to tell apart in its crop,
        # the working volume's
        self._track_unsorted = (not regions.tracked and not several and self.tracker.track is not None and
                                (torso or joints_shown_twice(kp, cfg.joints3d.second_person_ratio)
                                 >= STILL_SEVERAL_MIN_JOINTS))
        if seen_by is not None:  # its next crop follows the person
            # both frames passed: the other camera looks along the seen joints' rays, where its whole-volume crop
            # may draw a far person too small to find (docs/rig-file.md, session 69)
            self.tracker.update_view(seen_by, joints_2d[self.camera_names[seen_by]],
                                     conf_2d[self.camera_names[seen_by]], other_on_rays=True)
        if several:
            # each view's decoded peak may be either person's, so the pair's own figures say nothing of the rig:
            # the subject's own pairings do (SubjectSelector.subject_figures)
            agreement, foot = (None, None) if nobody else selector.subject_figures(subject, chosen, crops, regions,
                                                                                   terms=terms)
            if agreement is None or foot is None:  # no subject's pairings to measure (a camera knocked past the
                # gate, or panned far enough to take both people out of the box gates, leaves none): both people's
                pairs, matched = selector.both_people(kp, uv_model, crops, solution=pairings)
                if agreement is None:
                    agreement = selector.matched_px(matched)  # both people's peaks, paired one to one
                if foot is None:
                    foot = selector.matched_foot(kp, pairs, regions)  # each person's feet, before the box gates
        else:
            agreement = None if self._agreement is None else self._agreement.median_px
            # the triangulation's feet (not the prior's placed ones), whether or not the box gates left someone to
            # report (_joints_3d: the presence gate asked of the joints before them)
            foot = self._lowest_foot
        # two people's joints may mix in one skeleton: no handedness is read of a several_people pair
        hand = None if several else self._handedness
        _add_ms(timing, "joints_3d", t)  # (the figures too: both_people checks every pairing again)
        return _Pass(regions, frame_reason, env, j3, joints_2d, conf_2d, missing_2d, job, crops, not nobody,
                     *self._prior_check, several,
                     None if seen_by is None else self.camera_names[seen_by], agreement, foot, hand, kp)

    def _subject_prior(self, reported: Joints3D, subject: Joints3D, chosen: tuple[Keypoints2D, np.ndarray],
                       crops: list[Camera], regions: Regions) -> Joints3D:
        """A ``several_people`` pair's joints from the skeleton prior fed the picked or tracked subject's own peaks:
        in each view, the peak each of ``subject``'s joints was triangulated from (``chosen``,
        :meth:`SubjectSelector.keep_tracked_subject`), every other joint not decoded. The pair's decoded peaks, which
        :meth:`_joints_3d` fed it, are whichever person's is the stronger in each view: its skeleton from them lies
        between the two people. The gates are one person's (:meth:`_with_prior`, its disagreement measured against
        ``subject``), then the boxes; where the prior disagrees, ``reported`` (the subject's pairings, as without this
        step) stands. Sets the pair's ``_prior_check``; not ``_prior_follow``'s use: the track of two people follows
        this skeleton, the joints :meth:`_finish_pass` does not report among them."""
        kp, uv_model = chosen
        fed = replace(kp, valid=kp.valid & subject.valid[None])  # the decoded peak where no pairing was found
        est = self._with_prior(subject, uv_model, fed, crops)
        if self._prior_check[1]:
            return reported
        return self._gate_to_boxes(est, regions)

    def _seen_by_one_view(self, env: dict, kp: Keypoints2D, uv_model: np.ndarray, crops: list[Camera],
                          decoded: tuple[dict, dict, dict]) -> tuple[dict, dict, dict, int | None]:
        """A pair the presence gate says shows nobody in 3D: ``(joints_2d, conf_2d, missing_2d, view)``, the
        2D joints of the one view whose own encoder heatmaps pass the per-view presence rule
        (:meth:`_shows_someone`, as a rejected frame's other view is judged) and that view's index: a person
        seen by one camera only (entering at the edge of its view). Neither view, or both (their peaks do not
        meet in 3D: no answer to trust), or ``single_view_2d`` off: every 2D joint missing and ``None``.
        ``decoded``: the pair's 2D joints, which are the encoder heatmaps' with that heatmap source, so the
        usual empty room costs two counts; the rendered source decodes the encoder heatmaps here."""
        joints_2d, conf_2d, missing_2d = decoded
        good = None
        if self._single_view_2d and "encoder_heatmaps" in env:
            if self.config.heatmaps.source != "encoder":  # the rendered heatmaps' peaks: the view's own are these
                kp = decode_keypoints(np.ascontiguousarray(env["encoder_heatmaps"], dtype=np.float32),
                                      self.config.decoder)
                uv_model = heatmap_to_model_pixels(kp.uv, self.grid, self.size)
                joints_2d, conf_2d, missing_2d = self._image_joints(kp, uv_model, crops)
            seen = [i for i, name in enumerate(self.camera_names) if self._shows_someone(conf_2d[name])]
            good = seen[0] if len(seen) == 1 else None
        for i, name in enumerate(self.camera_names):
            if i != good:
                joints_2d[name], conf_2d[name] = np.zeros_like(joints_2d[name]), np.zeros_like(conf_2d[name])
                missing_2d[name] = np.ones_like(missing_2d[name])
        return joints_2d, conf_2d, missing_2d, good

    def _shows_someone(self, conf_2d: np.ndarray) -> bool:
        """The per-view presence rule: ``presence.min_joints`` of one view's 2D joints (``(J,)`` confidences,
        0 where missing) at its encoder-heatmap threshold or above (6 at 0.35); always with the gate off."""
        pres = self.config.presence
        return not pres.enabled or int(np.count_nonzero(conf_2d >= pres.threshold("encoder"))) >= pres.min_joints

    def _features_may_wait(self, regions: Regions) -> bool:
        """Whether a pass with a novel view asked for may run the keypoint-only ``human`` graph, leaving out
        the image features: a cold pass, with the cold start refined. One that finds the subject is run again
        on their crop, with the features, and that pass is reported; one that finds nobody has no view. Only a
        cold pass that finds someone but forms no track is reported with a view: :meth:`_add_features` runs
        the ``encoder`` graph for it then. Before, every pair of an empty room ran the ``encoder`` graph."""
        t = self.config.tracking
        return self._human_graph and not regions.tracked and t.enabled and t.refine_cold_start

    def _add_features(self, env: dict, timing: dict) -> None:
        """The image features a cold pass left out (:meth:`_features_may_wait`), from the ``encoder`` graph; the
        heatmaps the pass decoded (the flip test's average) are kept. The time counts as ``encoder``."""
        need = [t.name for t in self.contract.graph("encoder").outputs if t.name not in env]
        if need:
            t = time.perf_counter()
            out = self.session.run("encoder", env)
            env.update({k: out[k] for k in need})
            _add_ms(timing, "encoder", t)

    def _may_be_someone(self, heat: np.ndarray, views: Sequence[int], peaks: np.ndarray | None = None) -> bool:
        """Whether the flip test's second run can change the presence gate's answer
        (``heatmaps.flip_test_skip_below``, :func:`~ghnerf_runtime.flip_test.presence_peak`); always with
        the gate off. ``peaks``: ``heat``'s :func:`~ghnerf_runtime.flip_test.joint_peaks`, where already taken."""
        if not self._skips_flip_for_nobody:
            return True
        peaks = joint_peaks(heat) if peaks is None else peaks
        return ranked_peak(peaks, views, self.config.presence.min_joints) >= self.config.heatmaps.flip_test_skip_below

    @property
    def _skips_flip_for_nobody(self) -> bool:
        """Whether the flip test's second run is skipped where the heatmaps say nobody may be there."""
        return self.config.presence.enabled and self.config.heatmaps.flip_test_skip_below > 0

    def _views_may_show_someone(self, heat: np.ndarray) -> bool:
        """:meth:`_may_be_someone` of any of the presence gate's views (both, and each alone with one camera's
        2D joints answered), the heatmap maxima taken once for them all: an empty room asked all three, and took
        them three times."""
        peaks = joint_peaks(heat) if self._skips_flip_for_nobody else None
        return any(self._may_be_someone(heat, views, peaks) for views in self._presence_views)

    def _flip_test(self, batch: np.ndarray, heat: np.ndarray, timing: dict,
                   src_P: np.ndarray | None = None, beside: bool = False) -> np.ndarray:
        """``heat`` averaged with the encoder heatmaps of the mirrored crops (``heatmaps.flip_test``): the
        ``human`` graph when the model has one, else ``encoder``; the time goes to ``encoder_flip``. ``beside``:
        on its one-thread lane, as a novel view renders beside it (the same numbers)."""
        t = time.perf_counter()
        feeds = self._mirrored_feeds(batch, src_P)
        graph = "human" if self.session.has("human") else "encoder"
        run = self.session.run_on_lane if beside else self.session.run
        mirrored = run(graph, feeds)["encoder_heatmaps"]
        out = flip_averaged(heat, mirrored)
        _add_ms(timing, "encoder_flip", t)
        return out

    def _mirrored_feeds(self, batch: np.ndarray, src_P: np.ndarray | None) -> dict[str, np.ndarray]:
        """The flip test's feeds: the mirrored crops (and, for a graph that read cameras, their cameras)."""
        feeds = {"images": mirror_images(batch)}
        if src_P is not None:
            feeds["src_P"] = mirror_projections(src_P, self.size)
        return feeds

    def _image_joints(self, kp: Keypoints2D, uv_model: np.ndarray, crops: list[Camera],
                      views: Sequence[int] = (0, 1)) -> tuple[dict, dict, dict]:
        """Decoded peaks -> per camera name: pixels of the original image, confidence, missing.
        Cameras not in ``views`` get every joint missing."""
        S = self.size
        joints_2d, conf_2d, missing_2d = {}, {}, {}
        for i, (st, crop) in enumerate(zip(self._cams, crops)):
            name = st.camera.name
            # model_to_image_pixels without rebuilding the crop camera: crop pinhole -> lens.
            safe = np.where(kp.valid[i][:, None], uv_model[i], S / 2)
            xy = camera_normalized(crop.pixels_to_normalized(safe), crop, st.camera)
            uv_img = st.camera.normalized_to_pixels(xy, distort=True)
            # past the lens model's fold the model mirrors the point onto another part of the frame
            ok = kp.valid[i] & np.all(np.isfinite(uv_img), axis=-1) & st.camera.within_lens(xy) & (i in views)
            joints_2d[name] = np.where(ok[:, None], uv_img, 0.0)
            conf_2d[name] = np.where(ok, kp.confidence[i], 0.0).astype(np.float32)
            missing_2d[name] = ~ok
        return joints_2d, conf_2d, missing_2d

    def _single_view_pass(self, batch: np.ndarray, crops: list[Camera], regions: Regions, frame_reason: dict,
                          timing: dict) -> "_Pass":
        """One camera's crop failed the frame check (lens covered, blinded, a broken stream): the
        other camera's 2D joints from the encoder heatmaps. One view gives no depth, so every 3D
        joint is missing; the presence gate applies to the view's own peak values, and the view's
        next crop follows its joints (``SubjectTracker.update_view``)."""
        cfg = self.config
        good = next(i for i, st in enumerate(self._cams) if frame_reason[st.camera.name] is None)
        name = self.camera_names[good]
        t = time.perf_counter()
        # src_P as in _pass: a keypoint graph that reads the cameras (the benchmarks' oracle session) is fed them
        feeds = {"images": batch, "src_P": source_projections(crops, self.size, self.size)}
        heat = self.session.run("human" if self.session.has("human") else "encoder", feeds)
        _add_ms(timing, "encoder", t)
        heat = heat["encoder_heatmaps"]
        if cfg.heatmaps.flip_test and self._may_be_someone(heat, (good,)):
            heat = self._flip_test(batch, heat, timing, feeds["src_P"])
        t = time.perf_counter()
        kp = decode_keypoints(np.ascontiguousarray(heat, dtype=np.float32), cfg.decoder)
        uv_model = heatmap_to_model_pixels(kp.uv, self.grid, self.size)
        joints_2d, conf_2d, missing_2d = self._image_joints(kp, uv_model, crops, (good,))
        if not self._shows_someone(conf_2d[name]):
            joints_2d[name], conf_2d[name] = np.zeros_like(joints_2d[name]), np.zeros_like(conf_2d[name])
            missing_2d[name] = np.ones_like(missing_2d[name])
        self.tracker.update_view(good, joints_2d[name], conf_2d[name])  # its next crop follows the subject
        _add_ms(timing, "decode_2d", t)
        return _Pass(regions, frame_reason, None, Joints3D.missing(len(JOINT_NAMES)), joints_2d, conf_2d,
                     missing_2d, single_view=None if missing_2d[name].all() else name)

    def _track_joints(self, env: dict, crops: list[Camera], regions: Regions, reported: Joints3D) -> Joints3D:
        """The joints the next pair's crop follows: the reported ones, or (``tracking.follow_encoder``,
        rendered heatmaps) those of the encoder heatmaps this pair computed anyway, through the same
        triangulation and gates, or (the skeleton prior) the prior's whole skeleton, less strictly gated
        than what is reported, so a strict report gate does not shrink the crop around fewer joints.
        Nobody reported (the presence gate): nothing to follow either."""
        cfg = self.config
        if self._prior_follow is not None:
            # the prior's follow set is chosen by expected error alone (_PRIOR_FOLLOW_MAX_ERROR_M, or the report
            # gate if looser): its joints count for the track whatever tracking.min_confidence, a threshold for peak
            # values. Its score exp(-error / 0.1 m) falls below the default 0.1 past 0.23 m, which cut that gate short.
            f = self._prior_follow
            counted = np.where(f.valid, np.maximum(f.confidence, cfg.tracking.min_confidence), 0.0).astype(np.float32)
            return self._gate_to_boxes(Joints3D(f.points, counted, f.valid, f.reprojection_px), regions)
        if (cfg.heatmaps.source == "encoder" or not cfg.tracking.follow_encoder or not reported.valid.any()
                or "encoder_heatmaps" not in env):
            return reported
        kp = decode_keypoints(np.ascontiguousarray(env["encoder_heatmaps"], dtype=np.float32), cfg.decoder)
        uv = heatmap_to_model_pixels(kp.uv, self.grid, self.size)
        return self._gate_to_boxes(triangulate_joints(uv, kp.confidence, kp.valid, crops, cfg.joints3d), regions)

    def _gate_to_boxes(self, j3: Joints3D, regions: Regions) -> Joints3D:
        """Nobody stands outside the working volume, nor far from where the sweep looked."""
        margin = self.config.joints3d.max_outside_box_m
        return gate_to_box(gate_to_box(j3, regions.box, margin), self._volume_box, margin)

    # -------------------------------------------------------------- 3D
    def _joints_3d(self, env: dict, out: dict, blocks, heat: np.ndarray, kp: Keypoints2D, uv_model: np.ndarray,
                   crops: list[Camera], regions: Regions) -> Joints3D:
        cfg = self.config.joints3d
        self._prior_follow = None  # this pair's, set by _with_prior (someone is there) for _track_joints
        self._prior_check = (None, False)  # this pair's, set by _with_prior
        # the views' agreement, from the peaks the presence gate calls strong (phantom peaks of an empty room are
        # weaker), whatever the 3D method: it tells of the rig, not of the method
        pres = self.config.presence
        strong_peak = pres.threshold(self.config.heatmaps.source)  # the presence gate's peak threshold
        # one DLT of the peaks for the joints and the prior's inputs, in the crop cameras' kept terms
        solution = solve_two_view_peaks(uv_model, kp.confidence, kp.valid, crops, cfg,
                                        terms=self._crop_terms_for(crops).two_view)
        tri, self._agreement = triangulate_joints_checked(uv_model, kp.confidence, kp.valid, crops, cfg, strong_peak,
                                                          pres.min_joints, solution=solution)
        in_boxes = self._gate_to_boxes(tri, regions)  # the presence gate's
        # The floor check's feet are not box-gated (as the px figure is taken before the reprojection gate): a camera
        # panned far moves the whole triangulated person out of the working volume (8 degrees on the oracle: 3 m away
        # read as 4.8 m, the feet 0.7-0.8 m under the floor), and the box gates dropped exactly the joints that show it.
        # A joint far from the person's own body is dropped instead (a foot paired with the wrong peak lies metres
        # off), and someone must be there by the peaks (the presence gate, on those joints), not by the boxes.
        someone = tri if not pres.enabled else gate_presence(tri, pres.min_joints, strong_peak)
        near = near_the_body(someone, _FLOOR_BODY_M)
        self._lowest_foot = self._lowest_foot_m(near, kp, regions)
        # the cameras' inputs exchanged on a symmetric rig triangulate a mirror image (ghnerf_runtime.handedness):
        # read from the same strong, near joints as the feet, not the prior's (which always answers a person). Read on
        # every pair: whether it is several_people (whose figure _finish_pass drops) is not known yet, the torso check
        # below and the selector's after this return decide it
        strong_seen = near.valid & np.all(kp.valid & (kp.confidence >= strong_peak), axis=0)
        self._handedness = handedness(near.points, strong_seen)
        # two people's joints in one skeleton (two_people.mixed_torso), from the peaks strong in both views (a weak
        # peak may be noise's): asked whatever the 3D method, as the maps' second peaks are (_finish_pass)
        strong = tri.valid & np.all(kp.confidence >= strong_peak, axis=0)
        # each torso limb's excess over one body's, as the rule reads it (its part along the line of sight discounted:
        # the depth error grows with depth over baseline) and as measured (what the benchmarks print beside it)
        read = torso_excess(tri.points, strong, self._centres)
        self._torso_mixed = reads_as_two_people(read)
        self._torso_excess = np.stack([torso_excess(tri.points, strong), read])

        def centroid() -> Joints3D:
            g = self.grid
            depth = np.stack([scatter_block(out["depth"][i], blocks[i], g, g) for i in range(2)])
            return depth_centroid_joints(heat, depth, kp.uv, kp.confidence, kp.valid, crops, self.size, cfg)

        if cfg.method == "triangulate":
            if self.skeleton_prior is not None:
                # Someone there? Asked of the peaks (the presence gate's thresholds are the peaks'), never of
                # the prior, which was trained on people only and places a skeleton in any noise.
                if pres.enabled and not gate_presence(in_boxes, pres.min_joints, strong_peak).valid.any():
                    return Joints3D.missing(len(tri.valid), tri.reprojection_px.shape[-1])
                return self._with_prior(tri, uv_model, kp, crops, solution)
            if not cfg.single_view_fallback or tri.valid.all():
                return tri
            dc = centroid()
            fill = ~tri.valid & dc.valid
            return Joints3D(np.where(fill[:, None], dc.points, tri.points),
                            np.where(fill, 0.5 * dc.confidence, tri.confidence).astype(np.float32),
                            tri.valid | fill, tri.reprojection_px).sanitised()
        if cfg.method == "depth_centroid":
            return centroid()
        # volumetric
        key = (cfg.grid,) + tuple(np.round(regions.box, 4).ravel())
        if key not in self._grid_points:
            self._grid_points = {key: query_grid(regions.box, cfg.grid)}
        points, shape = self._grid_points[key]
        feeds = dict(env)
        feeds["tgt_P"] = target_projections(crops, self.size, self.size)
        feeds["points"] = np.ascontiguousarray(np.broadcast_to(points, (2,) + points.shape))
        q = self.session.run("query", feeds)
        return volumetric_joints(q["joint_heat"], points, shape, cfg)

    def _lowest_foot_m(self, tri: Joints3D, kp: Keypoints2D, regions: Regions) -> float | None:
        """The lower foot's height above the floor (:func:`~ghnerf_runtime.joints3d.lower_foot_m`: the median of its
        joints less ``joints3d.foot_standing_m``, a foot with ``_FLOOR_MIN_FOOT_JOINTS`` of them), of the joints
        triangulated from peaks strong in both views (the presence threshold) that both frames show well inside their
        edges (``_FLOOR_EDGE_FRAC``): not the prior's (it keeps placed feet near the floor, whatever the calibration),
        nor guesses at a frame's edge.
        ``None`` too unless the torso joints so triangulated stand ``_FLOOR_MIN_TORSO_M`` above that foot (their
        median height): a person upside down or lying is not standing on the floor with their feet (a window of
        handstands would otherwise read as a camera turned)."""
        strong = self.config.presence.threshold(self.config.heatmaps.source)
        seen = tri.valid & np.all(kp.valid & (kp.confidence >= strong), axis=0)
        feet = np.zeros(len(tri.valid), bool)
        feet[list(FLOOR_JOINTS)] = True
        feet &= seen
        for st, roi in zip(self._cams, regions.rois):
            idx = np.flatnonzero(feet)  # only the candidates are projected (8 of 25 at most)
            if not idx.size:
                return None
            cam, margin = st.camera, _FLOOR_EDGE_FRAC * roi.size
            uv = cam.project(tri.points[idx])[0]  # (a NaN uv: behind or off the lens)
            with np.errstate(invalid="ignore"):
                feet[idx] = ((uv[:, 0] >= margin) & (uv[:, 0] <= cam.width - 1 - margin)
                             & (uv[:, 1] >= margin) & (uv[:, 1] <= cam.height - 1 - margin))
        lowest = lower_foot_m(Joints3D(tri.points, tri.confidence, feet, tri.reprojection_px), FEET,
                              self.config.joints3d.foot_standing_m, _FLOOR_MIN_FOOT_JOINTS)
        torso = [j for j in _TORSO if seen[j]]
        if lowest is None or not torso or -sorted_median(tri.points[torso, 1]) - lowest < _FLOOR_MIN_TORSO_M:
            return None  # not seen on their feet (y down: a height is -y)
        return lowest

    def _with_prior(self, tri: Joints3D, uv_model: np.ndarray, kp: Keypoints2D, crops: list[Camera],
                    solution: TwoViewSolution | None = None) -> Joints3D:
        """The skeleton prior's joints: refined where triangulated, placed where hidden; a joint whose
        expected error exceeds ``max_prior_error_m`` is missing. Confidence: ``exp(-expected error /
        0.1 m)`` (0.7 at 35 mm, 0.37 at 100 mm), so it says how far off the joint may be. A skeleton further
        than ``max_prior_disagreement_m`` from ``tri`` gives ``tri`` instead. The box gates
        (``max_outside_box_m``) still apply after. ``solution``: the pair's solve of these peaks
        (:func:`~ghnerf_runtime.joints3d.solve_two_view_peaks`), which the prior's inputs reuse where their
        weights are the joints'."""
        est = self.skeleton_prior.estimate(uv_model, kp.confidence, kp.valid, [c.P for c in crops],
                                          self.config.joints3d.prior_flip_test,
                                          cameras=self._crop_terms_for(crops).prior,
                                          solutions=None if solution is None else [solution])
        # floored for the joints the gate keeps: past ~10.4 m of expected error the float32 score underflowed to 0,
        # and sanitised() dropped every such joint whatever the gate (max_prior_error_m may be up to 100 m)
        score = np.maximum(np.exp(-est.expected_error_m / _PRIOR_CONFIDENCE_SCALE_M), np.finfo(np.float32).tiny
                           ).astype(np.float32)

        def gated(max_error_m: float) -> Joints3D:
            keep = est.expected_error_m <= max_error_m
            return Joints3D(est.points, np.where(keep, score, 0.0), keep, tri.reprojection_px).sanitised()

        # The prior's expected error is its own guess, small also on poses it never learnt (lying, upside down),
        # where it answers a near-upright skeleton: a pair whose skeleton lies far from the well-triangulated
        # joints is reported as triangulated (docs/runtime.md, "The skeleton prior").
        limit = self.config.joints3d.max_prior_disagreement_m
        apart = disagreement_m(est.points, tri.points, tri.valid)
        fallback = limit > 0 and apart is not None and apart > limit
        self._prior_check = (apart, fallback)
        if fallback:
            self._prior_follow = tri  # someone is there (asked of the peaks before); the crop follows what is reported
            return tri
        self._prior_follow = gated(max(_PRIOR_FOLLOW_MAX_ERROR_M, self.config.joints3d.max_prior_error_m))
        return gated(self.config.joints3d.max_prior_error_m)

    # -------------------------------------------------------------- novel view
    def _novel_box(self, regions: Regions, j3: Joints3D) -> np.ndarray:
        """The subject seen in *this* pair when it has enough joints, else the sweep box."""
        if int(j3.valid.sum()) >= self.config.tracking.min_joints:
            pts = j3.points[j3.valid]
            m = self.config.tracking.box_margin_m
            return np.stack([pts.min(axis=0) - m, pts.max(axis=0) + m])
        return regions.box

    def _novel_camera(self, request: NovelViewRequest, box: np.ndarray) -> Camera:
        """The ``S x S`` camera of ``request``'s view cropped to ``box`` (whose centre is the subject's, the orbit's
        pivot when the rig's optical axes give none or cross away from it: ``novel_view.path``)."""
        full = request.camera
        if full is None:
            if self._between_pair is None:
                self._between_pair = tuple(st.upright_pinhole for st in self._cams)  # no view spinning between them
            cam_a, cam_b = self._between_pair
            pivot = novel_pivot(cam_a, cam_b, self.config.novel_view.path, np.mean(box, axis=0))
            # the line's camera is the rig's (fixed); an orbit's pivot follows the subject (along the axes, where
            # they fix it badly), so its cameras come and go
            key = (request.alpha, None if pivot is None else pivot.tobytes())
            if key not in self._between:
                if len(self._between) >= 16:
                    self._between.clear()
                self._between[key] = interpolate_camera(cam_a, cam_b, request.alpha, pivot=pivot)
            full = self._between[key]
        return novel_target(full, box, self.size, self.config.novel_view.crop_to_subject)

    def _render_novel(self, request: NovelViewRequest, env: dict, box: np.ndarray, timing: dict,
                      target: Camera | None = None, session: Any = None) -> NovelView:
        """The novel view (no overlay) of ``request`` cropped to ``box`` (``target``: its camera, when known;
        ``session``: what runs the graphs, default the estimator's)."""
        cfg = self.config.novel_view
        target = self._novel_camera(request, box) if target is None else target
        return render_novel_view(self.session if session is None else session, env, target, box, cfg,
                                 near_far_margin=self.config.tracking.near_far_margin_m,
                                 want_heat=cfg.heatmaps, timing=timing)

    def _start_novel(self, request: NovelViewRequest, env: dict, box: np.ndarray) -> _NovelJob:
        """Render the novel view in the worker thread (its camera is placed here, so that the proxy's depth in
        it can be cast while the worker renders)."""
        if self._worker is None:
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ghnerf-novel-view")
        target = self._novel_camera(request, box)
        runner = self.session.on_lanes() if self._novel_lanes else self.session

        def job(feeds: dict) -> tuple[NovelView, dict]:
            timing: dict[str, float] = {}
            return self._render_novel(request, feeds, box, timing, target, runner), timing

        return _NovelJob(target, self._worker.submit(job, dict(env)))

    def _proxy_inputs(self, p: "_Pass", camera: Camera) -> _ProxyInputs | None:
        """The body proxy of this pair's joints and its depth maps in the sources and in the view at ``camera``,
        as far as the painter, the blend and the matte read them; ``None`` when none of them runs (no joints)."""
        t = time.perf_counter()
        body = proxy_body(p.j3.points, p.j3.valid)
        if body.empty:
            return None
        cfg = self.config.novel_view
        paint = self.novel_painter is not None and not (
            angle_from_sources_deg(camera, p.crops, p.j3.points, p.j3.valid) < cfg.painter_min_angle_deg)
        if not (paint or cfg.proxy_blend or cfg.matte):
            return None
        rgb = model_input_to_rgb(p.env["images"], self.contract.normalisation) if paint or cfg.proxy_blend else None
        # the painter and the blend read the proxy's depth in the sources; the painter and the matte read it
        # in the whole view (the blend alone casts only the region's box)
        src_depth = [proxy_depth(body, c) for c in p.crops] if paint or cfg.proxy_blend else None
        depth = proxy_depth(body, camera) if paint or cfg.matte else None
        return _ProxyInputs(body, paint, rgb, src_depth, depth, 1e3 * (time.perf_counter() - t))

    def _over_proxy(self, nv: NovelView, p: "_Pass", timing: dict, inputs: _ProxyInputs) -> NovelView:
        """The view's subject repainted by the learnt painter (``novel_view.painter``, on views at least
        ``painter_min_angle_deg`` from the nearest source camera), then recoloured from the
        source crops (``novel_view.proxy_blend``), both over the body proxy of this pair's joints and only
        where the rendered picture shows the subject (or the proxy, for the painter), then faded to the
        background away from the proxy (``novel_view.matte``). ``inputs`` (:meth:`_proxy_inputs`, of
        ``nv.camera``): the proxy and its depth maps, whose time counts in the first stage that runs."""
        t = time.perf_counter() - 1e-3 * inputs.ms
        cfg = self.config.novel_view
        body, rgb, src_depth, depth = inputs.body, inputs.rgb, inputs.src_depth, inputs.depth
        region = subject_region(nv.image, self.contract.background, cfg.silhouette_min_diff)  # the picture's own
        image = nv.image
        if inputs.paint:
            image, _ = self.novel_painter.repaint(image, nv.camera, body, p.crops, rgb, p.j3.points, p.j3.valid,
                                                  cfg.proxy_tolerance_m, region=region, source_depth=src_depth,
                                                  depth=depth)
            timing[NOVEL_PAINT_STAGE] = 1e3 * (time.perf_counter() - t)
            t = time.perf_counter()
        if cfg.proxy_blend:
            image = proxy_blend(image, nv.camera, body, p.crops, rgb, cfg.proxy_tolerance_m, region=region,
                                max_angle_deg=cfg.proxy_max_angle_deg, source_depth=src_depth, depth=depth).image
            timing[NOVEL_PROXY_STAGE] = 1e3 * (time.perf_counter() - t)
            t = time.perf_counter()
        if cfg.matte:
            image = proxy_matte(image, nv.camera, depth, region, self.contract.background, cfg.matte_margin_m,
                                cfg.matte_feather_m, joints=p.j3.points, valid=p.j3.valid).image
            timing[NOVEL_MATTE_STAGE] = 1e3 * (time.perf_counter() - t)
        return NovelView(image, nv.camera, nv.depth, nv.heat, nv.rays)

    def _compose_novel(self, request: NovelViewRequest, nv: NovelView, j3: Joints3D, timing: dict) -> NovelView:
        """The requested overlay on the rendered view (the pair's own joints)."""
        t = time.perf_counter()
        image = nv.image
        if request.overlay == "skeleton":
            image = skeleton_overlay(image, nv.camera, j3.points, j3.valid)
        elif request.overlay == "heatmap" and nv.heat is not None:
            image = heatmap_overlay(image, nv.heat)
        timing["novel_compose"] = timing.get("novel_compose", 0.0) + 1e3 * (time.perf_counter() - t)
        return NovelView(image, nv.camera, nv.depth, nv.heat, nv.rays)


def _session_plan(config: EstimatorConfig) -> tuple[EstimatorConfig, tuple[str, ...]]:
    """``config`` as the model folder's skeleton prior leaves it, and the graphs it runs: the keypoint-only ``human``
    graph when the folder has one. Decided from the folder's file names, before anything is loaded."""
    from ghnerf_runtime.session import ModelSession  # local: keeps this module importable without a model

    config = config.beside_prior(ModelSession.has_skeleton_prior(config.session))
    return config, config.required_graphs(ModelSession.has_graph_file(config.session, "human"))


def load_session(config: EstimatorConfig):
    """The :class:`~ghnerf_runtime.session.ModelSession` of ``config.session`` with only the graphs the
    configuration runs: the keypoint-only ``human`` graph when the model folder has one."""
    from ghnerf_runtime.session import ModelSession

    config, graphs = _session_plan(config)
    return ModelSession.load(config.session, graphs, skeleton_prior=config.joints3d.uses_skeleton_prior(True),
                             novel_painter=config.novel_view.uses_painter(True))


def check_model_files(config: EstimatorConfig) -> Path:
    """That the model folder of ``config.session`` holds the files :func:`load_session` and the estimator would
    need, loading none (``ghnerf-run --validate-config``): it is a folder, it has a file for each graph the settings
    run (:meth:`~ghnerf_runtime.session.ModelSession.check_files`), and the skeleton prior or painter they turn
    ``on``. Whether the files load and serve the settings is for the run (or ``ghnerf-daemon --validate-config``).

    :returns: the resolved model folder.
    :raises ModelError: naming the folder or the file, and the setting that needs a missing one.
    """
    from ghnerf_runtime.session import ModelSession

    config, graphs = _session_plan(config)
    folder = ModelSession.check_files(config.session, graphs)
    if config.joints3d.skeleton_prior == "on" and not ModelSession.has_skeleton_prior(config.session):
        raise ModelError(f"joints3d.skeleton_prior = 'on' but the folder has no {PRIOR_FILE} (make one with python "
                         "-m training.skeleton_prior, or set joints3d.skeleton_prior = 'auto' or 'off')",
                         path=str(folder))
    nv = config.novel_view
    if nv.enabled and nv.painter == "on" and NovelPainter.find(folder, config.session.precision) is None:
        raise ModelError(f"novel_view.painter = 'on' but the folder has no {PAINTER_FILE} (make one with python -m "
                         "training.learnt_fill export, or set novel_view.painter = 'auto' or 'off')", path=str(folder))
    return folder
