"""Two people in the working volume: whose joints does the runtime report?

    .venv/bin/python benchmarks/measure_two_people.py [--scenes 8] [--pairs 10] [--pick-subject centre_line]
    .venv/bin/python benchmarks/measure_two_people.py --model-dir models [--scenes 8] [--pairs 10] [--places ...]
    .venv/bin/python benchmarks/measure_two_people.py --places=0,2.5,0,0 --behind 1.0 [--occlude] [--model-dir ...]
    .venv/bin/python benchmarks/measure_two_people.py --one-person-model models [--sequences 30] [--frames 10]
    .venv/bin/python benchmarks/measure_two_people.py --one-person-model models --ends [--scenes 8] [--motions ...]
    .venv/bin/python benchmarks/measure_two_people.py --calibration 0,2,-2 [--axis pan] [--scenes 4] [--pairs 10]

The runtime follows one subject and its model answers one peak per joint per view. With two people in view,
each view's peak of a joint is whichever person's is stronger there, and the two views need not pick the same
person. This runs the oracle session (``bench_runtime_common.OracleSession``: heatmaps a perfectly trained
model would give) with both people's Gaussians in every heatmap (their maximum), the estimator at its defaults,
over simulated scenes of two people a metre apart side by side, and prints, over every pair, the joints
reported and how many lie within 5 cm of the first person's, of the second's, or of neither (a point
triangulated from one person's peak in one view and the other's in the other), and whom each scene's pairs
followed: a pair's person is the one most of its joints are at, and a scene is stable when every pair that
reports joints has the same person. ``--pick-subject`` sets ``joints3d.pick_subject`` (``none``: session 53's
rule, nobody without a track).

With ``--model-dir`` the heatmaps are instead a trained model's (the folder's, at the runtime's defaults) on the
two people rendered together (``drivers.sim.render_people``: each person by their own renderer over the first
person's room, the nearer one's pixel where they overlap), the same figures printed (since session 55), after a
reference row: the first person alone on the same scenes (a model's own error puts some joints past 5 cm). Each
row also gives the reported joints' mean distance from the nearer person's, and the flagged pairs' alone;
``--skeleton-prior off`` shows the triangulation's own error (a flagged pair's joints are then its pairings'; with
the prior, since session 55, the prior's fed the subject's own peaks).

Each row ends with the crop turn searches (``roi.turn_search``, on by default since session 57) its estimators ran,
``Estimator.turn_searches`` summed (since session 57's review N: two people with nobody picked search only where a
view reads weakly).

``--by-joint`` adds to each row, joint by joint, the pairs that reported it, their mean distance from the nearer
person's, and of them those a flagged pair reported without a pairing of the subject's (the skeleton prior's place,
read off ``SubjectSelector.keep_tracked_subject`` on the pass reported: :class:`SubjectPairings`): docs/two-people.md,
"Fewer, right joints" (session 59).

``--off-joints`` adds to each row with the second person the joints :data:`NEAR_M` or more from both people, by
where each camera's reported 2D joint of them lies (:func:`read_off`: within :data:`NEAR_PX` of the first person's
joint as that camera sees it, the second's, neither's, or none reported) on pairs flagged ``several_people`` or not,
and joint by joint: which joints are off and why (one view's peak of each person; both views' peaks the subject's and
the 3D joint placed off them): docs/two-people.md, "Which joints are off behind the subject" (session 67).

``--no-refine`` turns ``tracking.refine_cold_start`` off: a cold pass is not run again on the crop of what it found
(docs/two-people.md, "A track of both people's joints", session 57's review).

``--behind METRES`` puts the second person that far behind the first along view 0's line of sight (the first's
place from ``--places``), and ``--occlude`` has the oracle hide each person's joints behind the other's body in a
view (:func:`hidden_behind`; the rendered people of ``--model-dir`` hide each other already): docs/two-people.md,
"One person behind the other" (session 56).

With ``--one-person-model`` it measures instead what the check costs on one person: a trained model (the
folder's, at the runtime's defaults) on the held-out-like bench sequences (``ghnerf-bench runtime``'s,
``load_sequences``), each pair through two estimators, the check on and off (``second_person_min_joints: 0``).
It prints the pairs flagged ``several_people``, whether the joints came out identical, their error against
the truth (mean over the joints found, and the share found), and, over every pass of the checked estimator
(a cold pass and its refined one are two), how many joints were shown twice in both views. A tool, not a
test: docs/two-people.md, "Two people in the working volume".

With ``--ends`` as well, the one person is instead rendered alone at the working volume's ends and corners (the
places of ``test_model_extremes``' ``test_estimator_with_the_subject_at_the_ends_of_the_working_volume``), ``--scenes``
seeds of each of ``--motions``, ``--frames`` pairs each, a row per place. Every row, of every mode but
``--calibration``, is followed by the spread of each pass's largest torso excess over one body's
(``two_people.torso_excess``), as measured and as ``two_people.mixed_torso`` reads it (the part along the line of
sight discounted for the depth error), against ``MIXED_TORSO_SLACK_M``: docs/two-people.md, "A torso of two people"
(session 58's review).

``--scan-every-s SECONDS`` sets ``presence.scan_every_s`` (the whole working volume scanned for anyone besides the
tracked subject, ``PairResult.someone_else``; 0.001 scans every tracked pair): each row adds the pairs scanned and
those that said someone else is there, and ``--one-person-model``'s line the same (docs/two-people.md, "Anyone else
near?", session 64). Since session 66 a row with the second person also says where the scans' crops put them
(:class:`ScanWatch`, :func:`second_in_scan`, :func:`own_peaks`): their joints inside the subject's blanked cells, their
distance in heatmap cells from the first person's same joint, and the joints whose maps show a peak of their own
(what the scan misses a person behind the subject for); a row of one person, the joints whose maps show a peak away
from their own joint (what a cue of peaks beside the subject would find with nobody else there).

With ``--calibration`` it measures the daemon's calibration figures (``lowest_foot_m``, ``reprojection_px_median``)
on two people's pairs against the reported person's alone at the same instants, the rig file's second camera turned
by each angle given about ``--axis`` while the oracle films through the true rig (``measure_calibration``;
docs/calibration.md, "Two people in view").
"""
from __future__ import annotations

import argparse
import sys
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from benchmarks.bench_runtime_common import OracleSession, edge128_contract  # noqa: E402
from ghnerf_runtime.body25 import JOINT_NAMES, LIMBS  # noqa: E402
from ghnerf_runtime.config import PICK_SUBJECT_RULES, SKELETON_PRIOR_MODES, EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, joints_shown_twice, load_session  # noqa: E402
from ghnerf_runtime.others_scan import box_cells, subject_box  # noqa: E402
from ghnerf_runtime.two_people import MIXED_TORSO_SLACK_M, TORSO_LIMBS_M  # noqa: E402

#: A reported joint this close to a person's is theirs (m).
NEAR_M = 0.05
#: ``--off-joints``: a camera's reported 2D joint this near a person's joint as that camera sees it (original image
#: pixels, the nearer person's) was read off that person's peak.
NEAR_PX = 8.0
#: ``--off-joints``: where a camera's 2D joint of an off joint lies (:func:`read_off`).
READ_OFF = ("first", "second", "neither", "none")
#: ``--off-joints``: the commonest kinds of off joints named (:func:`off_joints`), the rest summed.
_OFF_KINDS_SHOWN = 6
#: ``--occlude``: a body hides what lies within this of its limbs' segments (m, at the body's depth), behind it.
BODY_HALF_WIDTH_M = 0.15
#: The torso limbs' rows of ``Estimator._torso_excess`` (``two_people.TORSO_LIMBS_M``' order): the neck to the
#: mid-hip, then the mid-hip to either hip.
_NECK_MIDHIP = list(TORSO_LIMBS_M).index((1, 8))
_HIPS = [k for k, limb in enumerate(TORSO_LIMBS_M) if limb != (1, 8)]


def torso_spread(excess: list) -> str:
    """The spread over passes of each pass's largest torso excess over one body's (``excess``: each pass's
    ``Estimator._torso_excess``, as measured then as ``two_people.mixed_torso`` reads it, NaN where a limb's joints
    were not both strong), the neck to mid-hip's and the hips' largest alone, and the rule's reading: its largest,
    the passes over ``MIXED_TORSO_SLACK_M`` and the least margin under it."""
    rows = np.array([e for e in excess if np.isfinite(e).any()]).reshape(-1, 2, len(TORSO_LIMBS_M))
    if not len(rows):
        return "the torso's excess over one body's: no pass with a torso limb strong in both views"
    largest, read = np.nanmax(rows[:, 0], axis=1), np.nanmax(rows[:, 1], axis=1)
    over = int((read > MIXED_TORSO_SLACK_M).sum())

    def top(v):
        v = v[np.isfinite(v)]
        return f"{v.max():+.2f}" if len(v) else "none"

    return (f"the torso's largest excess over one body's (two_people.torso_excess) on {len(rows)} passes: median "
            f"{np.median(largest):+.2f}, p90 {np.percentile(largest, 90):+.2f}, max {largest.max():+.2f} m "
            f"(neck to mid-hip max {top(rows[:, 0, _NECK_MIDHIP])}, a hip max {top(rows[:, 0, _HIPS].ravel())}); as "
            f"mixed_torso reads it (along the line of sight over two_people.depth_scale): median {np.median(read):+.2f}"
            f", max {read.max():+.2f} m, {over} over the {MIXED_TORSO_SLACK_M:g} m slack"
            + ("" if over else f", the least margin under it {MIXED_TORSO_SLACK_M - read.max():.2f} m"))


#: ``--scan-every-s``: a scan's peak this close to a person's joint (heatmap cells) is theirs.
OWN_PEAK_CELLS = 1.5


def read_off(uv: np.ndarray | None, first_uv: np.ndarray, second_uv: np.ndarray) -> str:
    """Whose peak a camera's reported 2D joint ``uv`` (None: not reported) was read off, of :data:`READ_OFF`: the
    person whose joint (``first_uv``, ``second_uv``: projected into that camera) lies within :data:`NEAR_PX`, the
    nearer where both do."""
    if uv is None:
        return "none"
    apart = [float(np.linalg.norm(uv - p)) if np.all(np.isfinite(p)) else np.inf for p in (first_uv, second_uv)]
    who = int(np.argmin(apart))
    return READ_OFF[who] if apart[who] <= NEAR_PX else "neither"


def tally_off(counts: dict, result, cameras: list, first: np.ndarray, second: np.ndarray, off: np.ndarray) -> None:
    """Add a pair's ``off`` joints (``(J,)``: reported, :data:`NEAR_M` or more from both people) to ``counts``: per
    joint, on pairs not flagged and flagged (``off_joint``, ``(2, J)``); and by where each camera's 2D joint of it lies
    (:func:`read_off`, ``off_read``: ``(flagged, view 0's, view 1's)`` -> joints)."""
    flagged = int(bool(result.several_people))
    for j in np.flatnonzero(off):
        counts["off_joint"][flagged, j] += 1
        read = []
        for cam in cameras:
            name = cam.name
            uv = None if result.missing_2d[name][j] else np.asarray(result.joints_2d[name][j], np.float64)
            read.append(read_off(uv, cam.project(first[j])[0], cam.project(second[j])[0]))
        counts["off_read"][(flagged, *read)] += 1


def off_joints(counts: dict) -> str:
    """``--off-joints``' lines: the off joints by where the views' 2D joints lie, then joint by joint."""
    total = max(int(counts["off_joint"].sum()), 1)
    ranked = sorted(counts["off_read"].items(), key=lambda kv: -kv[1])
    kinds = ", ".join(f"{'flagged' if f else 'not flagged'} {a} / {b} {n} ({n / total:.0%})"
                      for (f, a, b), n in ranked[:_OFF_KINDS_SHOWN])
    rest = sum(n for _, n in ranked[_OFF_KINDS_SHOWN:])
    kinds += f", the rest {rest} ({rest / total:.0%})" if rest else ""
    joints = ", ".join(f"{JOINT_NAMES[j]} {counts['off_joint'][0, j]}/{counts['off_joint'][1, j]}"
                       for j in np.argsort(-counts["off_joint"].sum(axis=0), kind="stable")
                       if counts["off_joint"][:, j].any())
    return (f"  off joints ({NEAR_M * 100:.0f} cm or more from both people), {int(counts['off_joint'].sum())}, by "
            f"where view 0 / view 1's 2D joint lies (within {NEAR_PX:g} px of the first person's, the second's, "
            f"neither's, none reported): {kinds or 'none'}\n"
            f"  off joints by joint, pairs not flagged / flagged: {joints or 'none'}")


def second_in_scan(P: np.ndarray, box: np.ndarray, stride: int, first: np.ndarray,
                   second: np.ndarray) -> tuple[int, float]:
    """Where a scan's crop (camera ``P``, ``(3, 4)``, heatmap cells of ``stride`` pixels) shows the second person:
    how many of ``second``'s joints (``(J, 3)``) project into the subject's blanked cells (``box``, the scan's
    :func:`~ghnerf_runtime.others_scan.subject_box`; :func:`~ghnerf_runtime.others_scan.box_cells`), and the median
    distance in cells between each of their joints and ``first``'s same joint: a person the scan cannot tell,
    blanked out, or their peaks within a Gaussian's reach of the subject's (``--scan-every-s``)."""
    u0, v0, u1, v1 = box_cells(P, box, stride)
    uv = [project_cells(P, joints, stride) for joints in (first, second)]
    inside = (uv[1][:, 0] >= u0) & (uv[1][:, 0] < u1 + 1) & (uv[1][:, 1] >= v0) & (uv[1][:, 1] < v1 + 1)
    return int(inside.sum()), float(np.median(np.linalg.norm(uv[0] - uv[1], axis=1)))


def own_peaks(heat: np.ndarray, first_cells: np.ndarray, second_cells: np.ndarray, threshold: float) -> int:
    """How many joints of one view's scan heatmaps ``(J, H, W)`` show a peak of the second person's own: a local
    maximum (of its 3 x 3 cells) of at least ``threshold`` within :data:`OWN_PEAK_CELLS` of their joint
    (``second_cells``, ``(J, 2)`` in cells: :func:`project_cells`) and farther than that from the first's
    (``first_cells``); a peak both people share is not theirs."""
    peaks = strong_peaks(heat, threshold)
    near_second, near_first = near_cells(heat.shape, second_cells), near_cells(heat.shape, first_cells)
    return int((peaks & near_second & ~near_first).any(axis=(1, 2)).sum())


def peaks_away(heat: np.ndarray, cells: np.ndarray, threshold: float) -> int:
    """How many joints of one view's scan heatmaps ``(J, H, W)`` show a peak (as :func:`own_peaks`) farther than
    :data:`OWN_PEAK_CELLS` from the one person's joint (``cells``, ``(J, 2)``): on one person alone, what a cue of
    peaks outside the subject's own joints would find with nobody else there."""
    return int((strong_peaks(heat, threshold) & ~near_cells(heat.shape, cells)).any(axis=(1, 2)).sum())


def strong_peaks(heat: np.ndarray, threshold: float) -> np.ndarray:
    """``(J, H, W)``: the cells of ``heat`` at least ``threshold`` and as high as any of their 3 x 3 neighbours."""
    J, H, W = heat.shape
    padded = np.pad(np.asarray(heat, np.float32), ((0, 0), (1, 1), (1, 1)), constant_values=-np.inf)
    around = np.max([padded[:, dy:dy + H, dx:dx + W] for dy in range(3) for dx in range(3)], axis=0)
    return (heat >= around) & (heat >= threshold)


def near_cells(shape: tuple, cells: np.ndarray) -> np.ndarray:
    """``(J, H, W)``: the cells (their centres) within :data:`OWN_PEAK_CELLS` of each joint's ``cells`` ``(J, 2)``."""
    _, H, W = shape
    rows, cols = np.mgrid[0:H, 0:W] + 0.5  # cell centres, as the cells' coordinates count them
    return np.hypot(cols[None] - cells[:, 0, None, None], rows[None] - cells[:, 1, None, None]) <= OWN_PEAK_CELLS


def project_cells(P: np.ndarray, points: np.ndarray, stride: int) -> np.ndarray:
    """``(J, 2)``: ``points`` ``(J, 3)`` through the crop camera ``P`` ``(3, 4)``, in heatmap cells."""
    p = np.concatenate([np.asarray(points, np.float64), np.ones((len(points), 1))], axis=1) @ np.asarray(P).T
    return p[:, :2] / p[:, 2:] / stride


def hidden_behind(front: np.ndarray, back: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``(J,)`` which of ``back``'s joints (``(J, 3)``) the camera ``P`` (``(3, 4)``) sees behind ``front``'s body:
    projected within :data:`BODY_HALF_WIDTH_M` (at ``front``'s depth) of one of its limbs' segments, and farther from
    the camera than ``front``'s median joint. A crude body (sticks of that half-width), enough to hide a person
    standing behind another (``--occlude``)."""
    p = [np.concatenate([j, np.ones((len(j), 1))], axis=1) @ P.T for j in (front, back)]
    uv = [q[:, :2] / q[:, 2:] for q in p]
    depth = float(np.median(p[0][:, 2]))
    # pixels per metre at the front body's depth: its neck to mid-hip, projected over its length
    px_per_m = np.linalg.norm(uv[0][1] - uv[0][8]) / max(float(np.linalg.norm(front[1] - front[8])), 1e-6)
    a, b = uv[0][[i for i, _ in LIMBS]], uv[0][[k for _, k in LIMBS]]  # (L, 2) each limb's ends
    ab = b - a
    t = np.clip(np.einsum("jld,ld->jl", uv[1][:, None] - a[None], ab) / np.maximum((ab * ab).sum(-1), 1e-9), 0, 1)
    gap = np.linalg.norm(uv[1][:, None] - (a[None] + t[..., None] * ab[None]), axis=-1).min(axis=1)
    return (gap <= BODY_HALF_WIDTH_M * px_per_m) & (p[1][:, 2] > depth)


class TwoPeopleOracle(OracleSession):
    """The oracle, its 2D heatmaps the maximum of two people's (``set_people``). ``apart``: the last maps' distance
    between the two people's projections of each joint in each view, in heatmap cells (``(S, J)``; None with one
    person): two peaks a few cells apart share one region above the decoder's threshold. ``occlude``: a person's
    joint behind the other's body in a view (:func:`hidden_behind`) shows no peak there, as a camera would not
    see it (else every joint shows, at full strength, whatever stands in front); ``hidden_share``: the last maps'
    share of the second person's joints so hidden in each view (``(S,)``)."""

    people: tuple[np.ndarray, ...] = ()
    apart: np.ndarray | None = None
    occlude: bool = False
    hidden_share: np.ndarray | None = None

    def set_people(self, *joints_3d: np.ndarray) -> None:
        self.people = tuple(np.asarray(j, np.float64) for j in joints_3d)
        self.set_truth(self.people[0])

    def _source_heatmaps(self, src_P: np.ndarray) -> np.ndarray:
        maps = []
        two = len(self.people) == 2
        for k, joints in enumerate(self.people):
            self.truth = joints
            if self.occlude and two:
                self.visible = np.stack([~hidden_behind(self.people[1 - k], joints, P) for P in src_P])
                if k == 1:
                    self.hidden_share = 1.0 - self.visible.mean(axis=1)
            maps.append(super()._source_heatmaps(src_P))
        self.truth, self.visible = self.people[0], None
        self.apart = None
        if len(self.people) == 2:
            uv = []
            for joints in self.people:
                p = np.concatenate([joints, np.ones((len(joints), 1))], axis=1) @ np.swapaxes(src_P, 1, 2)
                uv.append(p[..., :2] / p[..., 2:])
            self.apart = np.linalg.norm(uv[0] - uv[1], axis=-1) / self.contract.heatmap_stride
        return np.max(maps, axis=0)


class FilmedTwoPeopleOracle(TwoPeopleOracle):
    """The two-people oracle filmed by the true rig's cameras while the estimator holds ``held``, a rig file with a
    camera turned since (``measure_calibration_drift.turned``): each crop's projection, built on the held camera,
    is composed with the held-to-true camera change (exact for a turn about the camera's centre, the lens model
    being the same). ``hidden``: ``(view, joints)`` the second person shows no peak of in that view (their feet
    behind something, say)."""

    def __init__(self, contract, true_rig, held_rig, hidden: tuple = ()) -> None:
        super().__init__(contract)
        self.to_true = []
        for held, true in zip(held_rig.pair, true_rig.pair):
            M = np.eye(4)  # [R_held | t_held] @ M = [R_true | t_true]
            M[:3, :3], M[:3, 3] = held.R.T @ true.R, held.R.T @ (true.t - held.t)
            self.to_true.append(M)
        self.hidden = hidden

    def _source_heatmaps(self, src_P: np.ndarray) -> np.ndarray:
        src_P = np.stack([P @ M for P, M in zip(src_P, self.to_true)])
        maps = []
        for k, joints in enumerate(self.people):
            self.truth = joints
            self.visible = np.ones((len(src_P), len(joints)), bool)
            if k == 1 and self.hidden:
                self.visible[self.hidden[0], list(self.hidden[1])] = False
            maps.append(OracleSession._source_heatmaps(self, src_P))
        self.truth, self.visible = self.people[0], None
        return np.max(maps, axis=0)


#: Where the two people stand (x, z in the rig frame, metres): side by side a metre apart, each 0.5 m off the
#: rig's centre line, the first nearer the cameras.
PLACES = ((-0.5, 3.0), (0.5, 3.4))


class SubjectPairings:
    """The joints a flagged pass found from the subject's own pairings (``SubjectSelector.keep_tracked_subject``'s third
    value), pass by pass (``Estimator._finish_pass``): a pair may run several (a cold pass and its refined one, a
    ``tracking.retry_cold`` rerun, a turn search's candidates), and the last to pick a subject need not be the one
    reported. Installs itself on ``est``; clear :attr:`passes` before each pair. Before session 59's review the
    benchmark kept the pair's last call, whichever pass made it."""

    def __init__(self, est) -> None:
        #: this pair's passes so far: (the pass, its subject's found joints, ``(J,)`` bool, or None where the pass
        #: did not look for the subject's pairings)
        self.passes: list[tuple[object, np.ndarray | None]] = []
        selector = est.subject_selector
        keep, finish, found = selector.keep_tracked_subject, est._finish_pass, [None]

        def keeping(*a, **k):
            out = keep(*a, **k)
            found[0] = out[2].valid.copy()
            return out

        def finishing(*a, **k):
            found[0] = None
            p = finish(*a, **k)
            self.passes.append((p, found[0]))
            return p

        selector.keep_tracked_subject, est._finish_pass = keeping, finishing

    def of(self, result) -> np.ndarray | None:
        """The found joints of the pass ``result`` (a ``PairResult`` of this pair) reports: the one whose 2D
        confidences it holds (the same dict; its 3D joints may be smoothed)."""
        for p, found in self.passes:
            if p.conf_2d is result.confidence_2d:
                return found
        raise LookupError(f"pair {result.sequence}: none of its {len(self.passes)} passes is the one reported")


class ScanWatch:
    """What a pair's ``presence.scan_every_s`` scan looked at: its crops' cameras (``crops_P``, ``(2, 3, 4)``), their
    heatmaps (``heat``, ``(2, J, H, W)``) and the subject's box it blanked (``box``), None where the pair did not
    scan. Installs itself on ``est``."""

    def __init__(self, est) -> None:
        self.crops_P: np.ndarray | None = None
        self.heat: np.ndarray | None = None
        self.box: np.ndarray | None = None
        scan, volume = est._scan_for_others, est._volume_heatmaps

        def scanning(images, p, *a, **k):
            self.box = subject_box(p.j3.points, p.j3.valid) if p.j3 is not None else None
            return scan(images, p, *a, **k)

        def reading(images):
            heat, crops = volume(images)
            if heat is not None:
                self.crops_P = np.stack([np.asarray(c.P, np.float64) for c in crops])
                self.heat = np.asarray(heat, np.float32)
            return heat, crops

        est._scan_for_others, est._volume_heatmaps = scanning, reading

    def clear(self) -> None:
        self.crops_P = self.heat = self.box = None

    def looked(self) -> bool:
        """Whether this pair's scan ran the keypoint graph on the subject's box (a due scan on a tracked pair)."""
        return self.crops_P is not None and self.box is not None


def tally_scan(counts: dict, scan: ScanWatch, stride: int, threshold: float, subject: np.ndarray,
               second: np.ndarray | None) -> None:
    """Add one looked-at scan (:meth:`ScanWatch.looked`) to ``counts``: with a ``second`` person, where each view's
    crop put them (:func:`second_in_scan`, :func:`own_peaks`); alone (None), the ``subject``'s peaks away from
    their own joints (:func:`peaks_away`)."""
    if second is None:
        counts["scan_alone"] += 1
    for v, P in enumerate(scan.crops_P):
        own = project_cells(P, subject, stride)
        if second is None:
            counts["scan_away"][v] += peaks_away(scan.heat[v], own, threshold)
            continue
        inside, apart_cells = second_in_scan(P, scan.box, stride, subject, second)
        counts["scan_inside"][v] += inside
        counts["scan_apart"].append(apart_cells)
        counts["scan_own"][v] += own_peaks(scan.heat[v], own, project_cells(P, second, stride), threshold)


def measure(scenes: int, pairs: int, alone: int, config: EstimatorConfig = EstimatorConfig(), swap: bool = False,
            places: tuple = PLACES, model_dir: str | None = None,
            second: bool = True, occlude: bool = False) -> tuple[dict[str, float], int]:
    """Counts over every pair with both people in view (the first ``alone`` pairs of each scene show the first
    person only and are not counted): joints reported, at the first person's, the second's, neither, and their
    distances from the nearer person's (``nearer_mm``, summed; a model's error beside a mix-up); pairs flagged
    ``several_people``, their joints and those joints' summed distances (``flagged_joints``, ``flagged_mm``);
    scenes whose pairs followed the first person, the second, and those that followed one person throughout
    (``stable``: every pair that reports joints has most of them at the same person, none at the other); and
    over the passes of the pairs counted (a cold pass and its refined one are two), ``passes`` and the joints
    shown twice (a runner-up of at least ``second_person_ratio`` of the peak) in view 0, in view 1 and in both
    (``twice_view0``, ``twice_view1``, ``twice_both``, summed), and those whose peaks made a torso of two people
    (``torso_mixed``: ``two_people.mixed_torso``, docs/two-people.md, "A torso of two people"): a view whose two
    people's peaks of a joint share a region showed none there before the runner-up in a region (session 55)
    (docs/two-people.md, "Two people 0.6 m apart").
    ``places``: where the first and the second person stand, ``((x, z), (x, z))``; ``swap``: each at the other's
    place. ``model_dir``: the trained model of that folder (``config``'s session otherwise) on the
    two people rendered together (``drivers.sim.render_people``) instead of the oracle. ``second``: False shows
    the first person alone throughout (the reference: how many of one person's joints a model puts within
    :data:`NEAR_M` of the truth). ``occlude``: the oracle hides a person's joints behind the other's body
    (:attr:`TwoPeopleOracle.occlude`; ``hidden_view0``/``hidden_view1``: the second person's joints so hidden, summed
    over the passes counted). Returns ``(counts, pairs counted)``."""
    import drivers.sim as sim

    rig = sim.RigPlacement().build()
    session = None
    if model_dir is not None:
        config = replace(config, session=replace(config.session, model_dir=model_dir))
        session = load_session(config)  # once: every scene's estimator shares it
    counts = {"reported": 0, "first": 0, "second": 0, "neither": 0, "nearer_mm": 0.0, "flagged": 0,
              "scanned": 0, "someone_else": 0, "scan_inside": np.zeros(2), "scan_apart": [], "scan_own": np.zeros(2),
              "scan_alone": 0, "scan_away": np.zeros(2),
              "flagged_joints": 0, "flagged_mm": 0.0,
              "followed_first": 0, "followed_second": 0, "stable": 0,
              "passes": 0, "twice_view0": 0, "twice_view1": 0, "twice_both": 0, "hidden_view0": 0.0,
              "hidden_view1": 0.0, "turn_searches": 0, "torso_mixed": 0, "torso_excess": [],
              # per joint: pairs reporting it, their mm from the nearer person's, and of them those a flagged pair
              # reported without a pairing of the subject's (the skeleton prior's place, or the pass's answer)
              "joint_reported": np.zeros(25, int), "joint_mm": np.zeros(25), "joint_unpaired": np.zeros(25, int),
              # the off joints (NEAR_M or more from both people): per joint, pairs not flagged / flagged, and by where
              # each view's 2D joint lies (--off-joints)
              "off_joint": np.zeros((2, 25), int), "off_read": Counter()}
    ratio = config.joints3d.second_person_ratio
    apart: list[np.ndarray] = []  # the oracle's (view, joint) cells between the people, each pass counted
    counted = 0
    for seed in range(1, scenes + 1):
        here = places[::-1] if swap else places
        first = sim.SimScene(sim.SceneConfig(seed=seed, motion="wave", position_xz=here[0]))
        other = sim.SimScene(sim.SceneConfig(seed=seed + 1000, motion="wave", position_xz=here[1]))
        oracle = TwoPeopleOracle(edge128_contract()) if session is None else None
        if oracle is not None:
            oracle.occlude = occlude
        whose: list[int] = []  # each reporting pair's person: 0 the first, 1 the second
        mixed = False  # a pair reported joints at both people
        with Estimator(oracle or session, rig, config) as est:
            decide, counting_now = est.subject_selector.several_people, [False]  # every pass asks it once: counted

            def counting(kp, held, decide=decide, counting_now=counting_now, est=est):
                if counting_now[0]:
                    twice = kp.valid & (kp.runner_up >= ratio * kp.confidence)  # (view, J), as joints_shown_twice
                    counts["passes"] += 1
                    counts["twice_view0"] += int(twice[0].sum())
                    counts["twice_view1"] += int(twice[1].sum())
                    counts["twice_both"] += joints_shown_twice(kp, ratio)
                    counts["torso_mixed"] += int(est._torso_mixed)  # (set by this pass's 3D stage, before this)
                    counts["torso_excess"].append(est._torso_excess.copy())
                    if oracle is not None and oracle.apart is not None:
                        apart.append(oracle.apart)
                    if oracle is not None and oracle.hidden_share is not None:
                        counts["hidden_view0"] += float(oracle.hidden_share[0])
                        counts["hidden_view1"] += float(oracle.hidden_share[1])
                return decide(kp, held)

            est.subject_selector.several_people = counting
            scan = ScanWatch(est)  # what this pair's scan looked at (its crops and the subject's box)
            pairings = SubjectPairings(est)  # the subject's joints from their own pairings, the reported pass's
            for i in range(alone + pairs):
                t = i / 30.0
                a, b = first.joints_3d(t), other.joints_3d(t)
                together = second and i >= alone
                counting_now[0] = i >= alone
                if oracle is not None:
                    oracle.set_people(a, b) if together else oracle.set_people(a)
                    # the frames only pass the frame check here: the oracle's heatmaps come from the joints
                    images = tuple(first.render(c, t, with_truth=False)[0] for c in rig.pair)
                elif not together:
                    images = tuple(first.render(c, t, with_truth=False)[0] for c in rig.pair)
                else:  # the model sees both: each person over the first's room, the nearer one's pixel in front
                    images = tuple(sim.render_people((first, other), c, t) for c in rig.pair)
                pairings.passes.clear()
                scan.clear()
                r = est.estimate(images, timestamp_s=t)
                if i < alone:
                    continue
                found = ~r.missing
                near_a = np.linalg.norm(r.joints_3d - a, axis=-1) < NEAR_M
                near_b = np.linalg.norm(r.joints_3d - b, axis=-1) < NEAR_M
                counts["reported"] += int(found.sum())
                counts["first"] += int((found & near_a).sum())
                counts["second"] += int((found & near_b & ~near_a).sum())
                counts["neither"] += int((found & ~near_a & ~near_b).sum())
                if together:
                    tally_off(counts, r, list(rig.pair), a, b, found & ~near_a & ~near_b)
                nearer = np.minimum(np.linalg.norm(r.joints_3d - a, axis=-1), np.linalg.norm(r.joints_3d - b, axis=-1))
                counts["nearer_mm"] += float(nearer[found].sum()) * 1000.0
                counts["joint_reported"][:len(found)] += found
                counts["joint_mm"][:len(found)] += np.where(found, nearer, 0.0) * 1000.0
                paired = pairings.of(r) if r.several_people else None
                if paired is not None:
                    counts["joint_unpaired"][:len(found)] += found & ~paired
                counts["flagged"] += int(r.several_people)
                counts["scanned"] += int(r.someone_else is not None)
                counts["someone_else"] += int(bool(r.someone_else))
                if scan.looked():  # what the scan's crops showed of each person
                    tally_scan(counts, scan, est.contract.heatmap_stride, config.presence.threshold("encoder"),
                               a, b if together else None)
                if r.several_people:  # the subject's alone: its pairings' (the prior's fed their peaks, with it)
                    counts["flagged_joints"] += int(found.sum())
                    counts["flagged_mm"] += float(nearer[found].sum()) * 1000.0
                counted += 1
                at_a, at_b = int((found & near_a).sum()), int((found & near_b & ~near_a).sum())
                if at_a or at_b:
                    whose.append(0 if at_a >= at_b else 1)
                    mixed |= at_a > 0 and at_b > 0
            counts["turn_searches"] += est.turn_searches  # (the alone pairs' too: none search, one person standing)
        if whose:
            counts["followed_first" if whose[0] == 0 else "followed_second"] += 1
            counts["stable"] += int(len(set(whose)) == 1 and not mixed)
    for v in range(2):  # the middle 80 % of the passes' joints (the oracle only)
        lo, hi = np.percentile([a[v] for a in apart], [10, 90]) if apart else (np.nan, np.nan)
        counts[f"apart_view{v}"] = f"{lo:.1f}-{hi:.1f}"
    return counts, counted


def measure_calibration(scenes: int, pairs: int, alone: int, degrees: float,
                        config: EstimatorConfig = EstimatorConfig(), places: tuple = PLACES, axis: str = "pan") -> dict:
    """The calibration checks' figures (``lowest_foot_m``, ``reprojection_px_median``) on two people's pairs
    against the reported subject's alone at the same instants (``--calibration``): the rig file's second camera
    turned ``degrees`` about its ``axis`` (``pan``, ``tilt``, ``roll``) since calibration
    (:class:`FilmedTwoPeopleOracle`). Each scene runs three estimators (the first person alone, the second alone,
    both after ``alone`` pairs of the first); a two-people pair is compared
    with the alone run of whichever person its joints lie nearer. Returns ``pairs`` (counted), ``flagged``,
    ``foot``/``px`` (two-people pairs with the figure), ``foot_alone``/``px_alone`` (the subject alone),
    ``foot_diff``/``px_diff`` (absolute differences where both have it), ``px_values``/``px_values_alone`` (the
    px figures themselves), ``windows`` (each scene's median of the
    two-people pairs' ``lowest_foot_m``) and ``windows_alone`` (the first person alone's)."""
    import drivers.sim as sim
    from benchmarks.measure_calibration_drift import turned

    true = sim.RigPlacement().build()
    held = turned(true, 1, axis, degrees)
    out = {"pairs": 0, "flagged": 0, "foot": 0, "px": 0, "foot_alone": 0, "px_alone": 0, "foot_diff": [],
           "px_diff": [], "px_values": [], "px_values_alone": [], "windows": [], "windows_alone": []}
    for seed in range(1, scenes + 1):
        people = [sim.SimScene(sim.SceneConfig(seed=seed + 1000 * k, motion="wave", position_xz=places[k]))
                  for k in (0, 1)]
        runs = {}
        for who in ("first", "second", "both"):
            oracle = FilmedTwoPeopleOracle(edge128_contract(), true, held)
            runs[who] = []
            with Estimator(oracle, held, config) as est:
                for i in range(alone + pairs):
                    t = i / 30.0
                    a, b = (p.joints_3d(t) for p in people)
                    if who == "both" and i >= alone:
                        oracle.set_people(a, b)
                    else:
                        oracle.set_people(b if who == "second" else a)
                    images = tuple(people[0].render(c, t, with_truth=False)[0] for c in true.pair)
                    r = est.estimate(images, timestamp_s=t)
                    if i >= alone:
                        runs[who].append((r, a, b))
        feet, feet_alone = [], []
        for (r, a, b), first, second in zip(runs["both"], runs["first"], runs["second"]):
            out["pairs"] += 1
            out["flagged"] += int(r.several_people)
            if first[0].lowest_foot_m is not None:
                feet_alone.append(first[0].lowest_foot_m)
            found = ~r.missing
            near_a = np.linalg.norm(r.joints_3d - a, axis=-1)[found].mean() if found.any() else 0.0
            near_b = np.linalg.norm(r.joints_3d - b, axis=-1)[found].mean() if found.any() else 1.0
            alone_r = (first if near_a <= near_b else second)[0]  # nobody reported: the first person's
            for key, mine, theirs in (("foot", r.lowest_foot_m, alone_r.lowest_foot_m),
                                      ("px", r.reprojection_px_median, alone_r.reprojection_px_median)):
                out[key] += int(mine is not None)
                out[key + "_alone"] += int(theirs is not None)
                if mine is not None and theirs is not None:
                    out[key + "_diff"].append(abs(mine - theirs))
            out["px_values"] += [] if r.reprojection_px_median is None else [r.reprojection_px_median]
            out["px_values_alone"] += [] if alone_r.reprojection_px_median is None else [alone_r.reprojection_px_median]
            if r.lowest_foot_m is not None:
                feet.append(r.lowest_foot_m)
        if feet:
            out["windows"].append(float(np.median(feet)))
        if feet_alone:
            out["windows_alone"].append(float(np.median(feet_alone)))
    return out


def measure_one_person(model_dir: str, sequences: int, frames: int, scan_every_s: float = 0.0) -> dict:
    """One person (module docstring, ``--one-person-model``): ``pairs``, ``flagged``, ``identical`` (every pair's
    joints and missing flags equal with the check on and off), ``found`` and ``joints`` (joints found, of all),
    ``error_mm`` (mean over those found; NaN with none), ``passes`` and ``shown_twice`` (passes by the number of
    joints shown twice in both views, at the defaults' ``second_person_ratio``), ``torso_mixed`` (passes whose peaks
    made a torso of two people, ``two_people.mixed_torso``), ``scanned`` and ``someone_else`` (pairs whose
    ``PairResult.someone_else`` is not None, and True: ``scan_every_s`` sets ``presence.scan_every_s`` of the checked
    estimator alone, so ``identical`` covers the scan too)."""
    from ghnerf_runtime.cli.simdata import load_sequences

    off = EstimatorConfig(session=SessionConfig(model_dir=model_dir))
    on = replace(off, presence=replace(off.presence, scan_every_s=scan_every_s))
    off = replace(off, joints3d=replace(off.joints3d, second_person_min_joints=0))
    session = load_session(on)
    ratio = on.joints3d.second_person_ratio
    shown: Counter[int] = Counter()
    out = {"pairs": 0, "flagged": 0, "identical": True, "found": 0, "joints": 0, "torso_mixed": 0, "torso_excess": [],
           "scanned": 0, "someone_else": 0}
    errors: list[float] = []
    for seq in load_sequences(sequences, frames):
        with Estimator(session, seq.rig, on) as checked, Estimator(session, seq.rig, off) as unchecked:
            decide = checked.subject_selector.several_people  # every pass asks it once: counted beside its answer

            def counting(kp, held, decide=decide, checked=checked):
                shown[joints_shown_twice(kp, ratio)] += 1
                out["torso_mixed"] += int(checked._torso_mixed)  # (set by this pass's 3D stage, before this)
                out["torso_excess"].append(checked._torso_excess.copy())
                return decide(kp, held)

            checked.subject_selector.several_people = counting
            for i in range(len(seq)):
                images = (np.array(seq.images[i, 0]), np.array(seq.images[i, 1]))
                when = dict(sequence=i, timestamp_s=i / float(seq.info.get("fps", 30.0)))  # as ghnerf-bench runtime
                r = checked.estimate(images, **when)
                u = unchecked.estimate(images, **when)
                out["pairs"] += 1
                out["flagged"] += int(r.several_people)
                out["scanned"] += int(r.someone_else is not None)
                out["someone_else"] += int(bool(r.someone_else))
                out["identical"] &= bool(np.array_equal(r.missing, u.missing)
                                         and np.array_equal(r.joints_3d, u.joints_3d))
                found = ~r.missing
                out["found"] += int(found.sum())
                out["joints"] += found.size
                errors.extend(np.linalg.norm(r.joints_3d[found] - seq.joints_3d[i][found], axis=-1) * 1000.0)
    out["error_mm"] = float(np.mean(errors)) if errors else float("nan")
    out["passes"] = sum(shown.values())
    out["shown_twice"] = dict(sorted(shown.items()))
    return out


def volume_ends() -> list[tuple[float, float]]:
    """The working volume's ends and corners on the floor (x, z), as ``tests/ghnerf_runtime/test_model_extremes.py``
    names them (``test_estimator_with_the_subject_at_the_ends_of_the_working_volume``): the near and far ends on the
    centre line, then the four corners, far ones last (``--ends``; the benchmark rig's volume)."""
    import drivers.sim as sim

    lo, hi = sim.RigPlacement().build().volume.min_corner, sim.RigPlacement().build().volume.max_corner
    x0, x1, z0, z1 = float(lo[0]), float(hi[0]), float(lo[2]), float(hi[2])
    return [(0.0, z0), (0.0, z1), (x0, z0), (x1, z0), (x0, z1), (x1, z1)]


def measure_one_person_at(model_dir: str, places: list, scenes: int, frames: int, motions: tuple) -> list[dict]:
    """One person alone, a trained model (the folder's, at the runtime's defaults) on the rendered scenes (``--ends``):
    at each of ``places`` ((x, z), rig frame), ``scenes`` seeds of each of ``motions``, ``frames`` pairs each at 30 fps
    (from 0.2 s, as test_model_extremes). Per place: ``place``, ``pairs``, ``flagged`` (``several_people``),
    ``found`` and ``joints``, ``torso_mixed`` (passes whose peaks made a torso of two people) and ``torso_excess``
    (each pass's ``Estimator._torso_excess``; a cold pass and its refined one are two)."""
    import drivers.sim as sim

    config = EstimatorConfig(session=SessionConfig(model_dir=model_dir))
    session = load_session(config)  # once: every scene's estimator shares it
    rig = sim.RigPlacement().build()
    rows = []
    for place in places:
        row = {"place": place, "pairs": 0, "flagged": 0, "found": 0, "joints": 0, "torso_mixed": 0,
               "torso_excess": []}
        for motion in motions:
            for seed in range(1, scenes + 1):
                scene = sim.SimScene(sim.SceneConfig(seed=seed, motion=motion, position_xz=place))
                with Estimator(session, rig, config) as est:
                    decide = est.subject_selector.several_people  # every pass asks it once: counted beside it

                    def counting(kp, held, decide=decide, est=est, row=row):
                        row["torso_mixed"] += int(est._torso_mixed)  # (set by this pass's 3D stage, before this)
                        row["torso_excess"].append(est._torso_excess.copy())
                        return decide(kp, held)

                    est.subject_selector.several_people = counting
                    for i in range(frames):
                        t = 0.2 + i / 30.0
                        images = tuple(scene.render(c, t, with_truth=False)[0] for c in rig.pair)
                        r = est.estimate(images, timestamp_s=t)
                        row["pairs"] += 1
                        row["flagged"] += int(r.several_people)
                        row["found"] += int((~r.missing).sum())
                        row["joints"] += r.missing.size
        rows.append(row)
    return rows


def behind_place(place: tuple, metres: float, view: int = 0) -> tuple[float, float]:
    """The floor point ``metres`` farther than ``place`` (x, z) along the line of sight of the benchmark rig's camera
    ``view`` through it (``--behind``): a second person there stands behind the first as that camera sees them."""
    import drivers.sim as sim

    eye = np.asarray(sim.RigPlacement().build().pair[view].center)[[0, 2]]
    ahead = np.asarray(place, np.float64) - eye
    x, z = np.asarray(place, np.float64) + metres * ahead / np.linalg.norm(ahead)
    return round(float(x), 3), round(float(z), 3)


def _places(text: str) -> tuple:
    """``--places``: four numbers, the first person's x and z, then the second's."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 4 or not all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"--places needs four numbers X0,Z0,X1,Z1 (metres), got {text!r}")
    return (values[0], values[1]), (values[2], values[3])


def scanned(counts: dict, pairs: int) -> str:
    """The row's ``presence.scan_every_s`` figures: pairs scanned (a ``someone_else`` answer) and those saying yes."""
    if not counts["scanned"]:
        return ""
    looked = len(counts.get("scan_apart", ())) // 2
    where = "" if not looked else (
        f"; the second person's joints inside the subject's blanked cells, per scan, view 0 "
        f"{counts['scan_inside'][0] / looked:.1f}, view 1 {counts['scan_inside'][1] / looked:.1f} of 25, each joint "
        f"{np.median(counts['scan_apart']):.1f} cells from the first's (median), with a peak of their own "
        f"(within {OWN_PEAK_CELLS:g} cells of theirs, not of the first's) view 0 {counts['scan_own'][0] / looked:.1f}, "
        f"view 1 {counts['scan_own'][1] / looked:.1f}")
    alone = counts.get("scan_alone", 0)
    if alone:
        where += (f"; the joints with a peak away from the person's own (farther than {OWN_PEAK_CELLS:g} cells), per "
                  f"scan, view 0 {counts['scan_away'][0] / alone:.1f}, view 1 {counts['scan_away'][1] / alone:.1f}")
    return (f"; someone_else on {counts['someone_else']} of {counts['scanned']} pairs with a scan's answer "
            f"({counts['someone_else'] / counts['scanned']:.0%}; {pairs} pairs)" + where)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", type=positive_count, default=8, help="scene pairs (seeds 1..N for the first person)")
    ap.add_argument("--pairs", type=positive_count, default=10, help="pairs per scene with both people, at 30 fps")
    ap.add_argument("--alone", type=non_negative_count, default=3,
                    help="second run: pairs of the first person alone before the second joins (0: no second run)")
    ap.add_argument("--pick-subject", default=EstimatorConfig().joints3d.pick_subject, choices=PICK_SUBJECT_RULES,
                    help="joints3d.pick_subject: whom two people without a track report (none: nobody)")
    ap.add_argument("--swap", action="store_true",
                    help="each person at the other's place (the first person 0.5 m right of the centre line, 3.4 m "
                         "ahead; the second 0.5 m left, 3.0 m ahead)")
    ap.add_argument("--places", type=_places, default=PLACES, metavar="X0,Z0,X1,Z1",
                    help="where the first and the second person stand (rig frame, metres; default "
                         f"{','.join(f'{v:g}' for p in PLACES for v in p)})")
    ap.add_argument("--behind", type=float, metavar="METRES",
                    help="the second person this far behind the first along the first camera's (view 0's) line of "
                         "sight through the first's place (--places' first; the second's is replaced)")
    ap.add_argument("--behind-min-joints", type=int, default=EstimatorConfig().joints3d.behind_min_joints,
                    metavar="N", help="joints3d.behind_min_joints: a tracked pass showing N joints twice in one view "
                                      "alone is several_people (0, the default: off; docs/two-people.md, \"One person "
                                      "behind the other\", measured with 6)")
    ap.add_argument("--occlude", action="store_true",
                    help="the oracle: a person's joints behind the other's body in a view show no peak there "
                         "(a camera would not see them; without it every joint shows at full strength)")
    ap.add_argument("--model-dir", metavar="DIR", type=model_folder_option,
                    help="a trained model (this folder's, at the runtime's defaults) on the two people rendered "
                         "together, instead of the oracle's heatmaps")
    ap.add_argument("--skeleton-prior", choices=SKELETON_PRIOR_MODES,
                    help="joints3d.skeleton_prior (default: the runtime's, "
                         f"{EstimatorConfig().joints3d.skeleton_prior}; with --model-dir: off shows the "
                         "triangulation's own error, a flagged pair's pairings unrefined)")
    ap.add_argument("--one-person-model", metavar="DIR",
                    help="instead: what the check costs on one person, this model folder on the bench sequences")
    ap.add_argument("--sequences", type=positive_count, default=30, help="with --one-person-model: bench sequences")
    ap.add_argument("--ends", action="store_true",
                    help="with --one-person-model: instead of the bench sequences, one person rendered at the working "
                         "volume's ends and corners (test_model_extremes' places), --scenes seeds of each of "
                         "--motions, --frames pairs each")
    ap.add_argument("--motions", default="wave", metavar="NAMES",
                    help="with --ends: the scenes' motions, comma-separated (drivers.sim.MOTION_NAMES)")
    ap.add_argument("--frames", type=positive_count, default=10, help="with --one-person-model: pairs per sequence")
    ap.add_argument("--calibration", metavar="DEGREES",
                    help="instead: the calibration checks' figures on two people against the subject's alone, the "
                         "rig file's second camera turned by each of these angles (comma-separated, 0: the true "
                         "rig) about --axis, the second person joining after --alone pairs")
    ap.add_argument("--axis", default="pan", choices=("pan", "tilt", "roll"),
                    help="with --calibration: the axis the second camera is turned about")
    ap.add_argument("--by-joint", action="store_true",
                    help="each row also per joint: the pairs reporting it, their mean mm from the nearer person's, "
                         "and of them those a flagged pair reported without a pairing of the subject's (the skeleton "
                         "prior's place; docs/two-people.md, \"Fewer, right joints\")")
    ap.add_argument("--off-joints", action="store_true",
                    help="each row with the second person also the joints 5 cm or more from both people: by where each "
                         "camera's 2D joint of them lies (the first person's, the second's, neither's, none reported) "
                         "on pairs flagged several_people or not, and joint by joint (docs/two-people.md, \"Which "
                         "joints are off behind the subject\")")
    ap.add_argument("--scan-every-s", type=float, default=EstimatorConfig().presence.scan_every_s, metavar="SECONDS",
                    help="presence.scan_every_s: scan the working volume for anyone besides the tracked subject this "
                         "often (0, the default: off; 0.001: every tracked pair); the rows count the pairs that said "
                         "someone else is there (PairResult.someone_else)")
    ap.add_argument("--no-refine", action="store_true",
                    help="tracking.refine_cold_start off: a cold pass (the working volume's crop) is not run again "
                         "on the crop of what it found (docs/two-people.md, \"A track of both people's joints\")")
    ap.add_argument("--no-turn-search", action="store_true",
                    help="roi.turn_search off (on by default for a model with encoder heatmaps): the rows' counts "
                         "without the crop turn search (docs/two-people.md, \"People close together\")")
    args = ap.parse_args(argv)
    # --calibration and --one-person-model run their own sessions (the oracle filmed through a turned rig; the
    # bench sequences at the runtime's defaults): a model or prior asked for there would be silently left out
    for mode, given in (("--calibration", args.calibration), ("--one-person-model", args.one_person_model)):
        ignored = [name for name, value in (("--model-dir", args.model_dir), ("--skeleton-prior", args.skeleton_prior),
                                            ("--swap", args.swap or None)) if value is not None]
        if given and ignored:
            ap.error(f"{mode} does not use {' or '.join(ignored)} (it runs "
                     f"{'the oracle session' if mode == '--calibration' else 'that folder at the defaults'}); "
                     f"leave {'it' if len(ignored) == 1 else 'them'} out")
    if args.skeleton_prior is None:
        args.skeleton_prior = EstimatorConfig().joints3d.skeleton_prior
    if args.occlude and (args.model_dir or args.calibration or args.one_person_model):
        ap.error("--occlude is the oracle's (the rendered people hide each other already; --calibration and "
                 "--one-person-model film no hidden joints): leave it out")
    if args.no_refine and args.one_person_model:
        ap.error("--one-person-model runs that folder at the defaults: leave --no-refine out")
    if not (np.isfinite(args.scan_every_s) and args.scan_every_s >= 0):
        ap.error(f"--scan-every-s needs 0 s or more, got {args.scan_every_s!r}")
    if args.scan_every_s and args.calibration:
        ap.error("--calibration does not use --scan-every-s: leave it out")
    if not 0 <= args.behind_min_joints <= 25:
        ap.error(f"--behind-min-joints needs 0 to 25 joints, got {args.behind_min_joints}")
    if args.behind is not None:
        if not (np.isfinite(args.behind) and args.behind > 0):
            ap.error(f"--behind needs a distance above 0 m, got {args.behind!r}")
        args.places = (args.places[0], behind_place(args.places[0], args.behind))
    if args.no_turn_search and (args.one_person_model or args.calibration):
        ap.error("--no-turn-search sets the two-people rows' estimators; --calibration and --one-person-model run "
                 "their own (the oracle session; that folder at the defaults): leave it out")
    tracking = replace(EstimatorConfig().tracking, refine_cold_start=not args.no_refine)
    roi = replace(EstimatorConfig().roi, turn_search=False) if args.no_turn_search else EstimatorConfig().roi
    if args.calibration:
        config = EstimatorConfig(joints3d=replace(EstimatorConfig().joints3d, pick_subject=args.pick_subject,
                                                  behind_min_joints=args.behind_min_joints), tracking=tracking)
        from firmware_host.daemon.config import CALIBRATION_MAX_FLOOR_M as limit  # the daemon's floor check
        for deg in (float(v) for v in args.calibration.split(",")):
            m = measure_calibration(args.scenes, args.pairs, args.alone, deg, config, args.places, args.axis)

            def spread(v, d=3):
                return f"median {np.median(v):.{d}f}, max {np.max(v):.{d}f}" if v else "none"

            def windows(v):
                return (f"{min(v):+.3f} to {max(v):+.3f} m, {sum(abs(w) > limit for w in v)} of {len(v)} past "
                        f"{limit:g} m") if v else "none"

            print(f"{args.axis} {deg:g} deg, {m['pairs']} pairs of two people ({args.scenes} scenes, {args.alone} "
                  f"pairs of the first alone before each), pick_subject {args.pick_subject}: {m['flagged']} flagged; "
                  f"lowest_foot_m on {m['foot']} (the subject alone {m['foot_alone']}), |two - alone| "
                  f"{spread(m['foot_diff'])} m; reprojection_px_median on {m['px']} (alone {m['px_alone']}), "
                  f"|two - alone| {spread(m['px_diff'])} px (the figure: two people {spread(m['px_values'], 2)}, alone "
                  f"{spread(m['px_values_alone'], 2)}); scene medians of lowest_foot_m: two people "
                  f"{windows(m['windows'])}, the first alone {windows(m['windows_alone'])}")
        return 0
    if args.ends and not args.one_person_model:
        ap.error("--ends places one person through a model: give --one-person-model DIR")
    if args.one_person_model and args.ends:
        from drivers.sim import MOTION_NAMES

        motions = tuple(m for m in args.motions.split(",") if m)
        unknown = [m for m in motions if m not in MOTION_NAMES]
        if unknown or not motions:
            ap.error(f"--motions: {','.join(unknown) or repr(args.motions)} not among {', '.join(MOTION_NAMES)}")
        for row in measure_one_person_at(args.one_person_model, volume_ends(), args.scenes, args.frames, motions):
            x, z = row["place"]
            print(f"one person at ({x:g}, {z:g}), {args.one_person_model} at the defaults, {args.scenes} scenes of "
                  f"{'/'.join(motions)} x {args.frames} pairs: {row['flagged']} of {row['pairs']} pairs flagged "
                  f"several_people, {100.0 * row['found'] / max(row['joints'], 1):.1f} % of joints found; "
                  f"{torso_spread(row['torso_excess'])}")
        return 0
    if args.one_person_model:
        m = measure_one_person(args.one_person_model, args.sequences, args.frames, args.scan_every_s)
        shown = ", ".join(f"{n} joints: {k}" for n, k in m["shown_twice"].items())
        print(f"one person, {args.one_person_model} at the defaults, {args.sequences} bench sequences of "
              f"{args.frames} pairs: {m['flagged']} of {m['pairs']} pairs flagged several_people; joints "
              f"{'identical' if m['identical'] else 'DIFFERENT'} with the check on and off; "
              f"{m['error_mm']:.2f} mm over {100.0 * m['found'] / max(m['joints'], 1):.2f} % of joints "
              f"(against the truth)" + scanned(m, m["pairs"]))
        print(f"passes by joints shown twice in both views at {EstimatorConfig().joints3d.second_person_ratio}: "
              f"{shown} ({m['passes']} passes); a torso of two people (two_people.mixed_torso) on "
              f"{m['torso_mixed']} of them")
        print(f"  {torso_spread(m['torso_excess'])}")
        return 0
    runs = [(0, True, f"{args.pairs * args.scenes} pairs of two people ({args.scenes} scenes)")]
    if args.alone:
        runs.append((args.alone, True, f"the second person joining after {args.alone} pairs of the first alone, the "
                                       f"next {args.pairs * args.scenes} pairs"))
    if args.model_dir is not None:  # a model's own error puts some of one person's joints past NEAR_M too
        runs.insert(0, (0, False, f"reference: the first person alone, {args.pairs * args.scenes} pairs "
                                  f"({args.scenes} scenes)"))
    config = EstimatorConfig(joints3d=replace(EstimatorConfig().joints3d, pick_subject=args.pick_subject,
                                              skeleton_prior=args.skeleton_prior,
                                              behind_min_joints=args.behind_min_joints), tracking=tracking,
                             presence=replace(EstimatorConfig().presence, scan_every_s=args.scan_every_s), roi=roi)
    for alone, second, what in runs:
        counts, pairs = measure(args.scenes, args.pairs, alone, config, args.swap, args.places, args.model_dir,
                                second, args.occlude)
        n = max(counts["reported"], 1)
        where = "" if args.places == PLACES else " at " + " and ".join(f"({x:g}, {z:g})" for x, z in args.places)
        maps = "the oracle's heatmaps" if args.model_dir is None else f"{args.model_dir} on the rendered pairs"
        if args.occlude:
            maps += ", each person's joints behind the other's body hidden"
        if args.skeleton_prior != EstimatorConfig().joints3d.skeleton_prior:
            maps += f", skeleton_prior {args.skeleton_prior}"
        if args.behind_min_joints:
            maps += f", behind_min_joints {args.behind_min_joints}"
        if args.no_refine:
            maps += ", refine_cold_start off"
        if args.no_turn_search:
            maps += ", roi.turn_search off"
        flagged_mm = (f"the flagged pairs' {counts['flagged_mm'] / counts['flagged_joints']:.1f}"
                      if counts["flagged_joints"] else "no flagged pair's joints")
        print(f"{what}{where}{', swapped' if args.swap else ''}, {maps}, the defaults, pick_subject "
              f"{args.pick_subject}: "
              f"{counts['reported'] / pairs:.1f} joints reported per pair; of them {counts['first'] / n:.0%} at the "
              f"first person's, {counts['second'] / n:.0%} at the second's, {counts['neither'] / n:.0%} at neither "
              f"(> {NEAR_M * 100:.0f} cm from both); {counts['nearer_mm'] / n:.1f} mm from the nearer person's (mean; "
              f"{flagged_mm}); {counts['flagged'] / pairs:.0%} of pairs flagged several_people; "
              f"scenes following the first person {counts['followed_first']}, the second {counts['followed_second']}, "
              f"one person throughout {counts['stable']} of {args.scenes}" + scanned(counts, pairs))
        passes = max(counts["passes"], 1)
        print(f"  {counts['passes']} passes: joints shown twice at {config.joints3d.second_person_ratio} per pass, "
              f"view 0 {counts['twice_view0'] / passes:.1f}, view 1 {counts['twice_view1'] / passes:.1f}, both "
              f"{counts['twice_both'] / passes:.1f}"
              + ("" if args.model_dir is not None else
                 f"; the people's peaks of a joint {counts['apart_view0']} cells apart in view 0, "
                 f"{counts['apart_view1']} in view 1 (10th-90th percentile)")
              + (f"; the second person's joints hidden per pass, view 0 {counts['hidden_view0'] / passes:.0%}, view 1 "
                 f"{counts['hidden_view1'] / passes:.0%}" if args.occlude else "")
              + f"; a torso of two people (two_people.mixed_torso) on {counts['torso_mixed']} passes"
              + f"; roi.turn_search searches {counts['turn_searches']}")
        print(f"  {torso_spread(counts['torso_excess'])}")
        if args.by_joint:
            print("  by joint (pairs reporting it, mean mm from the nearer person's, of them without a subject's "
                  "pairing): " + ", ".join(
                      f"{JOINT_NAMES[j]} {k} {counts['joint_mm'][j] / k:.0f} ({counts['joint_unpaired'][j]})"
                      if k else f"{JOINT_NAMES[j]} 0" for j, k in enumerate(counts["joint_reported"])))
        if args.off_joints and second:
            print(off_joints(counts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
