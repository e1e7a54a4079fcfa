"""Two people in view: the ``several_people`` flag and the subject whose joints a flagged pair reports.

Each view's heatmap of a joint may hold both people's peaks, the decoded one (the stronger) and the runner-up; a
pair is flagged where enough joints show twice in both views (:meth:`SubjectSelector.several_people`), or, by one
view alone, one person behind the other (:meth:`SubjectSelector.behind_view`). A flagged pair's subject is then
found among the four pairings of each joint's peaks across the views: those nearest the track, or without a track
the person ``joints3d.pick_subject`` names, or the one a view sees in front
(:meth:`SubjectSelector.keep_tracked_subject`); and its calibration figures are taken from the subject's own
pairings, or both people's where those give none (:meth:`SubjectSelector.subject_figures`,
:meth:`SubjectSelector.matched_px`, :meth:`SubjectSelector.matched_foot`). The geometry of two bodies (the split,
the pick, one skeleton) is :mod:`ghnerf_runtime.two_people`'s; docs/two-people.md says why each rule is there.

The :class:`~ghnerf_runtime.estimator.Estimator` holds one :class:`SubjectSelector` and keeps the track and its
hold (whether the track follows a flagged pass's subject): its crop turns swap the tracker, and the hold goes with
it, so both come in with each call.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ghnerf_runtime.body25 import LIMBS
from ghnerf_runtime.config import EstimatorConfig, Joints3DConfig
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig
from ghnerf_runtime.geometry.triangulation import TwoViewCameras, TwoViewSolution
from ghnerf_runtime.joints3d import Joints3D, ViewAgreement, gate_presence, near_the_body, solve_two_view_peaks, \
    triangulate_joints, triangulate_joints_checked
from ghnerf_runtime.keypoints import Keypoints2D, heatmap_to_model_pixels
from ghnerf_runtime.tracking import Regions, Track
from ghnerf_runtime.two_people import (PAIRINGS, attached, centre_of, floor_xz, held_apart, matched_errors, one_body,
                                       one_side_each, one_skeleton, pick_person, split_people)

__all__ = ["SubjectSelector", "STILL_SEVERAL_MIN_JOINTS", "guessed_joints", "joints_shown_twice",
           "one_skeleton_each_side", "picks_subject"]

#: A pass following a ``several_people`` pass's subject stays flagged with this many joints shown twice in both
#: views (:meth:`SubjectSelector.several_people`).
STILL_SEVERAL_MIN_JOINTS = 1
#: Two people's floor figure (:meth:`SubjectSelector.matched_foot`) leaves out a joint (foot or torso) whose peak lies
#: within this many heatmap cells of its map's edge in either view: the crop frames the subject or the working volume,
#: not each person, and a joint beyond the crop's edge puts its maximum on the map's last cells (on the oracle, a
#: person 4 m off beside one 2.5 m off: the far one's feet 1.9 cells past view 1's edge peaked on its last cell at
#: 0.13-0.46, and paired with view 0's peaks read 0.04-0.06 m up on the true rig, where each person's own feet read
#: within 0.005 m: tests/ghnerf_runtime/test_two_people.py).
_CROP_EDGE_CELLS = 2.0


def joints_shown_twice(kp: Keypoints2D, ratio: float) -> int:
    """How many joints' maps show, in *both* views, a second peak (the decoder's ``kp.runner_up``) of at
    least ``ratio`` of the first: what ``joints3d.second_person_min_joints`` is compared with (the
    ``several_people`` check; ``ratio`` is ``joints3d.second_person_ratio``)."""
    twice = kp.valid & (kp.runner_up >= ratio * kp.confidence)  # (2, J)
    return int(np.count_nonzero(twice.all(axis=0)))


def _paired(*options: np.ndarray) -> tuple[np.ndarray, ...]:
    """Each ``(option, view, J, ...)`` array as the two views' ``(view, 4 * J, ...)``: the four pairings
    (:data:`~ghnerf_runtime.two_people.PAIRINGS`) one after the other, for one triangulation of them all."""
    J = options[0].shape[2]
    return tuple(np.stack([opt[PAIRINGS[:, v], v].reshape((len(PAIRINGS) * J,) + opt.shape[3:]) for v in range(2)])
                 for opt in options)


def picks_subject(cfg: Joints3DConfig) -> bool:
    """Whether a ``several_people`` pass without a track reports one of the two people (``pick_subject``, with
    the triangulation: :meth:`SubjectSelector.keep_tracked_subject`)."""
    return cfg.method == "triangulate" and cfg.pick_subject != "none"


def guessed_joints(subject: Joints3D, kp: Keypoints2D) -> np.ndarray:
    """A flagged pair's joints that :meth:`Estimator._finish_pass` does not report, ``(J,)``: of those no pairing of the
    subject's found (``subject``, :meth:`SubjectSelector.keep_tracked_subject`), each whose map shows a peak in a view
    (``kp``, the pass's decoded peaks): that peak is someone's and not the subject's (else a pairing would hold it), the
    other person's or both people's merged, the subject's own hidden there; the skeleton prior's place for it (fed none
    of its peaks), or the pass's answer near the track, is a guess beside the other person (two people 0.6 m apart
    through the shipped model: the subject's side facing the other, 112-314 mm off; docs/two-people.md, "Fewer, right
    joints"). A joint no view shows a peak of is hidden from both cameras: the prior places it from the subject's body,
    as for one person, where it hangs from a joint the subject's pairings found (a heel from its ankle); one hanging
    from nothing found lay 186 mm off there (the left heel, its foot's peaks the other person's)."""
    hangs = np.zeros(len(subject.valid), bool)
    for a, b in LIMBS:
        hangs[a] |= bool(subject.valid[b])
        hangs[b] |= bool(subject.valid[a])
    return ~subject.valid & (kp.valid.any(axis=0) | ~hangs)


def one_skeleton_each_side(joints: np.ndarray, found: np.ndarray) -> np.ndarray:
    """Of a flagged pair's subject's ``found`` joints (``joints``, ``(J, 3)``), those that make one skeleton
    (:func:`~ghnerf_runtime.two_people.one_skeleton`) less a limb joint at its twin's place that its own side does
    not hold where the twin's does (:func:`~ghnerf_runtime.two_people.one_side_each`; docs/two-people.md, "One
    peak, two sides")."""
    return one_side_each(joints, one_skeleton(joints, found))


class SubjectSelector:
    """A pair's two people: the flag, the subject's joints and peaks, and a flagged pair's calibration figures.

    Args:
        config: the estimator's resolved configuration (``joints3d``, ``presence``, ``heatmaps.source``).
        rig: the calibrated rig (its two cameras' centres and the working volume, for the pick).
        grid: the heatmaps' side (cells); size: the model's input side (pixels).
        gate_to_boxes: the estimator's box gates (the crop's box and the working volume), which the subject's
            pairings pass as one person's joints do.
        lowest_foot_m: the estimator's floor check (joints, their peaks, the regions -> the lower foot's height).
        floor_body_m: how far across the floor a foot joint may lie from its person's median (the floor check's
            ``_FLOOR_BODY_M``).
    """

    def __init__(self, config: EstimatorConfig, rig: Rig, grid: int, size: int,
                 gate_to_boxes: Callable[[Joints3D, Regions], Joints3D],
                 lowest_foot_m: Callable[[Joints3D, Keypoints2D, Regions], float | None], floor_body_m: float) -> None:
        self.config = config
        self.rig = rig
        self.grid = grid
        self.size = size
        self._gate_to_boxes = gate_to_boxes
        self._lowest_foot_m = lowest_foot_m
        self._floor_body_m = floor_body_m

    def several_people(self, kp: Keypoints2D, held: bool) -> bool:
        """Two people in view: at least ``second_person_min_joints`` joints whose maps show a second peak of at
        least ``second_person_ratio`` of the first in both views. Each view's peak is then whichever person's is
        stronger there, and the two views need not pick the same person; the triangulation of a mixed pair often
        passes the reprojection gate (people side by side: the error lies along the epipolar lines), so the maps
        are what tells. On one person no joint came near it in both views (docs/two-people.md).

        Once a pass is flagged, the passes that follow its subject stay flagged while any joint shows twice
        (:data:`STILL_SEVERAL_MIN_JOINTS`): the subject's own crop shows fewer of the other person's joints (on the
        oracle 2 to 5 in the passes that fell below 6), and a pass not flagged lets the other's peaks into the
        track. One person is never flagged, so never held. A track that follows a pass flagged by one view alone
        (:meth:`behind_view`) is held by that rule instead. ``held``: the track follows a pass flagged in both views
        (the estimator keeps that with the track, which its crop turns swap)."""
        cfg = self.config.joints3d
        if cfg.second_person_min_joints == 0:
            return False
        twice = joints_shown_twice(kp, cfg.second_person_ratio)
        return twice >= (STILL_SEVERAL_MIN_JOINTS if held else cfg.second_person_min_joints)

    def behind_view(self, kp: Keypoints2D, held_view: int | None) -> int | None:
        """One person behind the other as one camera sees them (docs/two-people.md, "One person behind the other"):
        the view that shows one peak where the other shows two, or None. Where the pair shows fewer than
        ``second_person_min_joints`` joints twice in both views, a view showing ``behind_min_joints`` twice by itself
        (the other view then the one peak's) makes the pair ``several_people`` all the same: the hidden person's
        peaks are behind the other's in one view, beside them in the other. Off by default (``behind_min_joints``
        0): one person alone through the shipped model reaches 6 on some pairs (docs/two-people.md). Passes
        following such a pass's subject stay so while that view shows any joint twice
        (:data:`STILL_SEVERAL_MIN_JOINTS`). Asked of tracked passes that :meth:`several_people` did not flag
        (:meth:`Estimator._finish_pass`). ``held_view``: the one-peak view of the pass flagged by one view alone
        whose subject the track follows, else None."""
        cfg = self.config.joints3d
        if cfg.behind_min_joints == 0 or cfg.second_person_min_joints == 0 or \
                joints_shown_twice(kp, cfg.second_person_ratio) >= cfg.second_person_min_joints:
            return None
        per_view = np.count_nonzero(kp.valid & (kp.runner_up >= cfg.second_person_ratio * kp.confidence), axis=-1)
        if held_view is not None:
            seen, need = 1 - held_view, STILL_SEVERAL_MIN_JOINTS
        else:
            seen, need = int(np.argmax(per_view)), cfg.behind_min_joints
        return 1 - seen if per_view[seen] >= need else None

    def keep_tracked_subject(self, j3: Joints3D, kp: Keypoints2D, uv_model: np.ndarray, crops: list[Camera],
                             regions: Regions, track: Track | None, track_unsorted: bool,
                             cold_several: bool | None = None, behind: int | None = None, *,
                             solution: TwoViewSolution | None = None
                             ) -> tuple[Joints3D, tuple[Keypoints2D, np.ndarray] | None, Joints3D]:
        """Of a ``several_people`` pair's joints, those within ``max_track_step_m`` of the tracked subject's place
        for them; without a track, one of the two people's (:meth:`_picked_subject`; with ``pick_subject: none``
        or another 3D method than the triangulation, none: whose joints would they be?). Returns them; where the
        pairings of peaks and runner-ups gave joints (:meth:`_tracked_candidates`), the peaks each view's 2D
        joints come from (a :class:`Keypoints2D` and its model pixels), else ``None`` (the decoded peaks); and
        the subject's joints that the peaks gave, alone (those pairings'; the first value's other joints are
        ``j3``'s, with the skeleton prior the prior's fed both people's peaks), which the presence gate counts with
        the prior as it counts the reported joints without it, whose peaks alone the prior is then fed
        (:meth:`Estimator._subject_prior`), and which give the calibration figures (:meth:`subject_figures`).
        ``cold_several`` (this pass refines this pair's cold pass, :meth:`Estimator._finish_pass`; where the subject is
        picked): ``False``, the track is a cold pass's that did not tell two people apart (both people's joints,
        mixed): picked as without a track (nobody with ``pick_subject: none``: the mixed track is not followed);
        ``True``, the cold pass picked the subject from its coarse crop: split
        again on this pass's finer one, and the person nearer the track's centre is the subject (the cold split
        may have given a joint wrongly). ``behind``: the view that shows one peak where the other shows two
        (:meth:`behind_view`): picked as without a track, the person that view sees is the subject
        (:meth:`_seen_subject`); a tracked pass keeps the pairings nearest the track as for any flagged pass (two
        of them are that view's one peak with each of the other view's two). ``track``: the tracked subject (None
        without one); ``track_unsorted``: it is a cold pass's that showed maybe two people too small to tell apart.
        ``solution``: :meth:`solve_pairings` of this pass, computed earlier (the answer is the same without it)."""
        cfg = self.config.joints3d
        picks = picks_subject(self.config.joints3d)
        # a cold pass's track not flagged (cold_several False: this pair's, refined; with refine_cold_start off, the
        # pair before's) is both people's joints mixed: nobody's to follow, whether or not a subject is picked
        # (followed, it streamed a skeleton of both people's joints and of points between them as the subject, and
        # measured its feet: docs/two-people.md, "A track of both people's joints")
        unsorted = cold_several is False or (cold_several is None and track_unsorted)
        if track is None or unsorted or (picks and cold_several is not None):
            none = Joints3D.missing(len(j3.valid), j3.reprojection_px.shape[-1])
            if not picks:
                return none, None, none
            if behind is not None:
                return self._seen_subject(none, kp, uv_model, crops, regions, behind, solution)
            # (no track: a cold pass retried after a several_people tracked pass, picked as without a track)
            near = (centre_of(track.joints[None], np.where(track.valid, 0, -1)) if cold_several and track is not None
                    else None)
            # a refining pass flagged where its cold pass, on the working volume's coarser crop, was not: nothing
            # to split there is one person's peaks with a few of the other's (_one_shown)
            return self._picked_subject(none, kp, uv_model, crops, regions, near, solution,
                                        one_shown=cold_several is False)
        step = np.linalg.norm(j3.points - track.joints, axis=-1)
        near = track.valid & (step <= cfg.max_track_step_m)
        kept = Joints3D(j3.points, j3.confidence, j3.valid & near, j3.reprojection_px).sanitised()
        if cfg.method != "triangulate":  # the 3D joint is no peaks' triangulation (nor the prior's)
            return kept, None, kept
        return self._tracked_candidates(kept, kp, uv_model, crops, regions, track.joints, track.valid, solution)

    def solve_pairings(self, kp: Keypoints2D, uv_model: np.ndarray, crops: list[Camera], *,
                       terms: TwoViewCameras | None = None) -> TwoViewSolution:
        """One two-view solve of each joint's four pairings of the two views' peaks (:meth:`_pairings`' peaks and
        weights), before any gate: :meth:`keep_tracked_subject` (through the box gates) and :meth:`both_people`
        (before them) check the same solve, so the estimator solves a flagged pass's pairings once and passes it
        to both (``solution=``). ``terms``: the crop cameras' kept
        :class:`~ghnerf_runtime.geometry.triangulation.TwoViewCameras` (the estimator's)."""
        return solve_two_view_peaks(*_paired(*self._peak_options(kp, uv_model)), crops, self.config.joints3d,
                                    terms=terms)

    def _pairings(self, kp: Keypoints2D, uv_model: np.ndarray, crops: list[Camera], regions: Regions,
                  solution: TwoViewSolution | None = None) -> tuple[Joints3D, np.ndarray, np.ndarray, np.ndarray]:
        """Each joint's four pairings of the two views' peaks (:data:`~ghnerf_runtime.two_people.PAIRINGS`: the
        decoded peak or the runner-up in view 0 with either in view 1), triangulated through the usual gates
        (reprojection, ray angle, boxes): the ``(4 * J)`` joints, pairing after pairing, and each option's model
        pixels, values and validity ``(option, view, J, ...)``. A runner-up exists only where the map shows a
        second peak above the decoder's threshold: another region's, or one of the peak's own region past a valley
        (:data:`~ghnerf_runtime.keypoints.RUNNER_UP_DIP`). ``solution``: :meth:`solve_pairings` of these peaks
        (used where it solved them; solved here otherwise)."""
        uv_opt, conf_opt, valid_opt = self._peak_options(kp, uv_model)
        tri = self._gate_to_boxes(triangulate_joints(*_paired(uv_opt, conf_opt, valid_opt), crops,
                                                     self.config.joints3d, solution=solution), regions)
        return tri, uv_opt, conf_opt, valid_opt

    def _peak_options(self, kp: Keypoints2D, uv_model: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each view's two options of each joint, the decoded peak and the runner-up: their model pixels, values and
        validity, ``(option, view, J, ...)``."""
        ru_model = heatmap_to_model_pixels(kp.runner_up_uv, self.grid, self.size)
        uv_opt = np.stack([uv_model, ru_model])  # (peak | runner-up, view, J, 2)
        conf_opt = np.stack([kp.confidence, kp.runner_up])
        valid_opt = np.stack([kp.valid, kp.runner_up > 0])  # a runner-up is a second peak above the threshold
        return uv_opt, conf_opt, valid_opt

    def both_people(self, kp: Keypoints2D, uv_model: np.ndarray, crops: list[Camera], *,
                    solution: TwoViewSolution | None = None) -> tuple[tuple, ViewAgreement]:
        """A ``several_people`` pair's four pairings of each joint (:meth:`_pairings`' tuple) triangulated through
        the reprojection gate but not the box gates, and their agreement before the gate, of the peaks at least the
        presence threshold in both views: what both people's calibration figures are taken from where the
        subject's own pairings give none (:meth:`matched_px`, :meth:`matched_foot`). ``solution``:
        :meth:`solve_pairings` of these peaks (used where it solved them; solved here otherwise)."""
        strong = self.config.presence.threshold(self.config.heatmaps.source)
        uv_opt, conf_opt, valid_opt = self._peak_options(kp, uv_model)
        tri, agreement = triangulate_joints_checked(*_paired(uv_opt, conf_opt, valid_opt), crops,
                                                    self.config.joints3d, strong, 1, solution=solution)
        return (tri, uv_opt, conf_opt, valid_opt), agreement

    def _tracked_candidates(self, kept: Joints3D, kp: Keypoints2D, uv_model: np.ndarray, crops: list[Camera],
                            regions: Regions, track_joints: np.ndarray, track_valid: np.ndarray,
                            solution: TwoViewSolution | None = None
                            ) -> tuple[Joints3D, tuple[Keypoints2D, np.ndarray] | None, Joints3D]:
        """A ``several_people`` pair's joints from whichever peaks are the tracked subject's: each view's map of a
        joint holds both people's peaks, the decoded one (the stronger) and the runner-up, so the subject's joint
        is one of the four pairings across the views (:meth:`_pairings`), and the one nearest the track's joint,
        within ``max_track_step_m``, is reported; a joint with none keeps ``kept``'s answer (the skeleton prior's
        or the depth centroid's, when they gave it). The third value is the found joints alone
        (:meth:`keep_tracked_subject`)."""
        cfg = self.config.joints3d
        J = len(track_joints)
        pairs = self._pairings(kp, uv_model, crops, regions, solution)
        points, valid = pairs[0].points.reshape(4, J, 3), pairs[0].valid.reshape(4, J)
        dist = np.linalg.norm(points - track_joints, axis=-1)
        ok = valid & track_valid & (dist <= cfg.max_track_step_m)
        best, found = np.argmin(np.where(ok, dist, np.inf), axis=0), ok.any(axis=0)
        lost = ~found & ~kept.valid
        if lost.any() and found.any():
            # a joint missing from the track (the previous pair's), or moved further than the step: the subject's is
            # the pairing that the split (two_people.split_people) gives the person who has the joints found near
            # the track
            people = split_people(points, valid)
            agree = [int(np.count_nonzero((p == best) & found)) for p in people]
            who = int(np.argmax(agree))
            if agree[who] > agree[1 - who]:
                # only where it hangs from a joint found near the track (a sparse split may misgive a joint), and
                # not nearer its found twin than the torso holds them (that twin's peak read again: a left
                # shoulder at the right one's place hangs within its bone's reach of the neck as well)
                candidates, tracked = points[np.maximum(people[who], 0), np.arange(J)], points[best, np.arange(J)]
                add = (lost & (people[who] >= 0) & attached(candidates, tracked, found)
                       & held_apart(candidates, tracked, found))
                best, found = np.where(add, people[who], best), found | add
        # a pairing off its limbs' reach of the subject's other joints is not the subject's (one view's peak of each
        # person, or the other's in both, near a track's joint gone astray): two_people.one_skeleton; nor one at
        # its twin's place that its own side does not hold (one peak read as both sides): two_people.one_side_each
        found = one_skeleton_each_side(points[best, np.arange(J)], found)
        return self._from_pairings(kept, kp, pairs, best, found)

    def _picked_subject(self, kept: Joints3D, kp: Keypoints2D, uv_model: np.ndarray, crops: list[Camera],
                        regions: Regions, near: np.ndarray | None = None, solution: TwoViewSolution | None = None,
                        one_shown: bool = False) -> tuple[Joints3D, tuple[Keypoints2D, np.ndarray] | None, Joints3D]:
        """A ``several_people`` pair without a track: the pairings (:meth:`_pairings`) split into two people
        (:func:`~ghnerf_runtime.two_people.split_people`), and the one ``joints3d.pick_subject`` names
        (:func:`~ghnerf_runtime.two_people.pick_person`) of those with enough joints to pass the presence gate
        (``presence.min_joints``) is reported, as :meth:`_tracked_candidates` reports the tracked subject's; the
        track then follows that person. Nobody (``kept``) where neither has enough. ``near`` (a floor point,
        x and z): the person whose centre is nearer it instead of the rule's. ``one_shown``: where the split finds no
        two people, the one person the decoded peaks show (:meth:`_one_shown`) instead of nobody."""
        J = len(kept.valid)
        pairs = self._pairings(kp, uv_model, crops, regions, solution)
        points = pairs[0].points.reshape(4, J, 3)
        people = split_people(points, pairs[0].valid.reshape(4, J))
        pres = self.config.presence
        need = pres.min_joints if pres.enabled else 1
        if one_shown and (people < 0).all():  # nothing to split: one person's peaks, the other's hidden or merged
            return self._one_shown(kept, kp, pairs, need)
        centres = [centre_of(points, p) if np.count_nonzero(p >= 0) >= need else None for p in people]
        below = floor_xz(0.5 * (self.rig.pair[0].center + self.rig.pair[1].center))  # the cameras' midpoint
        towards = floor_xz(self.rig.volume.center) - below
        if not np.linalg.norm(towards) > 1e-6:  # the volume centred above the cameras: the rig's forward, z
            towards = np.array([0.0, 1.0])
        if near is not None:
            away = [np.inf if c is None else float(np.linalg.norm(c - near)) for c in centres]
            who = int(np.argmin(away)) if np.isfinite(min(away)) else None
        else:
            who = pick_person(centres, below, towards, self.config.joints3d.pick_subject)
        if who is None:
            return kept, None, Joints3D.missing(J, kept.reprojection_px.shape[-1])
        best = np.maximum(people[who], 0)
        # the split gives a joint to the person it hangs nearest, within MAX_LIMB_M: held to each limb's own length,
        # and one peak is not read as both sides' joints
        return self._from_pairings(kept, kp, pairs, best,
                                   one_skeleton_each_side(points[best, np.arange(J)], people[who] >= 0))

    def _one_shown(self, kept: Joints3D, kp: Keypoints2D, pairs: tuple, need: int
                   ) -> tuple[Joints3D, tuple[Keypoints2D, np.ndarray] | None, Joints3D]:
        """A pass refining a cold pass not flagged, flagged itself, whose pairings hold no joint twice
        (``split_people`` has nobody to tell apart): flagged by its torso (``two_people.mixed_torso``), each view's
        peaks are one person's but for a few joints where a view drew the other's instead, which lie off that
        person's limbs (the torso's more than a limb's reach). The decoded peaks' joints that make one skeleton
        (:func:`one_skeleton_each_side`) are the subject's; nobody (``kept``) with fewer than ``need``. Before
        session 66 such a pass reported nobody and dropped its track, so with a person a metre behind the subject
        along one camera's line of sight every pair started cold again (docs/two-people.md, "Anyone else near?")."""
        J = len(kept.valid)
        decoded = pairs[0].points.reshape(4, J, 3)[0]  # PAIRINGS[0]: the decoded peak in both views
        found = one_skeleton_each_side(decoded, pairs[0].valid.reshape(4, J)[0])
        if np.count_nonzero(found) < need:
            return kept, None, Joints3D.missing(J, kept.reprojection_px.shape[-1])
        return self._from_pairings(kept, kp, pairs, np.zeros(J, int), found)

    def _seen_subject(self, kept: Joints3D, kp: Keypoints2D, uv_model: np.ndarray, crops: list[Camera],
                      regions: Regions, behind: int, solution: TwoViewSolution | None = None
                      ) -> tuple[Joints3D, tuple[Keypoints2D, np.ndarray] | None, Joints3D]:
        """One person behind the other in view ``behind`` (:meth:`behind_view`) and no track: the person that view
        sees is reported, as :meth:`_picked_subject` reports the picked one. Its one peak of a joint is theirs (the
        other's is hidden behind them, or merged with theirs), so their joint is that peak paired with one of the
        other view's two, both on its ray: where one pairing passes the gates (:meth:`_pairings`; the other, the
        hidden person's peak with the seen one's, mostly fails the reprojection gate) that one, where both do the
        nearer that view's camera (the other lies about as far off as the hidden person); then only the joints that
        make one body (:func:`~ghnerf_runtime.two_people.one_body`: where the other view's two peaks merged, its one
        peak may be the hidden person's, and the pairing lies at their joint). The split of two people
        (:func:`~ghnerf_runtime.two_people.split_people`) has little to work on here: the pairings with the other
        person's peak in both views are missing. Nobody (``kept``) with fewer than ``presence.min_joints`` joints.
        ``pick_subject`` is not asked: the hidden person's joints would be triangulated from the seen one's peak."""
        J = len(kept.valid)
        pairs = self._pairings(kp, uv_model, crops, regions, solution)
        points, valid = pairs[0].points.reshape(4, J, 3), pairs[0].valid.reshape(4, J)
        mine = np.flatnonzero(PAIRINGS[:, behind] == 0)  # that view's peak with either of the other view's
        depth = np.linalg.norm(points[mine] - self.rig.pair[behind].center, axis=-1)
        best = mine[np.argmin(np.where(valid[mine], depth, np.inf), axis=0)]
        # where the other view's two peaks merged, the one pairing may be the hidden person's peak with the seen
        # one's, lying at the hidden person's joint: its limbs break there (two_people.one_body)
        found = one_body(points[best, np.arange(J)], valid[mine].any(axis=0))
        pres = self.config.presence
        if np.count_nonzero(found) < (pres.min_joints if pres.enabled else 1):
            return kept, None, Joints3D.missing(J, kept.reprojection_px.shape[-1])
        return self._from_pairings(kept, kp, pairs, best, found)

    def _from_pairings(self, kept: Joints3D, kp: Keypoints2D, pairs: tuple, best: np.ndarray, found: np.ndarray
                       ) -> tuple[Joints3D, tuple[Keypoints2D, np.ndarray] | None, Joints3D]:
        """The subject's joints: pairing ``best[j]`` of :meth:`_pairings` where ``found``, ``kept``'s elsewhere;
        each view's 2D joint is the peak the joint was triangulated from, with that peak's value (the decoded peak
        where the joint kept ``kept``'s answer); and the found joints alone. ``None`` for the peaks where nothing
        was found."""
        tri, uv_opt, conf_opt, valid_opt = pairs
        J = len(kept.valid)
        if not found.any():
            return kept, None, Joints3D.missing(J, kept.reprojection_px.shape[-1])
        j = np.arange(J)
        points = tri.points.reshape(4, J, 3)
        j3 = Joints3D(np.where(found[:, None], points[best, j], kept.points),
                      np.where(found, tri.confidence.reshape(4, J)[best, j], kept.confidence).astype(np.float32),
                      found | kept.valid,
                      np.where(found[:, None], tri.reprojection_px.reshape(4, J, -1)[best, j], kept.reprojection_px))
        # each view's option of the chosen pairing (the decoded peak where a joint kept its old answer)
        opt = np.where(found, PAIRINGS[best].T, 0)  # (2, J)
        v = np.arange(2)[:, None]
        chosen = Keypoints2D(np.where(opt[..., None] == 1, kp.runner_up_uv, kp.uv),
                             conf_opt[opt, v, j], valid_opt[opt, v, j], kp.runner_up, kp.runner_up_uv)
        peaks = Joints3D(j3.points, np.where(found, j3.confidence, 0.0).astype(np.float32), found, j3.reprojection_px)
        return j3.sanitised(), (chosen, uv_opt[opt, v, j]), peaks.sanitised()

    def subject_figures(self, subject: Joints3D, chosen: tuple[Keypoints2D, np.ndarray] | None,
                        crops: list[Camera], regions: Regions, *, terms: TwoViewCameras | None = None
                        ) -> tuple[float | None, float | None]:
        """A ``several_people`` pair's calibration figures (``reprojection_px_median``, ``lowest_foot_m``) from the
        reported subject's own pairings (``subject``, the found joints, and ``chosen``, each view's peak they were
        triangulated from: :meth:`_from_pairings`), by the one-person rules (the presence threshold in both views,
        ``presence.min_joints`` joints for the px figure, the frames' edges for the feet). Only joints whose maps
        show two peaks apart in both views count: where a view shows one, it may be the other person's (the
        subject's hidden) or both people's merged. ``(None, None)`` where nobody was picked or tracked (the split
        failed, ``pick_subject: none``, or the 3D method is not the triangulation: ``chosen`` is ``None``).

        The px figure differs from one person's: the pairings passed ``joints3d.max_reprojection_px`` to be chosen
        (:meth:`_pairings`), so a joint past that gate is not measured; a camera turned that far reports nobody
        and gives no figure here, and the pair's px figure is then both people's peaks' (:meth:`matched_px`), as
        one person's pair still gives one (docs/calibration.md). ``terms``: the crop cameras' kept
        :class:`~ghnerf_runtime.geometry.triangulation.TwoViewCameras` (the estimator's)."""
        if chosen is None or not subject.valid.any():
            return None, None
        kp, uv_model = chosen
        use = subject.valid & np.all(kp.runner_up > 0, axis=0)  # a runner-up is a second peak apart in that view
        pres = self.config.presence
        strong = pres.threshold(self.config.heatmaps.source)
        _, agreement = triangulate_joints_checked(uv_model, kp.confidence, kp.valid & use, crops,
                                                  self.config.joints3d, strong, pres.min_joints, terms=terms)
        foot = self._lowest_foot_m(Joints3D(subject.points, subject.confidence, use, subject.reprojection_px), kp,
                                   regions)
        return agreement.median_px, foot

    def matched_px(self, agreement: ViewAgreement) -> float | None:
        """A ``several_people`` pair's px figure from both people's peaks, where the subject's own pairings give
        none (:meth:`subject_figures`): each joint whose map shows two peaks apart in both views, each at least the
        presence threshold, is measured as its four pairings' errors before the ``joints3d.max_reprojection_px``
        gate (``agreement``, :meth:`both_people`; as one person's figure is), the views' peaks paired one to one
        the way that fits best (:func:`~ghnerf_runtime.two_people.matched_errors`: one of the two ways is the
        people's own joints); the median of the two people's errors over at least ``presence.min_joints`` such
        joints, else ``None``. Nobody need be picked: a camera knocked past the gate leaves no pairing to pick
        from, and this is what still shows it (docs/calibration.md, "Two people in view"). Its floor figure is
        :meth:`matched_foot`'s, from the people the pairings split into (a way's two points are not known to be
        whose)."""
        pres = self.config.presence
        if agreement.worst_px is None:  # (an agreement built without its joints' errors: nothing to pair)
            return None
        errors = matched_errors(agreement.worst_px.reshape(len(PAIRINGS), -1))
        measured = np.isfinite(errors).all(axis=0)
        if int(measured.sum()) < max(pres.min_joints, 1):
            return None
        return float(np.median(errors[:, measured]))

    def matched_foot(self, kp: Keypoints2D, pairs: tuple, regions: Regions) -> float | None:
        """A ``several_people`` pair's floor figure where the subject's own pairings give none (nobody picked: a
        camera panned far takes both people out of the working volume's box, which the pairings the subject is
        picked from pass; ``pick_subject: none``; the subject's feet not seen): the pairings before the box gates
        (``pairs``, :meth:`both_people`) split into two people (:func:`~ghnerf_runtime.two_people.split_people`,
        as a subject is picked from), and each person's lower foot by the one-person rules
        (:meth:`Estimator._lowest_foot_m`, of the joints shown twice in both views, as :meth:`subject_figures` takes
        them;
        ``presence.min_joints`` of them at the presence threshold to be someone; within ``_FLOOR_BODY_M`` of that
        person's own median, :func:`~ghnerf_runtime.joints3d.near_the_body`; each joint's peaks ``_CROP_EDGE_CELLS``
        inside both maps' edges, as the crops need not frame that person). The median of the people's figures
        (one person's where the other gives none), else ``None``. A split that tells nobody apart gives none: a
        foot is never measured from a pairing not given to one person (docs/calibration.md, "Two people in
        view")."""
        tri = pairs[0]
        J = len(kp.valid[0])
        people = split_people(tri.points.reshape(len(PAIRINGS), J, 3), tri.valid.reshape(len(PAIRINGS), J))
        twice = np.all(kp.runner_up > 0, axis=0)  # a runner-up is a second peak apart in that view
        pres = self.config.presence
        strong = pres.threshold(self.config.heatmaps.source)
        none = Joints3D.missing(J, tri.reprojection_px.shape[-1])
        feet = []
        for person in people:
            _, peaks, found = self._from_pairings(none, kp, pairs, np.maximum(person, 0), (person >= 0) & twice)
            if peaks is None:
                continue
            # (2, J, 2) heatmap cells of the peaks each joint was triangulated from: one past the crop's edge peaks
            # on the map's last cells, and is left out before it counts for someone, their median or their torso
            uv = peaks[0].uv
            inside = np.all((uv >= _CROP_EDGE_CELLS) & (uv <= self.grid - 1 - _CROP_EDGE_CELLS), axis=(0, 2))
            found = Joints3D(found.points, found.confidence, found.valid & inside, found.reprojection_px).sanitised()
            if pres.enabled:
                found = gate_presence(found, pres.min_joints, strong)
            foot = self._lowest_foot_m(near_the_body(found, self._floor_body_m), peaks[0], regions)
            if foot is not None:
                feet.append(foot)
        return float(np.median(feet)) if feet else None
