"""Two people in view and no track yet: separate them and choose one (docs/two-people.md, "Two people in the
working volume").

Each view's map of a joint holds both people's peaks: the decoded one (the stronger there) and the runner-up
(``Keypoints2D.runner_up_uv``). Of the four pairings across the two views (:data:`PAIRINGS`), two are the people's
joints and two are mixed (one person's peak in one view, the other's in the other), and the mixed ones often pass
the reprojection gate. What tells them apart is where they lie: a person's joints stand in a column around the
person's centre, while the mixed points of people side by side lie together between them, nearer the cameras
(on the oracle: about 1.4 m from either person). So the people are two centres on the floor plane and each joint
is given to them as a whole: either the straight pairings (peak with peak, runner-up with runner-up) or the
crossed ones, each going to the nearer centre; a pairing may also go unused (the joint missing for that person).
That is a 2-means constrained per joint, started from each torso joint's two-person options in turn (every joint's
where no torso joint has them), the start of the lowest cost kept: no start needs to be right, one of a torso
joint's is (they stand nearest their person's centre). The centres settled, each joint is given again along the
limbs from the neck out (:data:`~ghnerf_runtime.body25.LIMBS`), to whichever person's joint it hangs from is
nearer: a waving hand reaches as far from its own person's centre as from the other's (on the
oracle, one person's wrist 0.70 m from their centre and the other's 0.36 m from it), never as far from its own
elbow. Pure numpy, arrays in and out.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ghnerf_runtime.body25 import BODY_PARTS, FLIP_INDEX, JOINT_NAMES, LIMBS
from ghnerf_runtime.config import PICK_SUBJECT_RULES
from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.proxy_matte import BONE_M

#: The four pairings of the two views' peaks: (view 0's option, view 1's), 0 the decoded peak, 1 the runner-up.
PAIRINGS = np.array([[0, 0], [0, 1], [1, 0], [1, 1]])
#: A joint lies within this of its person's centre on the floor plane (arm span about 1.8 m): a joint further off
#: costs as much as no joint, so it is left out rather than given to that person.
BODY_RADIUS_M = 1.0
#: Two people's centres are at least this far apart (a body's depth): two centres that settle nearer are one
#: column of points taken twice, such as the mixed points' (each joint's two mixed pairings may lie together).
MIN_APART_M = 0.4
#: BODY_25's longest limb (the neck to the mid-hip: up to 0.62 m in the simulator's people, the thigh 0.5 m) with
#: room for the triangulation's error: a joint further from every joint it shares a limb with is not that
#: person's (:func:`attached`, and the split along the limbs).
MAX_LIMB_M = 0.75
#: Two people whose distances (centre line or cameras) differ by less than this are as near as each other (the
#: rule's second distance decides): a waving person's centre (:func:`centre_of`) strays up to about 0.09 m from
#: where they stand (the oracle's scenes, benchmarks/measure_two_people.py), so two people standing equally far
#: off differ by up to about twice that.
TIE_M = 0.2
#: :func:`one_body`: a group of joints whose floor centre lies further than this from the largest group's is another
#: person's: half the 1 m between two people one behind the other, more than a limb's group strays from its body's
#: centre (an arm held out: its shoulder, elbow and wrist's median about 0.4 m off).
SAME_BODY_M = 0.5
#: One body's torso limbs (:data:`~ghnerf_runtime.body25.LIMBS`' neck to mid-hip and mid-hip to either hip) and their
#: lengths, metres: ``proxy_matte.BONE_M``'s generous average adult (the simulator's people up to 0.59 m and 0.10 m).
#: A torso holds its shape whatever the pose, unlike the arms, whose left and right one view may swap.
TORSO_LIMBS_M: dict[tuple[int, int], float] = {(1, 8): 0.55, (8, 9): 0.12, (8, 12): 0.12}
#: :func:`one_skeleton`: a limb (:data:`~ghnerf_runtime.body25.LIMBS`) of one body is at most its
#: ``proxy_matte.BONE_M`` length (a generous average adult) times this, for a taller person, plus
#: :data:`BONE_SLACK_M` for the triangulation's error (each end's pulled peaks: the shipped model's subject 0.6 m from
#: another person, a right shoulder 108 mm off on average). The left shoulders read from the other person's peaks
#: there lay 0.62 m from the subject's neck (bound 0.49 m; one body's 0.18 m) (docs/two-people.md,
#: "Fewer, right joints").
BONE_SCALE = 1.2
#: :func:`one_skeleton`: metres added to each limb's bound (:data:`BONE_SCALE`). 0.15 m dropped some of the shipped
#: model's pulled peaks of the subject (ears 132-267 mm off, an elbow 18 mm off beside its shoulder) and, two people a
#: metre apart, the track that followed then flagged 68 % of the pairs instead of 50 % (25.9 mm against 23.8).
BONE_SLACK_M = 0.25
#: :func:`mixed_torso`: a torso limb this much longer than one body's (its part along the line of sight discounted
#: past :data:`SLACK_DEPTH_BASELINES` baselines from the cameras, :func:`torso_excess`) is two people's joints. One
#: person through the shipped model, strong peaks in both views, came to at most 0.16 m over on the bench sequences
#: and 0.23 m at the working volume's near end; two people 0.6 m apart whose left side was read from the other
#: person, 0.69 m over (the median) (benchmarks/measure_two_people.py, docs/two-people.md "A torso of two people").
MIXED_TORSO_SLACK_M = 0.5
#: :func:`depth_scale`: past this many baselines from the cameras, a limb's part along the line of sight is divided by
#: its depth over these baselines: the benchmark rig's working volume centre, 3 m with 1.2 m between the cameras,
#: where :data:`MIXED_TORSO_SLACK_M` was measured. At its far corners (4 m), one person's hip came up to 0.43 m over
#: one body's (0.07 m under the slack), 0.26 m with its part along the line of sight so discounted.
SLACK_DEPTH_BASELINES = 2.5
#: :func:`one_side_each`: a left limb joint and its right twin found within this of each other are one peak's evidence
#: read twice. The shipped model's subject 0.6 m from another person, the prior off: a left wrist taken from the raised
#: right hand's peaks in both views lay 23-39 mm from the right wrist (a metre apart, a right wrist read from the left
#: hand 40 mm from the left wrist); the other twins of :data:`LIMB_TWINS` read 105 mm apart at the least on the four
#: rows of docs/two-people.md, "One peak, two sides" (the big toes, each 13-68 mm from the subject's).
TWIN_SAME_M = 0.06
#: Each BODY_25 joint's parent along :data:`~ghnerf_runtime.body25.LIMBS` (the joint nearer the neck), -1 for the neck.
_PARENT: tuple[int, ...] = tuple(next((a for a, b in LIMBS if b == j), -1) for j in range(len(JOINT_NAMES)))


def _left_joints(parent_has_side: bool) -> tuple[int, ...]:
    """The left joints off the face, in :data:`~ghnerf_runtime.body25.JOINT_NAMES` order, whose parent
    (:data:`_PARENT`) has a side (``parent_has_side``: an elbow, a knee) or has none (the neck or the mid-hip,
    both sides' own: a shoulder, a hip). The face is left out (its twins sit round one nose: see
    :data:`LIMB_TWINS`)."""
    return tuple(j for j in range(len(JOINT_NAMES))
                 if JOINT_NAMES[j].startswith("L") and j not in BODY_PARTS["head"] and _PARENT[j] >= 0
                 and (FLIP_INDEX[_PARENT[j]] != _PARENT[j]) == parent_has_side)


#: :func:`one_side_each`'s twins, ``(left, right)``: each left limb joint whose parent has a side too (the elbows,
#: wrists, knees, ankles and feet; a shoulder or hip hangs from the neck or mid-hip, both sides' own, which tells no
#: side) with its right twin, in :data:`~ghnerf_runtime.body25.JOINT_NAMES` order, which runs along each limb from
#: the torso out. The face is left out: its twins sit a skull's width apart round one nose, and the shipped model
#: read a subject's eyes 42 mm apart, as near as the wrists above.
LIMB_TWINS: tuple[tuple[int, int], ...] = tuple((j, FLIP_INDEX[j]) for j in _left_joints(parent_has_side=True))


def _torso_twins_apart() -> dict[tuple[int, int], float]:
    """:data:`TORSO_TWINS_APART_M`: each left joint hanging from a joint without a side (the neck, the mid-hip; the
    face's from the nose left out, as :data:`LIMB_TWINS` leaves it) with its right twin, where the bound is above 0."""
    apart = {}
    for left in _left_joints(parent_has_side=False):
        right = FLIP_INDEX[left]
        least = BONE_M[JOINT_NAMES[left]] + BONE_M[JOINT_NAMES[right]] - BONE_SLACK_M
        if least > 0.0:
            apart[(left, right)] = round(least, 3)
    return apart


#: :func:`held_apart`: the left and right joints the torso holds apart, ``(left, right)``, each with the least
#: distance one body's may read, metres: the two bones between them (``proxy_matte.BONE_M``, each from the neck or
#: the mid-hip they share, nearly in line across the torso) less :data:`BONE_SLACK_M` for the two ends' error. The
#: shoulders 0.15 m (the shipped model's subject's, found, read 0.33 m apart at the least on the four rows of
#: docs/two-people.md, "Fewer, right joints"; a left shoulder read from the right one's peaks, 0.10 m); the hips'
#: bound, 0.24 - 0.25 m, holds nothing (the model's pulled hips read 0.085 m apart), so they are not asked.
TORSO_TWINS_APART_M: dict[tuple[int, int], float] = _torso_twins_apart()
#: Assignment rounds per start: a start that has not settled by then is kept as it stands.
_ROUNDS = 8

# Each joint's options: the pairing given to person 0 and to person 1 (-1: none). Two pairings go together only
# when they use different peaks in both views: straight (0 with 3) or crossed (1 with 2).
_OPTIONS = np.array([(a, b) for a, b in ((0, 3), (3, 0), (1, 2), (2, 1))]
                    + [(k, -1) for k in range(4)] + [(-1, k) for k in range(4)] + [(-1, -1)])
_BOTH = 4  # the first four options give the joint to both people


def floor_xz(points: np.ndarray) -> np.ndarray:
    """The floor-plane coordinates (x, z) of rig-frame points (y is down)."""
    return np.asarray(points)[..., [0, 2]]


def split_people(points: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Two people's joints among the four pairings of each joint (module docstring).

    Args:
        points: ``(4, J, 3)`` the pairings' triangulated joints (rig frame), in :data:`PAIRINGS` order.
        valid: ``(4, J)`` which passed the gates.

    Returns:
        ``(2, J)`` int: each person's pairing of each joint, -1 where that person has none; -1 throughout where no
        joint has two people's pairings (nobody to tell apart). ``J`` is BODY_25's 25 (the limbs are its).
    """
    points = np.asarray(points, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool)
    if points.ndim != 3 or points.shape[0] != 4 or points.shape[2] != 3 or valid.shape != points.shape[:2]:
        raise ShapeError(f"split_people: points must be (4, J, 3) and valid (4, J), got {points.shape} and "
                         f"{valid.shape}")
    J = points.shape[1]
    xz = floor_xz(points)
    allowed = np.ones((len(_OPTIONS), J), bool)
    for o, (a, b) in enumerate(_OPTIONS):
        for k in (a, b):
            if k >= 0:
                allowed[o] &= valid[k]
    best_cost, best, centres = np.inf, np.full((2, J), -1), None
    two = [(j, a, b) for j in range(J) for a, b in _OPTIONS[:_BOTH:2]  # (0, 3) and (1, 2): either order
           if valid[a, j] and valid[b, j]]
    torso = [start for start in two if start[0] in BODY_PARTS["torso"]]
    for j, a, b in torso or two:  # (a start costs about 0.5 ms on a 2-core host: 12 at most from the torso)
        start = np.stack([xz[a, j], xz[b, j]])
        cost, chosen = _settle(xz, allowed, start)  # (start: the centres where it settled)
        if np.linalg.norm(start[0] - start[1]) >= MIN_APART_M and cost < best_cost:
            best_cost, best, centres = cost, chosen, start
    if centres is None:
        return best
    return _along_limbs(points, allowed, best, centres)


def _along_limbs(points: np.ndarray, allowed: np.ndarray, chosen: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """``chosen`` (the settled split) given again from the neck out (module docstring): each joint's option is the
    cheapest by the 3D distance of each person's pairing from that person's joint it hangs from (none further than
    :data:`MAX_LIMB_M`), or from their centre on the floor plane (``centres``) where they have none, capped and
    costed as :func:`_settle`'s."""
    chosen = chosen.copy()
    J = points.shape[1]
    for parent, child in LIMBS:
        if child >= J:
            continue
        cost = np.zeros(len(_OPTIONS))
        for person in range(2):
            k = _OPTIONS[:, person]
            here = points[np.maximum(k, 0), child]  # (options, 3)
            if chosen[person, parent] >= 0:  # no limb is longer than MAX_LIMB_M: further is another's joint
                dist = np.linalg.norm(here - points[chosen[person, parent], parent], axis=-1)
                dist = np.where(dist <= MAX_LIMB_M, dist, np.inf)
            else:
                dist = np.minimum(np.linalg.norm(floor_xz(here) - centres[person], axis=-1), BODY_RADIUS_M)
            cost += np.where(k >= 0, dist, BODY_RADIUS_M)
        chosen[:, child] = _OPTIONS[np.argmin(np.where(allowed[:, child], cost, np.inf))]
    return chosen


def _settle(xz: np.ndarray, allowed: np.ndarray, centres: np.ndarray) -> tuple[float, np.ndarray]:
    """From two centres (moved in place): give each joint its cheapest option, move the centres to the medians of
    what they got, again until nothing changes. Returns the cost (the distances of the joints given to each centre,
    and :data:`BODY_RADIUS_M` for each joint a person went without) and the ``(2, J)`` pairings."""
    J = xz.shape[1]
    j = np.arange(J)
    choice = None
    for _ in range(_ROUNDS):
        dist = np.linalg.norm(xz[:, :, None, :] - centres[None, None], axis=-1)  # (4, J, 2)
        dist = np.minimum(dist, BODY_RADIUS_M)  # (never cheaper than going without: the option without is there)
        cost = np.zeros((len(_OPTIONS), J))
        for person in range(2):
            k = _OPTIONS[:, person]
            cost += np.where(k[:, None] >= 0, dist[np.maximum(k, 0)][:, j, person], BODY_RADIUS_M)
        cost = np.where(allowed, cost, np.inf)
        pick = np.argmin(cost, axis=0)
        total = float(cost[pick, j].sum())
        if choice is not None and np.array_equal(pick, choice):
            break
        choice = pick
        chosen = _OPTIONS[pick].T  # (2, J)
        for person in range(2):
            mine = chosen[person] >= 0
            if mine.any():  # a centre with no joint stays where it was
                centres[person] = np.median(xz[chosen[person][mine], j[mine]], axis=0)
    return total, _OPTIONS[choice].T.copy()


def matched_errors(errors: np.ndarray) -> np.ndarray:
    """Each joint's two people's errors, ``(2, J)``, from its four pairings' (``errors``, ``(4, J)`` in
    :data:`PAIRINGS` order, NaN for a pairing not measured): of the two ways to pair the views' peaks one to one,
    straight (pairings 0 and 3) or crossed (1 and 2), the one whose larger error is the smaller, a way with a
    pairing not measured losing to one with both; NaN for a joint with neither way measured whole.

    One of the ways is the people's own joints, the other the mixed points; both views' peaks are used once, so a
    knocked camera's error shows in both of the people's pairings, while a mixed pairing's may happen to cancel it
    (the one person's image lower than the other's by as much): the lowest of the four would read low. A mixed
    pairing may also fail to meet at all (its rays cross behind a camera: a camera panned 8 degrees on the oracle
    of benchmarks/measure_two_people.py); a peak too weak to measure leaves both ways short (it is in each).

    Example (joint 0: the straight way fits, a crossed pairing happens to fit better still; joint 1: a crossed
    pairing not measured; joint 2: a straight one and a crossed one not measured):
        >>> nan = np.nan
        >>> matched_errors(np.array([[2.0, 1.0, nan], [0.5, nan, nan], [4.0, 1.0, 1.0], [2.2, 1.1, 1.0]])).tolist()
        [[2.0, 1.0, nan], [2.2, 1.1, nan]]
    """
    e = np.asarray(errors, dtype=np.float64)
    if e.ndim != 2 or e.shape[0] != len(PAIRINGS):
        raise ShapeError(f"matched_errors: errors must be ({len(PAIRINGS)}, J), one row per pairing, got shape "
                         f"{e.shape}")
    straight, crossed = e[[0, 3]], e[[1, 2]]
    # a way's larger error, +inf where a pairing of it was not measured (np.max spreads the NaN)
    worse_straight, worse_crossed = (np.nan_to_num(w.max(axis=0), nan=np.inf) for w in (straight, crossed))
    chosen = np.where(worse_crossed < worse_straight, crossed, straight)
    return np.where(np.isfinite(np.minimum(worse_straight, worse_crossed)), chosen, np.nan)


def attached(candidates: np.ndarray, joints: np.ndarray, found: np.ndarray) -> np.ndarray:
    """``(J,)`` which of ``candidates`` (``(J, 3)``, one per joint) lie within :data:`MAX_LIMB_M` of a ``found``
    joint of ``joints`` (``(J, 3)``) they share a limb with (:data:`~ghnerf_runtime.body25.LIMBS`)."""
    near = np.zeros(len(candidates), bool)
    for a, b in LIMBS:
        for j, other in ((a, b), (b, a)):
            if j < len(candidates) and other < len(candidates) and found[other]:
                near[j] |= bool(np.linalg.norm(candidates[j] - joints[other]) <= MAX_LIMB_M)
    return near


def held_apart(candidates: np.ndarray, joints: np.ndarray, found: np.ndarray) -> np.ndarray:
    """``(J,)`` which of ``candidates`` (``(J, 3)``, one per joint) lie at least :data:`TORSO_TWINS_APART_M` from
    their twin where ``found`` in ``joints`` (``(J, 3)``); True for a joint the torso does not hold apart from its twin,
    or whose twin is not found. A shoulder nearer its found twin than the torso allows is that twin's peak read again
    (a left shoulder map's runner-up on the right shoulder): bound from above alone (:func:`attached`,
    :func:`one_skeleton`), it lies within its bone's reach of the neck."""
    candidates = np.asarray(candidates, dtype=np.float64)
    joints = np.asarray(joints, dtype=np.float64)
    found = np.asarray(found, dtype=bool)
    if candidates.shape != joints.shape or joints.shape != (len(found), 3):
        raise ShapeError(f"held_apart: candidates and joints must be ({len(found)}, 3) for {len(found)} found flags, "
                         f"got {candidates.shape} and {joints.shape}")
    apart = np.ones(len(found), bool)
    for (left, right), least in TORSO_TWINS_APART_M.items():
        for j, twin in ((left, right), (right, left)):
            if j < len(found) and twin < len(found) and found[twin]:
                apart[j] = bool(np.linalg.norm(candidates[j] - joints[twin]) >= least)
    return apart


def limb_bound_m(parent: int, child: int) -> float:
    """The longest one body's limb ``(parent, child)`` of :data:`~ghnerf_runtime.body25.LIMBS` may be read as,
    metres (:data:`BONE_SCALE`, :data:`BONE_SLACK_M`); a chain of limbs through joints not found, the sum of its
    bones times :data:`BONE_SCALE` plus :data:`BONE_SLACK_M` once (the slack is its two ends' error)."""
    return BONE_SCALE * BONE_M[JOINT_NAMES[child]] + BONE_SLACK_M


def _group_roots(count: int, links: Sequence[tuple[int, int]]) -> np.ndarray:
    """``(count,)`` each item's group, as the id of one of its members, after joining each pair of ``links`` in
    order (union-find; ``a``'s group joins ``b``'s, so which member names a group follows the links' order)."""
    group = np.arange(count)

    def root(j: int) -> int:
        while group[j] != j:
            group[j] = group[group[j]]
            j = int(group[j])
        return j

    for a, b in links:
        group[root(a)] = root(b)
    return np.array([root(j) for j in range(count)])


def _joints_and_found(caller: str, joints: np.ndarray, found: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``joints`` as ``(J, 3)`` float64 and ``found`` as ``(J,)`` bool, or a :class:`ShapeError` naming ``caller``."""
    joints = np.asarray(joints, dtype=np.float64)
    found = np.asarray(found, dtype=bool)
    if joints.shape != (len(found), 3):
        raise ShapeError(f"{caller}: joints must be ({len(found)}, 3) for {len(found)} found flags, "
                         f"got {joints.shape}")
    return joints, found


def one_skeleton(joints: np.ndarray, found: np.ndarray) -> np.ndarray:
    """``(J,)`` which ``found`` joints of ``joints`` (``(J, 3)``, rig frame) make one skeleton: two found joints are
    linked where the limbs between them (:data:`~ghnerf_runtime.body25.LIMBS`, through joints not found, a tree's
    one path) are long enough to reach (:func:`limb_bound_m`); the largest group so linked is kept (of
    groups as large, the one with the lowest joint, the neck before the limbs). A joint triangulated from another
    person's peaks, or from one view's peak of each person, lies off its own limbs' reach: its group is the
    smaller. Unlike :func:`one_body` (:data:`MAX_LIMB_M`, the longest limb's, for every limb: a left shoulder
    0.62 m from its neck passes), each limb is held to its own length."""
    joints, found = _joints_and_found("one_skeleton", joints, found)
    J = len(found)
    near: dict[int, list[tuple[int, float]]] = {j: [] for j in range(J)}  # each joint's limbs and their lengths
    for a, b in LIMBS:
        if a < J and b < J:
            bone = BONE_SCALE * BONE_M[JOINT_NAMES[b]]
            near[a].append((b, bone))
            near[b].append((a, bone))
    links: list[tuple[int, int]] = []
    for start in np.flatnonzero(found):
        # walk the tree out from ``start`` through joints not found, to the first found joint on each path
        stack, seen = [(int(start), 0.0)], {int(start)}
        while stack:
            j, reach = stack.pop()
            for k, bound in near[j]:
                if k in seen:
                    continue
                seen.add(k)
                if not found[k]:
                    stack.append((k, reach + bound))
                elif np.linalg.norm(joints[k] - joints[start]) <= reach + bound + BONE_SLACK_M:  # (the ends' error)
                    links.append((k, int(start)))
    roots = _group_roots(J, links)
    if not found.any():
        return found.copy()
    sizes = np.bincount(roots[found], minlength=J)
    # of the largest groups, the one holding the lowest found joint (the first found joint in such a group)
    keep = roots[np.flatnonzero(found & (sizes[roots] == sizes.max()))[0]]
    return found & (roots == keep)


def side_support(joints: np.ndarray, found: np.ndarray, j: int) -> bool:
    """Whether joint ``j`` of ``joints`` (``(J, 3)``) hangs within its limb's reach (:func:`limb_bound_m`) of its
    parent (the joint it hangs from along :data:`~ghnerf_runtime.body25.LIMBS`), ``found``: its own side's chain from
    the torso holds it. Only the parent counts: a left arm read from the right one's peaks holds itself together
    (its elbow and wrist a forearm apart), but not to the left shoulder."""
    parent = _PARENT[j]
    if parent < 0 or not found[parent]:
        return False
    return bool(np.linalg.norm(joints[parent] - joints[j]) <= limb_bound_m(parent, j))


def one_side_each(joints: np.ndarray, found: np.ndarray) -> np.ndarray:
    """``(J,)`` ``found`` less, of each left limb joint and its right twin (:data:`LIMB_TWINS`) found within
    :data:`TWIN_SAME_M` of each other, the one its own side does not hold (:func:`side_support`) where the other's
    does, judged from the torso out (a joint so left out holds nothing further along its limb). One place is one
    peak's evidence in each view, whichever map's: one person's maps may show a second peak of a joint on the other
    side's limb (a left wrist's runner-up on the raised right hand, in both views), and that pairing lies at the right
    wrist, within the arm's reach of the neck, which no bone bound (:func:`one_skeleton`) tells from the left wrist.
    Where both sides hold theirs (hands clasped) or neither does, both stay: nothing tells which is the mistake."""
    joints, found = _joints_and_found("one_side_each", joints, found)
    J = len(found)
    keep = found.copy()
    for left, right in LIMB_TWINS:
        if left >= J or right >= J or not (found[left] and found[right]):
            continue
        if np.linalg.norm(joints[left] - joints[right]) > TWIN_SAME_M:
            continue
        held = side_support(joints, keep, left), side_support(joints, keep, right)
        if held[0] != held[1]:
            keep[right if held[0] else left] = False
    return keep


def one_body(joints: np.ndarray, found: np.ndarray) -> np.ndarray:
    """``(J,)`` which ``found`` joints of ``joints`` (``(J, 3)``) make one body: the joints are grouped along the
    limbs (:data:`~ghnerf_runtime.body25.LIMBS`, two joints of a limb in one group where within :data:`MAX_LIMB_M`),
    and a group is kept where its floor centre lies within :data:`SAME_BODY_M` of the largest group's. A joint
    triangulated from another person's peak lies at that person's and breaks its limbs there: its group is theirs."""
    joints = np.asarray(joints, dtype=np.float64)
    found = np.asarray(found, dtype=bool)
    J = len(found)
    roots = _group_roots(J, [(a, b) for a, b in LIMBS if a < J and b < J and found[a] and found[b]
                             and np.linalg.norm(joints[a] - joints[b]) <= MAX_LIMB_M])
    if not found.any():
        return found.copy()
    sizes = np.bincount(roots[found], minlength=J)
    largest = roots == int(np.argmax(sizes))
    centre = np.median(floor_xz(joints[largest & found]), axis=0)
    keep = np.zeros(J, bool)
    for r in np.unique(roots[found]):
        mine = found & (roots == r)
        keep |= mine & bool(np.linalg.norm(np.median(floor_xz(joints[mine]), axis=0) - centre) <= SAME_BODY_M)
    return keep


def mixed_torso(joints: np.ndarray, found: np.ndarray, centres: np.ndarray) -> bool:
    """Whether ``found`` joints of ``joints`` (``(J, 3)``, rig frame) hold a torso limb (:data:`TORSO_LIMBS_M`) longer
    than one body's by more than :data:`MIXED_TORSO_SLACK_M`, its part along the line of sight discounted for the
    triangulation's depth error (:func:`torso_excess` with ``centres``, the two cameras' ``(2, 3)``): the joints are
    two people's, each view's peak of a joint being whichever person's is stronger there and the views agreeing on it
    (the mid-hip one person's, a hip the other's), which no reprojection gate sees and no joint shown twice may tell
    (docs/two-people.md, "A torso of two people").

    Example (cameras 1.2 m apart; a mid-hip and its hips 0.1 m apart 3 m away, then the left hip 0.7 m aside; then
    the hip 0.7 m behind the mid-hip at 4.5 m, within one body's depth error there):
        >>> c = np.array([[-0.6, 0, 0], [0.6, 0, 0]])
        >>> j = np.zeros((25, 3)); j[1] = (0, -1.0, 3); j[8] = (0, -0.5, 3); j[9] = (-0.1, -0.5, 3)
        >>> j[12] = (0.1, -0.5, 3); found = np.zeros(25, bool); found[[1, 8, 9, 12]] = True
        >>> mixed_torso(j, found, c)
        False
        >>> j[12] = (0.7, -0.5, 3); mixed_torso(j, found, c)
        True
        >>> j[:, 2] = 4.5; j[12] = j[8] * (1 + 0.7 / np.linalg.norm(j[8])); mixed_torso(j, found, c)
        False
    """
    return reads_as_two_people(torso_excess(joints, found, centres, caller="mixed_torso"))


def reads_as_two_people(excess: np.ndarray) -> bool:
    """Whether torso limbs' ``excess`` as :func:`mixed_torso` reads it (:func:`torso_excess` with the cameras'
    centres; NaN: a limb not found) passes :data:`MIXED_TORSO_SLACK_M` anywhere: for a caller that keeps the
    excess too (the estimator, for the benchmarks), so that it is measured once."""
    excess = np.asarray(excess, dtype=np.float64)
    return bool(np.any(excess[np.isfinite(excess)] > MIXED_TORSO_SLACK_M))


def depth_scale(point: np.ndarray, centres: np.ndarray, caller: str = "depth_scale") -> float:
    """How much larger the triangulation's depth error is at ``point`` (rig frame) than where
    :data:`MIXED_TORSO_SLACK_M` was measured: its distance from the cameras' midpoint (``centres``, the two cameras'
    ``(2, 3)``) over :data:`SLACK_DEPTH_BASELINES` baselines, at least 1. The crop frames the person, so the model's
    error is a steady share of the body, and a share of the body in the image triangulates to a depth error that grows
    as depth over baseline (along the line of sight only: across it, the error stays that share of the body).

    Example (cameras 1.2 m apart: 3 m is where the slack was measured, 6 m twice as far):
        >>> c = np.array([[-0.6, 0, 0], [0.6, 0, 0]])
        >>> depth_scale(np.array([0, 0, 2.0]), c), depth_scale(np.array([0, 0, 6.0]), c)
        (1.0, 2.0)
    """
    centres = np.asarray(centres, dtype=np.float64)
    if centres.shape != (2, 3) or not np.isfinite(centres).all():
        raise ShapeError(f"{caller}: centres must be the two cameras' finite (2, 3) centres, got shape "
                         f"{centres.shape}")
    baseline = float(np.linalg.norm(centres[1] - centres[0]))
    if baseline <= 0.0:
        raise ShapeError(f"{caller}: centres must be two cameras apart, got both at {centres[0].tolist()}")
    depth = float(np.linalg.norm(np.asarray(point, dtype=np.float64) - centres.mean(axis=0)))
    return max(1.0, depth / (SLACK_DEPTH_BASELINES * baseline))


def torso_excess(joints: np.ndarray, found: np.ndarray, centres: np.ndarray | None = None,
                 caller: str = "torso_excess") -> np.ndarray:
    """``(len(TORSO_LIMBS_M),)`` how much longer each torso limb (:data:`TORSO_LIMBS_M`, in its order) of ``found``
    joints of ``joints`` (``(J, 3)``) is than one body's, metres (negative: shorter); NaN where a joint of it is not
    found. With ``centres`` (the two cameras' ``(2, 3)``), the limb's part along the line of sight through its
    midpoint is first divided by :func:`depth_scale` there: what :func:`mixed_torso` holds against
    :data:`MIXED_TORSO_SLACK_M`. One person through the shipped model at the working volume's far corners (4 m) put a
    hip up to 0.43 m over one body's, 0.26 m as read so: the most of it along the line of sight; two people side by
    side lie across it (benchmarks/measure_two_people.py prints both readings, docs/two-people.md "A torso of two
    people"). ``caller``: the function a shape error names."""
    joints = np.asarray(joints, dtype=np.float64)
    found = np.asarray(found, dtype=bool)
    if joints.ndim != 2 or joints.shape[1] != 3 or found.shape != joints.shape[:1]:
        raise ShapeError(f"{caller}: joints must be (J, 3) and found (J,), got {joints.shape} and {found.shape}")
    J = len(found)
    excess = np.full(len(TORSO_LIMBS_M), np.nan)
    for k, ((a, b), length) in enumerate(TORSO_LIMBS_M.items()):
        if a < J and b < J and found[a] and found[b]:
            limb = joints[b] - joints[a]
            if centres is not None:
                middle = (joints[a] + joints[b]) / 2.0
                sight = middle - np.asarray(centres, dtype=np.float64).mean(axis=0)
                sight = sight / max(float(np.linalg.norm(sight)), 1e-9)
                along = float(limb @ sight)
                limb = limb + (along / depth_scale(middle, centres, caller) - along) * sight
            excess[k] = float(np.linalg.norm(limb)) - length
    return excess


def centre_of(points: np.ndarray, chosen: np.ndarray) -> np.ndarray | None:
    """A person's centre on the floor plane: the median (x, z) of their joints (``points`` ``(4, J, 3)``, ``chosen``
    ``(J,)`` pairings, -1 none; a waving arm moves it little), or None without a joint."""
    mine = chosen >= 0
    if not mine.any():
        return None
    return np.median(floor_xz(points[chosen[mine], np.flatnonzero(mine)]), axis=0)


def pick_person(centres: list[np.ndarray | None], origin_xz: np.ndarray, facing_xz: np.ndarray,
                rule: str) -> int | None:
    """Which person is the subject, by ``rule`` (``Joints3DConfig.pick_subject``):

    * ``"centre_line"``: the one nearest the rig's centre line (``origin_xz``, the floor point below the cameras'
      midpoint, along ``facing_xz``, towards the working volume's centre), on the floor plane; within
      :data:`TIE_M` of each other, the one nearer the cameras (``origin_xz``).
    * ``"nearest"``: the one nearest the cameras; within :data:`TIE_M`, the one nearer the centre line.
    * ``"none"``: nobody.

    Where both distances tie, the first. ``centres``: each person's floor centre, None for a person left out
    (too few joints). Returns the index, or None (nobody to pick)."""
    if rule not in PICK_SUBJECT_RULES:
        raise ValueError(f"pick_person: rule must be one of {list(PICK_SUBJECT_RULES)}, got {rule!r}")
    present = [i for i, c in enumerate(centres) if c is not None]
    if rule == "none" or not present:
        return None
    facing = np.asarray(facing_xz, dtype=np.float64)
    facing = facing / np.linalg.norm(facing)
    keys = {}
    for i in present:
        d = np.asarray(centres[i], dtype=np.float64) - origin_xz
        off_line = abs(d[0] * facing[1] - d[1] * facing[0])  # the 2D cross product: distance from the line
        away = float(np.linalg.norm(d))
        keys[i] = (off_line, away) if rule == "centre_line" else (away, off_line)
    pick = present[0]
    for i in present[1:]:
        a, b = keys[i], keys[pick]
        if a[0] < b[0] - TIE_M or (abs(a[0] - b[0]) <= TIE_M and a[1] < b[1]):
            pick = i
    return pick
