"""``replay:///path/to/take``: play back a recording made by ``record+<url>``.

URL options:

* ``speed``: ``recorded`` (default) honours the recorded inter-frame timing on the
  injected clock; ``free`` delivers frames as fast as they decode; a number
  (``speed=2``, at least 0.001) plays at that multiple of real time. A read waiting for its frame's time
  is woken at once by a ``close()`` from another thread (:class:`~drivers.errors.RigOperationError`).
* ``loop``: ``1`` starts over at the end instead of raising :class:`EndOfStream`.
* ``tolerance_ms``, ``policy``, ``max_pending``: pairing, as every rig URL takes them
  (:mod:`drivers.pairing_options`; default policy ``all``: a recording is
  usually processed offline, every pair counts). ``policy=latest`` with a paced
  ``speed`` plays like a live rig: each read jumps to the newest pair due, however
  far behind the reader is, and the older ones are dropped (counted, their images
  never decoded); free-running playback never skips ahead.

* ``keep_time``: ``1`` delivers the recorded timestamps. By default (``0``) frames are
  re-stamped onto the source's clock: the first frame gets the clock time at which playback
  started (the first read), every other frame its recorded distance from the first. A live
  rig's stamps are its host's monotonic clock, and the joint stream carries them as capture
  times: a recorded stamp (another boot, another machine) made every receiver's latency
  (``send - capture``) hours long. Only the origin moves, so pairing, smoothing, tracking
  and rate limits see the recorded spacing; at ``speed=recorded`` a stamp is the time its
  frame plays, at other speeds (and ``free``) the stamps run ahead of or behind the clock.

Each camera plays in its recorded order (its image file numbers), the cameras merged by capture time. A
camera's stamp going back is a clock reset: warned of, and the frames after it re-based to follow on one
frame period after those before, one shift for both cameras (:func:`playback_order`; with ``keep_time=1``
too); one stamp out of line with its neighbours, they over a frame period apart, is a bad stamp, played at their
midpoint (a camera's first or last, one step from its neighbour, where the other cameras' stamps there say so;
two in a row, spread between their neighbours, where the other cameras' stamps say so). Indices and
ground truth are delivered unchanged on the first pass. Each further ``loop``
pass shifts timestamps by the recording's span (plus one frame period: the median step between a camera's
successive distinct stamps, else 1/30 s) and indices by the
per-camera index span (last - first + 1), so both keep increasing per camera. A take that was not closed cleanly
plays without the rows whose files are missing, empty or cut short
(:func:`~drivers.backends.recording_format.broken_rows_split`; the warning names the first). Layout and
validation: docs/recording-format.md.

Image sizes: a take with any image of another size than its rig camera's (every image measured at
:meth:`~ReplayRigSource.open`, from its header where the format gives one, else decoded:
:func:`~drivers.backends.recording_format.image_size`; docs/recording-format.md, "Replay")
is refused at open with :class:`~drivers.errors.FrameSizeError`, as the other backends refuse cameras delivering
another size than their rig file's (:meth:`ReplayRigSource.size_error`). An image that does not decode (a header
cut short or corrupt, or a valid layout this OpenCV refuses) is no size: it is a corrupt frame, as is an image whose
size changed after the open: ``read()`` raises :class:`~drivers.errors.RigOperationError` naming it once, and the
next read goes on. A camera none of whose images decode at open would play nothing: the take is refused at open.
Those checks look at every file of the take: a :meth:`~ReplayRigSource.close` from another thread stops them at the
next file, and ``open()`` raises :class:`~drivers.errors.RigInitializationError`.
"""
from __future__ import annotations

import bisect
import logging
import statistics
import threading
from collections import Counter, deque
from collections.abc import Iterable, Iterator
from dataclasses import replace
from pathlib import Path, PurePosixPath
from typing import TypeVar

import numpy as np

from drivers.backends.recording_format import (
    FRAMES,
    MANIFEST,
    FrameRow,
    Manifest,
    RefusedLayoutError,
    UndecodableImageError,
    broken_rows_split,
    file_is_whole,
    image_size,
    load_image,
    load_truth,
    read_manifest,
    read_rows,
    why_not_closed,
)
from drivers.base import RigSource
from drivers.clock import Clock
from drivers.errors import (
    EndOfStream,
    FrameSizeError,
    RigConfigError,
    RigInitializationError,
    RigOperationError,
)
from drivers.frames import CameraTruth, Frame
from drivers.pairing import DropPolicy, FramePairer, PairingConfig
from drivers.pairing_options import take_pairing_options
from drivers.url import RigUrl, decimal_number
from ghnerf_runtime.path_check import shown

log = logging.getLogger(__name__)

#: The slowest ``speed=`` played.
MIN_SPEED = 0.001
#: What :meth:`ReplayRigSource._until_closed` passes on.
_Item = TypeVar("_Item")

#: How many of a camera's images of another size than its rig camera's the refusal at open names.
SIZE_NAMES_SHOWN = 3
#: The image of a frame pushed by :meth:`ReplayRigSource._catch_up` before its file is decoded.
_NOT_LOADED = np.empty((0, 0, 3), np.uint8)


def _parse_speed(url: RigUrl) -> float | None:
    """``None`` for free-running, else the playback rate (1.0 = as recorded)."""
    raw = url.take_str("speed", "recorded")
    if raw == "recorded":
        return 1.0
    if raw == "free":
        return None
    try:
        speed = decimal_number(raw)  # type: ignore[arg-type]  # as take_float: speed=1_0 is refused, not read as 10
    except ValueError as e:
        raise RigConfigError(f"rig URL {url.url!r}: option speed={raw!r} must be 'recorded', 'free' or a number >= "
                             f"{MIN_SPEED:g} ({e})") from None
    # A floor: a frame's due time is its recorded offset / speed in integer nanoseconds, and speed=1e-320
    # made that infinite (an OverflowError from read); at 1/1000 an hour's take already plays for six weeks.
    if not MIN_SPEED <= speed < float("inf"):
        raise RigConfigError(
            f"rig URL {url.url!r}: option speed={raw!r} must be 'recorded', 'free' or a number >= {MIN_SPEED:g}"
        )
    return speed


def frame_period_ns(rows: list[FrameRow]) -> int:
    """The take's frame period: the median over cameras of the median step between a camera's successive
    distinct stamps (``rows`` in each camera's playing order), else 1/30 s."""
    periods = []
    for cam in dict.fromkeys(r.camera for r in rows):
        stamps = [r.timestamp_ns for r in rows if r.camera == cam]
        # Python integers: two 64-bit stamps far apart overflow an int64 difference. Repeated stamps say
        # nothing of the period: a take whose stamps were all one had a 1 ns period, so each loop pass came
        # 1 ns after the last, and a paced read after any stall pushed millions of passes (a hang). Steps
        # back (a clock reset) say nothing of it either.
        steps = [b - a for a, b in zip(stamps, stamps[1:]) if b > a]
        if steps:
            periods.append(statistics.median(steps))
    return int(statistics.median(periods)) if periods else 33_333_333


def _file_number(row: FrameRow) -> int | None:
    """The number the recorder gave the row's image file (``images/<camera>/00000012.png``: 12), if it has one."""
    stem = PurePosixPath(row.image).stem
    return int(stem) if stem.isdigit() else None


def recorded_order(rows: list[FrameRow]) -> dict[str, list[int]]:
    """Each camera's rows (positions in ``rows``) in the order it recorded them: by image file number, which the
    recorder counts per camera as frames arrive. Not the journal's order (two writer threads can swap rows
    there), nor the stamps' (a clock reset sends them back). A camera whose files are not all numbered keeps
    its journal order."""
    by_camera: dict[str, list[int]] = {}
    for i, row in enumerate(rows):
        by_camera.setdefault(row.camera, []).append(i)
    for cam, mine in by_camera.items():
        numbers = [_file_number(rows[i]) for i in mine]
        if None not in numbers:
            by_camera[cam] = [i for _, i in sorted(zip(numbers, mine))]  # a tie (never written): journal order
    return by_camera


def playback_order(rows: list[FrameRow], directory: Path | str = "") -> list[FrameRow]:
    """The rows in the order they play, those after a clock reset re-based.

    Each camera plays in its recorded order (:func:`recorded_order`), the cameras merged by capture time. A
    camera's stamp going back is taken as a clock reset (a device that restarted, a host clock set back)
    and splits that camera's rows into segments; a camera's k-th segment is taken to follow the other
    camera's k-th. The rows of segment k (k >= 1) are re-based by one shift common to the cameras that
    have one, so that it starts one frame period after the latest frame of segment k-1: the segments play
    one after another, in the order recorded, and the cameras keep their relative timing within a segment,
    so pairs stay pairs. The true gap at a reset is not recorded; one frame period stands for it. A warning
    per camera that went back names its first reset and the shift (recorded stamp = played stamp - shift).
    One stamp out of line with both its neighbours, or two in a row, is first mended (:func:`_mend_bad_stamps`),
    not a reset.

    Re-based, not played with the stamps going back: every later stage (pairing, tracking, smoothing, sinks)
    takes a camera's stamps as increasing, and a pairer that sees one camera go back while the other still
    holds a frame of the old timeline loses the first pair after the reset.
    """
    segments: dict[str, list[list[int]]] = {}
    stamps = {i: row.timestamp_ns for i, row in enumerate(rows)}
    order = recorded_order(rows)
    for cam, mine in order.items():
        others = [theirs for other, theirs in order.items() if other != cam]
        _mend_bad_stamps(rows, mine, stamps, directory, others)
        split: list[list[int]] = []
        for i in mine:
            if not split or stamps[i] < stamps[split[-1][-1]]:
                split.append([])
            split[-1].append(i)
        segments[cam] = split
    if any(len(split) > 1 for split in segments.values()):
        period = frame_period_ns([rows[i] for split in segments.values() for segment in split for i in segment])
        shifts = [0]
        for k in range(1, max(len(split) for split in segments.values())):
            reset = [split for split in segments.values() if len(split) > k]
            previous_end = max(stamps[split[k - 1][-1]] for split in reset) + shifts[k - 1]
            shifts.append(previous_end + period - min(stamps[split[k][0]] for split in reset))
        for cam, split in segments.items():
            for k, segment in enumerate(split[1:], start=1):
                for i in segment:
                    stamps[i] += shifts[k]
            if len(split) > 1:
                before, after = rows[split[0][-1]], rows[split[1][0]]
                log.warning(
                    "recording %s: camera %r's timestamps go back at frame %s (index %d, %s line %d): %d ns after "
                    "%d ns, taken as a clock reset (%d in this camera); the take plays in the recorded order, "
                    "the frames after a reset stamped to follow one frame period after those before (after the "
                    "first: recorded stamp = played stamp - %d ns, keep_time=1 too)",
                    directory, cam, after.image, after.index, FRAMES, after.line, after.timestamp_ns,
                    before.timestamp_ns, len(split) - 1, shifts[1],
                )
    # Capture order across cameras, ties in journal order; then each camera's rows are put back in its
    # recorded order at the places its rows took: a camera's stamps are non-decreasing in that order, so the
    # stamps at those places are the same, and only a camera's equal stamps change places.
    merged = sorted(range(len(rows)), key=lambda i: (stamps[i], i))
    queues = {cam: deque(i for segment in split for i in segment) for cam, split in segments.items()}
    played = []
    for position in merged:
        i = queues[rows[position].camera].popleft()
        row = rows[i]
        played.append(row if stamps[i] == row.timestamp_ns else replace(row, timestamp_ns=stamps[i]))
    return played


#: A camera's first (last) step longer than this many times the next (previous) one is out of line.
END_STEPS = 4


#: The most frames in a row of one camera mended as bad stamps: a longer run out of line plays as recorded (a reset).
MENDED_RUN = 2


#: The most frame periods a frame between a mended stamp's (or run's) neighbours, themselves in line: wider apart, a
#: pause lies there too (a reset then a pause reads as a glitch by its own camera alone, session 73).
MENDED_ROOM = 4


def _mend_bad_stamps(rows: list[FrameRow], mine: list[int], stamps: dict[int, int], directory: Path | str,
                     others: list[list[int]]) -> None:
    """Give a lone bad stamp of one camera (``mine``: its rows in recorded order) the midpoint of its neighbours'.

    A stamp out of line with the frames either side of it, which are in line with each other (a glitched stamp
    an hour ahead or back, the frames after it on the old timeline), is one bad stamp, not a clock reset: taken
    as a reset, it re-based every later frame of that camera by the glitch, so none paired again and a paced
    replay waited out the glitch (an hour); not where another camera jumped with it (:func:`_jumped_with_them`).
    Up to ``MENDED_RUN`` such stamps in a row are mended too, spread
    evenly between their neighbours, where the other cameras (``others``: their rows in recorded order) say so
    (:func:`_mend_runs`). Lone or in a run, only where the neighbours lie over a frame period apart
    (:func:`_out_of_line`): a clock reset back one to three frames brings one back within a period. A camera's
    first and last frames have one neighbour: mended one step from it where the other cameras say so
    (:func:`_bad_end`) and recorded at that frame's time (:func:`_recorded_beyond`), unless their clocks went back
    there too (:func:`_on_their_reset`) or one jumped with it (:func:`_jumped_at_the_end`);
    ``MENDED_RUN`` of them in a row likewise (:func:`_mend_end_runs`)."""
    period_ns = _mending_period_ns(rows, mine, others)
    # runs first: the lone test takes a run's first (back, then ahead)
    mended = _mend_runs(mine, stamps, others, period_ns)
    for before, here, after in zip(mine, mine[1:], mine[2:]):
        if (_out_of_line([stamps[here]], stamps[before], stamps[after], period_ns)
                and not _jumped_with_them(stamps[here], stamps[before], stamps[after], others, stamps)):
            mended.append((here, stamps[here]))
            stamps[here] = (stamps[before] + stamps[after]) // 2
    mended += _mend_end_runs(mine, stamps, others, period_ns)
    ends = [(mine[:3], [stamps[theirs[0]] for theirs in others if theirs], False),
            (mine[:-4:-1], [stamps[theirs[-1]] for theirs in others if theirs], True)]
    for (end, near, far), elsewhere, last in (ends if len(mine) >= 3 else []):
        in_line = stamps[near] <= stamps[far] if end == mine[0] else stamps[far] <= stamps[near]
        if (in_line and _bad_end(stamps[end], stamps[near], stamps[far], elsewhere)
                and _recorded_beyond(elsewhere, stamps[near], last, period_ns)
                and not _jumped_at_the_end(stamps[end], stamps[near], last, others, stamps, period_ns)
                and not _on_their_reset(stamps[end], _across_a_reset(others, stamps, last, stamps[near], period_ns),
                                        period_ns)):
            mended.append((end, stamps[end]))
            stamps[end] = max(0, 2 * stamps[near] - stamps[far])
    if mended:
        (first, recorded), row = mended[0], rows[mended[0][0]]
        log.warning("recording %s: camera %r's stamp at frame %s (index %d, %s line %d), %d ns, is out of line with "
                    "the frames beside it: taken as a bad stamp, played in line with them, at %d ns (%d in "
                    "this camera)", directory, row.camera, row.image, row.index, FRAMES, row.line,
                    recorded, stamps[first], len(mended))


def _mending_period_ns(rows: list[FrameRow], mine: list[int], others: list[list[int]]) -> int:
    """The frame period a mended stamp's neighbours must lie over apart: this camera's (``mine``) lower median step
    forward among those with no step back beside them (:func:`_steady_steps`), which leaves out a bad stamp's
    hour-long steps (the lower median, the one two stamps ahead in a row keep). Not the shorter of its and the
    other cameras' (``others``): a slower camera beside faster ones had a reset back one to two of its own frames
    mended by their period (session 72 review). A camera of a few frames, with under two such steps, keeps that
    shorter one (its median step, :func:`frame_period_ns`, may be a bad stamp's); alone, its own, not 1/30 s."""
    steady = _steady_steps([rows[i].timestamp_ns for i in mine])
    if len(steady) >= 2:
        return int(statistics.median_low(steady))
    own_ns = frame_period_ns([rows[i] for i in mine])
    # only cameras with a step forward tell a period: others of one frame, or of two across a reset, gave
    # frame_period_ns's 1/30 s, which beat a 10 fps camera's own and had its reset mended (session 72 review)
    theirs = [rows[i] for group in others if _steps_forward([rows[i].timestamp_ns for i in group]) for i in group]
    return min(own_ns, frame_period_ns(theirs)) if theirs else own_ns


def _steps_forward(stamps_ns: list[int]) -> bool:
    """Whether a camera's stamps, in its playing order, step forward anywhere."""
    return any(b > a for a, b in zip(stamps_ns, stamps_ns[1:]))


def _steady_steps(stamps_ns: list[int]) -> list[int]:
    """The steps forward between successive stamps that have no step back beside them."""
    steps = [b - a for a, b in zip(stamps_ns, stamps_ns[1:])]
    return [step for k, step in enumerate(steps)
            if step > 0 and (k == 0 or steps[k - 1] >= 0) and (k + 1 == len(steps) or steps[k + 1] >= 0)]


def _out_of_line(run_ns: list[int], low_ns: int, high_ns: int, period_ns: int) -> bool:
    """Whether stamps ``run_ns`` in a row, between neighbours stamped ``low_ns`` and ``high_ns``, are out of line in
    a way a bad stamp (or run) is: every one outside the neighbours, those two in line with each other and over
    ``period_ns`` apart, room for the frames between them, but at most ``MENDED_ROOM`` periods a frame. A reset back
    one to three frames also has a frame back in line after the one or two before it, but within a period (session
    72: these were mended as bad stamps)."""
    if not low_ns <= high_ns or high_ns - low_ns <= period_ns:
        return False
    # a pause beside a reset (after it, or before) keeps the camera on the new line, its neighbours far apart
    if high_ns - low_ns > MENDED_ROOM * (len(run_ns) + 1) * period_ns:
        return False
    return not any(low_ns <= ns <= high_ns for ns in run_ns)


def _mend_runs(mine: list[int], stamps: dict[int, int], others: list[list[int]],
               period_ns: int) -> list[tuple[int, int]]:
    """Mend runs of 2 to ``MENDED_RUN`` stamps in a row out of line with the frames either side
    (:func:`_out_of_line`, ``period_ns`` its frame period): each run's stamps spread evenly between them, where the
    other cameras confirm the old timeline (:func:`_run_is_bad`). Returns the rows mended with their recorded
    stamps. A reset stays on the new timeline and a pause goes on from it, so neither has a frame back in line
    after it; nor has a reset back two to three frames, but its frame after next lands within a period of the frame
    before it (session 72: two frames were squeezed in there)."""
    mended: list[tuple[int, int]] = []
    elsewhere: list[int] | None = None  # the other cameras' stamps, sorted once a run is found
    for length in range(2, MENDED_RUN + 1):
        for start in range(1, len(mine) - length):
            before, run, after = mine[start - 1], mine[start:start + length], mine[start + length]
            low, high = stamps[before], stamps[after]
            if not _out_of_line([stamps[i] for i in run], low, high, period_ns):
                continue
            if elsewhere is None:
                elsewhere = sorted(stamps[i] for theirs in others for i in theirs)
            if _run_is_bad([stamps[i] for i in run], low, high, elsewhere):
                for k, i in enumerate(run, start=1):
                    mended.append((i, stamps[i]))
                    stamps[i] = low + (high - low) * k // (length + 1)
    return mended


def _run_is_bad(run_ns: list[int], low_ns: int, high_ns: int, elsewhere_ns: list[int]) -> bool:
    """Whether stamps ``run_ns`` in a row, out of line between ``low_ns`` and ``high_ns``, are bad ones: the other
    cameras' stamps (``elsewhere_ns``, sorted) go on between those two, and none lies within a frame step of the
    run's (a clock that jumped for every camera at once). From one camera alone a glitch of two frames cannot be
    told from a reset and a jump back forward: not mended."""
    inside = bisect.bisect_right(elsewhere_ns, high_ns) - bisect.bisect_left(elsewhere_ns, low_ns)
    if not inside:
        return False
    step_ns = (high_ns - low_ns) // (len(run_ns) + 1)
    return all(bisect.bisect_right(elsewhere_ns, ns + step_ns) == bisect.bisect_left(elsewhere_ns, ns - step_ns)
               for ns in run_ns)


def _mend_end_runs(mine: list[int], stamps: dict[int, int], others: list[list[int]],
                   period_ns: int) -> list[tuple[int, int]]:
    """Mend ``MENDED_RUN`` stamps at a camera's first (last) frames out of line with the two frames beyond them,
    themselves in line, where the other cameras say so (:func:`_end_run_is_bad`): each played one step further out
    from the nearer of those two. Returns the rows mended with their recorded stamps."""
    mended: list[tuple[int, int]] = []
    if len(mine) < MENDED_RUN + 2 or not others:
        return mended
    elsewhere = sorted(stamps[i] for theirs in others for i in theirs)
    # each end from the take's inside out: the frame beyond, the neighbour, then the run; out: the way stamps go
    for (far, near, *run), out in ((mine[MENDED_RUN + 1::-1], -1), (mine[-MENDED_RUN - 2:], 1)):
        step_ns = (stamps[near] - stamps[far]) * out
        if step_ns > 0 and _end_run_is_bad([stamps[i] for i in run], stamps[near], out, step_ns, period_ns,
                                           elsewhere):
            fixes = [(i, max(0, stamps[near] + out * k * step_ns)) for k, i in enumerate(run, start=1)]
            for i, ns in fixes if out > 0 else fixes[::-1]:  # in recorded order: the warning names the first
                mended.append((i, stamps[i]))
                stamps[i] = ns
    return mended


def _end_run_is_bad(run_ns: list[int], near_ns: int, out: int, step_ns: int, period_ns: int,
                    elsewhere_ns: list[int]) -> bool:
    """Whether stamps ``run_ns`` at a camera's end, from its neighbour ``near_ns`` outward (``out``: +1 the last end,
    -1 the first; ``step_ns`` the camera's step there), are bad ones: each the wrong way or over ``END_STEPS`` times
    its steps out, and so from each other; the other cameras' stamps (``elsewhere_ns``, sorted) going on across the
    run's frames (1.5 to 6 periods out from ``near_ns``) and none within a period of the run's. One side to check
    against (session 73): a camera that began (ended) after (before) the run's frames lends nothing there, one whose
    clock reset or paused with this one's has its stamps by the run's, and two stamps in line with each other may
    be this camera's clock alone gone to a new line and staying there."""
    if any(0 < (ns - near_ns) * out <= END_STEPS * k * step_ns for k, ns in enumerate(run_ns, start=1)):
        return False
    # two in line with each other: as far as the take shows, this camera's clock alone reset or paused there
    if any(0 < (b - a) * out <= END_STEPS * step_ns for a, b in zip(run_ns, run_ns[1:])):
        return False
    low_ns, high_ns = sorted((near_ns + out * 3 * period_ns // 2, near_ns + out * 2 * (len(run_ns) + 1) * period_ns))
    if bisect.bisect_right(elsewhere_ns, high_ns) == bisect.bisect_left(elsewhere_ns, low_ns):
        return False
    return all(bisect.bisect_right(elsewhere_ns, ns + period_ns) == bisect.bisect_left(elsewhere_ns, ns - period_ns)
               for ns in run_ns)


def _jumped_with_them(here_ns: int, low_ns: int, high_ns: int, others: list[list[int]],
                      stamps: dict[int, int]) -> bool:
    """Whether another camera (``others``: rows in recorded order) jumped with a lone stamp ``here_ns`` out of line
    between ``low_ns`` and ``high_ns``: it has a stamp within a frame step of it (half the neighbours' gap) next to
    one within a step of either neighbour. A clock reset, or one then a pause, hits every camera of a synced rig at
    once: mended as a bad stamp, it broke the pairs there (session 73). A glitch an hour off lands near none, or
    (a take longer than the glitch) among stamps that go on in line there, far from its neighbours."""
    step_ns = (high_ns - low_ns) // 2

    def jump(on_ns: int, beside_ns: int) -> bool:
        return abs(on_ns - here_ns) <= step_ns and min(abs(beside_ns - low_ns), abs(beside_ns - high_ns)) <= step_ns

    successive = ((stamps[a], stamps[b]) for theirs in others for a, b in zip(theirs, theirs[1:]))
    return any(jump(a, b) or jump(b, a) for a, b in successive)


def _jumped_at_the_end(end_ns: int, near_ns: int, last: bool, others: list[list[int]], stamps: dict[int, int],
                       period_ns: int) -> bool:
    """Whether another camera (``others``: rows in recorded order) jumped with a camera's first (``last``) stamp
    ``end_ns``: two successive stamps of its, in that order, within ``period_ns`` of the end stamp and of its
    neighbour ``near_ns``. Two cameras' clocks paused at their last frame, a third camera's take ended before: its
    last stamp lay nearer their neighbours, and both ends were mended as bad stamps (session 73 review). In that
    order: in any order, the other cameras' stamps going on in line lie by a stamp a frame or two off and its
    neighbour (a first stamp 47 ms late was kept)."""
    before_ns, after_ns = (near_ns, end_ns) if last else (end_ns, near_ns)
    return any(abs(stamps[a] - before_ns) <= period_ns and abs(stamps[b] - after_ns) <= period_ns
               for theirs in others for a, b in zip(theirs, theirs[1:]))


def _bad_end(end_ns: int, near_ns: int, far_ns: int, elsewhere_ns: list[int]) -> bool:
    """Whether a camera's first (or last) stamp ``end_ns`` is a bad one: the step to the next (previous) stamp
    ``near_ns`` goes the wrong way or is over ``END_STEPS`` times the step on to ``far_ns``, and the other cameras'
    stamps at that end (``elsewhere_ns``) lie nearer ``near_ns`` than it. From one camera alone a bad first stamp
    cannot be told from a clock reset after it (nor a bad last one from a pause): not mended."""
    if not elsewhere_ns:
        return False
    wrong_way = (end_ns - near_ns) * (far_ns - near_ns) > 0
    if not (wrong_way or abs(end_ns - near_ns) > END_STEPS * abs(far_ns - near_ns)):
        return False
    return min(abs(o - near_ns) for o in elsewhere_ns) < min(abs(o - end_ns) for o in elsewhere_ns)


def _recorded_beyond(elsewhere_ns: list[int], near_ns: int, last: bool, period_ns: int) -> bool:
    """Whether another camera recorded at the time of a camera's first (``last``) frame: its first (last) stamp, one
    of ``elsewhere_ns``, half a period or more before (after) that frame's neighbour ``near_ns``. A camera whose
    clock reset at its last frame, after the others' last (before their first), left no other stamp there, and
    its reset was mended as a bad end stamp (session 72's closing note)."""
    way = 1 if last else -1
    return any((ns - near_ns) * way >= period_ns // 2 for ns in elsewhere_ns)


def _across_a_reset(others: list[list[int]], stamps: dict[int, int], last: bool, near_ns: int,
                    period_ns: int) -> list[int]:
    """The other cameras' (``others``: rows in recorded order) stamps across a step back at one end of the take:
    those after each one's last step back (``last``), else before its first, where its stamp on this side of that
    step lies within ``period_ns`` of ``near_ns`` (the end stamp's neighbour: the reset came there); none from a
    camera that never went back, or went back elsewhere (a reset mid-take: its stamps after it span the take's
    rest, and a bad end stamp among them was kept as a reset, session 72 review)."""
    across: list[int] = []
    for theirs in others:
        ns = [stamps[i] for i in theirs]
        backs = [k for k in range(1, len(ns)) if ns[k] < ns[k - 1]]
        if not backs:
            continue
        back = backs[-1] if last else backs[0]
        beside_ns = ns[back - 1] if last else ns[back]
        if abs(beside_ns - near_ns) <= period_ns:
            across += ns[back:] if last else ns[:back]
    return across


def _on_their_reset(end_ns: int, across_ns: list[int], period_ns: int) -> bool:
    """Whether a camera's first (last) stamp ``end_ns``, out of line at its end, lies within ``period_ns`` of another
    camera's stamps across a step back (``across_ns``, :func:`_across_a_reset`): a clock reset that hit that camera
    too, at that place, not a bad stamp. Another camera with one more frame on the new timeline (the old, at the
    first end) has its end stamp nearer this one's neighbour, and the reset was mended as a bad end stamp (session
    72 review)."""
    return any(abs(ns - end_ns) <= period_ns for ns in across_ns)


class ReplayRigSource(RigSource):
    """A recording played back as a rig.

    Args:
        directory: the recording directory.
        manifest, rows: the loaded recording (see :mod:`drivers.backends.recording_format`).
        speed: playback rate, ``None`` for free-running.
        loop: start over at the end.
        keep_time: deliver the recorded timestamps rather than re-stamping them onto ``clock``.
    """

    scheme = "replay"

    def __init__(
        self,
        directory: Path,
        manifest: Manifest,
        rows: list[FrameRow],
        *,
        speed: float | None = 1.0,
        loop: bool = False,
        keep_time: bool = False,
        pairing: PairingConfig | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(manifest.rig, pairing=pairing, clock=clock)
        self.directory = directory
        self.manifest = manifest
        # Each camera in its recorded order, the cameras merged by capture time (re-based after a clock reset).
        self._rows = playback_order(rows, directory)
        self.speed = speed
        self.loop = loop
        self.keep_time = keep_time
        self._cursor = 0
        self._pass = 0
        self._anchor_ns: int | None = None  # clock time at which the first frame is due (set by the first read)
        self._time_span_ns, self._index_span = self._loop_spans()
        self._unloaded: dict[Frame, tuple[FrameRow, int]] = {}  # frames pushed by _catch_up, image not read yet
        self._closing = threading.Event()  # set by close: wakes a read waiting in another thread, stops an open

    @classmethod
    def from_url(cls, url: RigUrl, *, clock: Clock | None = None,
                 pairing: PairingConfig | None = None) -> "ReplayRigSource":
        if not url.target:
            raise RigConfigError(f"rig URL {url.url!r}: give the recording directory, e.g. replay:///data/take1")
        speed = _parse_speed(url)
        loop = url.take_bool("loop", False)
        keep_time = url.take_bool("keep_time", False)
        options = take_pairing_options(url, policy=DropPolicy.ALL)
        url.finish()
        directory = Path(url.target)
        # warned of at open, once per daemon run: the daemon creates a source at each reopen and each reload's check
        manifest = read_manifest(directory, warn=False)
        rows = read_rows(directory, manifest)
        if not manifest.complete:
            rows, broken = broken_rows_split(directory, rows)
            if broken:
                first = broken[0]
                log.warning("recording %s: dropped %d journal row(s) whose files are missing, empty or cut short "
                            "(written after the last flush before the take was cut short), first: %s line %d "
                            "(image %s)", directory, len(broken), directory / FRAMES, first.line, first.image)
            log.warning("recording %s was not closed cleanly%s; playing the %d frames it holds", directory,
                        why_not_closed(manifest), len(rows))
        source = cls(
            directory, manifest, rows, speed=speed, loop=loop, keep_time=keep_time,
            pairing=pairing or options.config(), clock=clock,
        )
        source._rig_read_from(directory / MANIFEST)
        return source

    def _loop_spans(self) -> tuple[int, dict[str, int]]:
        """How far timestamps and per-camera indices move on each loop pass."""
        if not self._rows:
            return 0, {}
        index_span: dict[str, int] = {}
        for cam in self.rig.names:
            indices = [r.index for r in self._rows if r.camera == cam]
            if indices:
                index_span[cam] = max(indices) - min(indices) + 1
        period = frame_period_ns(self._rows)
        return self._rows[-1].timestamp_ns - self._rows[0].timestamp_ns + period, index_span

    def _open(self) -> None:
        # every file of the take is looked at (thousands, on an SD card): a close from another thread stops that
        broken = [(row, rel) for row in self._until_closed(self._rows) for rel in (row.image, row.truth)
                  if rel is not None and not file_is_whole(self.directory / rel)]
        if broken:
            row, rel = min(broken, key=lambda b: b[0].line)
            raise RigInitializationError(
                f"recording {shown(str(self.directory))}: {len(broken)} file(s) listed in {FRAMES} are missing or "
                f"empty, first: {shown(str(self.directory / rel))} "
                f"({shown(str(self.directory / FRAMES))} line {row.line})"
            )
        size_error = self.size_error()
        if size_error is not None:
            raise size_error
        self._stop_if_closed()
        log.info("replaying %s: %d frames, speed %s", self.directory, len(self._rows), self.speed or "free")

    def size_error(self) -> FrameSizeError | RigInitializationError | None:
        """The error of a take whose images are not all its rig's size, else ``None``: the first camera (in the
        rig's order) none of whose images decode (:meth:`_undecodable_refusal`), or with an image of another size
        than its rig camera's.

        Every image is measured at :meth:`open`, from its header (:func:`image_size`: a PNG's, JPEG's (EXIF or
        not: its orientation is ignored, :func:`load_image`) or BMP's size read without decoding it; an image in
        another format, or whose header cannot be read, decoded instead).
        An image that does not decode is no size: left to its read, a corrupt frame, whatever the cause (corrupt,
        or valid but of a layout this OpenCV refuses, :class:`RefusedLayoutError`: its read names the cause); a
        camera none of whose images decode would play nothing, and is refused. Images of another size are
        a take recorded at another size than the rig it carries, its images (all or some) resized by a tool
        after, or its manifest's rig replaced: refused, as each such frame would fail its read (a take resized
        in part played with every such frame skipped; one resized throughout played nothing, and the daemon,
        taking two failed reads before a pair for a failed rig, reopened it from its start for ever).
        Public for ``ghnerf-daemon --validate-config``, which refuses such a take before any open.
        """
        order = recorded_order(self._rows)
        for cam in self.rig.cameras:
            mine = [self._rows[i].image for i in order.get(cam.name, [])]
            sizes = [(rel, image_size(self.directory / rel)) for rel in self._until_closed(mine)]
            if mine and not any(isinstance(size, tuple) for _, size in sizes):
                return self._undecodable_refusal(cam.name, sizes)
            wrong = [(rel, size) for rel, size in sizes
                     if isinstance(size, tuple) and size != (cam.width, cam.height)]
            if wrong:
                return self._size_refusal(cam.name, (cam.width, cam.height), len(mine), wrong)
        return None

    def _undecodable_refusal(self, camera: str,
                             sizes: list[tuple[str, tuple[int, int] | RefusedLayoutError | None]],
                             ) -> RigInitializationError:
        """The error naming the take, ``camera``, none of whose images decode, and the first's cause: an
        :class:`UndecodableImageError` where one is valid but of a layout this OpenCV refuses (the remedy named),
        else a RigInitializationError naming the first file as corrupt."""
        refused = [error for _, error in sizes if isinstance(error, RefusedLayoutError)]
        head = (f"recording {shown(str(self.directory))}: camera {camera!r}: none of its {len(sizes)} images decode, "
                f"nothing of it would play")
        if refused:
            return UndecodableImageError(f"{head} ({len(refused)} of a layout this OpenCV refuses; first: "
                                         f"{refused[0]})")
        return RigInitializationError(f"{head} (first: {shown(str(self.directory / sizes[0][0]))} is corrupt: "
                                      f"OpenCV cannot decode it)")

    def _size_refusal(self, camera: str, expected: tuple[int, int], count: int,
                      wrong: list[tuple[str, tuple[int, int]]]) -> FrameSizeError:
        """The error naming the take, ``camera``, how many of its ``count`` images are of another size (which
        sizes, the first few files) and its rig camera's size in the manifest."""
        found = Counter(size for _, size in wrong)  # in order of first appearance
        sizes = " and ".join(f"{w}x{h}" + (f" ({n})" if len(found) > 1 else "") for (w, h), n in found.items())
        # frames.jsonl's names as written, escaped where one holds a control character (the take's may be anyone's)
        names = (", ".join(shown(rel) for rel, _ in wrong[:SIZE_NAMES_SHOWN])
                 + (", ..." * (len(wrong) > SIZE_NAMES_SHOWN)))
        verb = "is" if len(wrong) == 1 else "are"
        message = (
            f"recording {shown(str(self.directory))}: camera {camera!r}: {len(wrong)} of its {count} images {verb} "
            f"{sizes} ({names}; read from each image's header at open), but its rig camera in "
            f"{shown(str(self.directory / MANIFEST))} is "
            f"{expected[0]}x{expected[1]}: the take was recorded at another size than the rig it carries, its images "
            f"(all or some) were resized after, or its manifest's rig was replaced; play it with the images and "
            f"manifest.json it was recorded with (docs/recording-format.md, 'Image sizes')"
        )
        return FrameSizeError(message, camera, expected, wrong[0][1])

    def _next(self) -> tuple[FrameRow, int] | None:
        """The row played next and its loop pass's timestamp shift; ``None`` at the end (no loop)."""
        cursor, passes = self._cursor, self._pass
        if cursor >= len(self._rows):
            if not (self.loop and self._rows):
                return None
            cursor, passes = 0, passes + 1
        return self._rows[cursor], passes * self._time_span_ns

    def _advance(self) -> None:
        if self._cursor >= len(self._rows):
            self._cursor, self._pass = 0, self._pass + 1
        self._cursor += 1

    def _read_frame(self, timeout_s: float) -> Frame | None:
        upcoming = self._next()
        if upcoming is None:
            raise EndOfStream(f"recording {shown(str(self.directory))} ended after {len(self._rows)} frames")
        row, shift_ns = upcoming
        if self._anchor_ns is None:
            self._start_playing()
        assert self._anchor_ns is not None
        if self.speed is not None:
            due = self._due_ns(row, shift_ns, self._anchor_ns, self.speed)
            deadline = self.clock.now_ns() + int(timeout_s * 1e9)
            if due > deadline:
                self._wait_until(deadline)
                return None
            self._wait_until(due)
        self._advance()
        frame = self._load(row, shift_ns)
        if self._closing.is_set():  # closed while the files were read: a closed source hands out no frame
            raise self._closed_while_reading()
        return frame

    def _wait_until(self, when_ns: int) -> None:
        """Sleeps on the clock until ``when_ns``; a close from another thread meanwhile ends the wait at once."""
        self.clock.wait_until(when_ns, self._closing)
        if self._closing.is_set():
            raise self._closed_while_reading()

    def _closed_while_reading(self) -> RigOperationError:
        """What a read raises when another thread closes the source under it."""
        return RigOperationError(f"replay of {shown(str(self.directory))} closed while a read waited for its frame")

    def _start_playing(self) -> None:
        """Anchor playback (pacing and re-stamping) at the clock's now: the first frame plays now."""
        self._anchor_ns = self.clock.now_ns()
        if not self.keep_time and self._rows:
            # Logged so a stream can be matched with the take (recorded = delivered + offset).
            log.info("replay %s: frames stamped on this clock; recorded time = stamp %+d ns (keep_time=1: "
                     "the recorded stamps)", self.directory, self._rows[0].timestamp_ns - self._anchor_ns)

    @property
    def live_timestamps(self) -> bool:  # type: ignore[override]
        """Re-stamped frames played at the recorded pace carry the time they play, as a live rig's would."""
        return not self.keep_time and self.speed == 1.0

    def _due_ns(self, row: FrameRow, shift_ns: int, anchor_ns: int, speed: float) -> int:
        """Clock time at which ``row`` (on the loop pass shifted by ``shift_ns``) plays."""
        return anchor_ns + int((row.timestamp_ns + shift_ns - self._rows[0].timestamp_ns) / speed)

    def _due_now(self) -> tuple[FrameRow, int] | None:
        """The next row and its shift if it is due by now (paced playback, once started), else ``None``."""
        # Unpaced playback has every frame at hand: draining would read the whole recording.
        if self.speed is None or self._anchor_ns is None:
            return None
        upcoming = self._next()  # None at the end: the next read raises EndOfStream, after the pairs due
        if upcoming is None or self._due_ns(*upcoming, self._anchor_ns, self.speed) > self.clock.now_ns():
            return None
        return upcoming

    def _frame_available(self) -> bool:
        return self._due_now() is not None

    @property
    def drain_limit(self) -> int:  # type: ignore[override]
        """Every row due by now (paced playback holds no queue: all of them wait); at least the default.
        A read alone skips them in :meth:`_catch_up`; a recorder around this source drains them all."""
        if self.speed is None or self._anchor_ns is None or not self._rows:
            return RigSource.drain_limit
        now, n, cursor, passes = self.clock.now_ns(), 0, self._cursor, self._pass
        while True:
            if cursor >= len(self._rows):
                if not self.loop:
                    break
                cursor, passes = 0, passes + 1
            if self._due_ns(self._rows[cursor], passes * self._time_span_ns, self._anchor_ns, self.speed) > now:
                break
            n, cursor = n + 1, cursor + 1
        return max(n, RigSource.drain_limit)

    def _catch_up(self, pairer: FramePairer) -> None:
        """Push every row due by now without reading its files, then load those the pairer still holds
        (the newest pair, partners awaited): however far behind the reader, a read decodes a pair or
        two, and the skipped rows count as they would live (dropped pairs, unpaired frames)."""
        while (due := self._due_now()) is not None:
            row, shift_ns = due
            self._advance()
            frame = self._frame(row, shift_ns, _NOT_LOADED, None, None)
            self._unloaded[frame] = due
            pairer.push(frame)
        if not self._unloaded:
            return
        errors: list[RigOperationError] = []
        try:
            pairer.replace_held(lambda frame: self._loaded(frame, errors))
        finally:
            self._unloaded.clear()  # the rest went into dropped pairs or were unpaired
        if errors:
            # A row that cannot be loaded (corrupt, wrong size) leaves the pairer with its frame, and the
            # error is raised once, as a paced read without catching up would: the next read goes on.
            pairer.discard_held(lambda frame: frame.image is _NOT_LOADED)
            raise errors[0]

    def _loaded(self, frame: Frame, errors: list[RigOperationError]) -> Frame:
        due = self._unloaded.get(frame)
        if due is None:
            return frame
        try:
            return self._load(*due)
        except RigOperationError as e:
            errors.append(e)
            return frame  # still the placeholder: discarded after

    def _load(self, row: FrameRow, shift_ns: int) -> Frame:
        path = self.directory / row.image
        image = load_image(path)
        cam = self.rig.camera(row.camera)
        if image.shape != (cam.height, cam.width, 3):
            # Not a FrameSizeError: every image of the take had the rig's size at open (size_error), so this one
            # file changed since, a corrupt frame the next read goes past. Typed as a size, it would read to a
            # daemon as a rig that does not fit: the take reopened from its start, then a stop.
            raise RigOperationError(
                f"recording image {shown(str(path))} is {image.shape[1]}x{image.shape[0]}, but the rig's camera "
                f"{row.camera!r} is {cam.width}x{cam.height} as the take's images were at open: this file was "
                f"corrupted or edited since, a corrupt frame (the next read goes on)"
            )
        truth, joints_3d = load_truth(self.directory / row.truth) if row.truth is not None else (None, None)
        return self._frame(row, shift_ns, image, truth, joints_3d)

    def _frame(self, row: FrameRow, shift_ns: int, image: np.ndarray, truth: CameraTruth | None,
               joints_3d: np.ndarray | None) -> Frame:
        passes = shift_ns // self._time_span_ns if self._time_span_ns else 0
        # Re-stamped: the same distance from the first frame, measured from the clock time playback started.
        origin = 0 if self.keep_time or self._anchor_ns is None else self._anchor_ns - self._rows[0].timestamp_ns
        return Frame(
            camera=row.camera,
            image=image,
            timestamp_ns=row.timestamp_ns + shift_ns + origin,
            index=row.index + passes * self._index_span.get(row.camera, 0),
            truth=truth,
            scene_time_s=row.scene_time_s,
            joints_3d=joints_3d,
        )

    def _until_closed(self, items: Iterable[_Item]) -> Iterator[_Item]:
        """``items``, each checked first that no close from another thread cancelled the open (raising then)."""
        for item in items:
            self._stop_if_closed()
            yield item

    def _stop_if_closed(self) -> None:
        if self._closing.is_set():
            raise RigInitializationError(f"recording {shown(str(self.directory))}: closed while open() checked the "
                                         "take's files: the open was cancelled")

    def _cancel_open(self) -> None:
        self._closing.set()  # the open's checks stop at the next file (_until_closed)

    def _close(self) -> None:
        self._closing.set()  # files are opened per frame: nothing else is held
