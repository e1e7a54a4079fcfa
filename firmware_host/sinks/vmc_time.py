"""/VMC/Ext/T: seconds since the sink's first frame, never going back, and not thrown off by a glitched stamp.

Capture stamps can go back: a camera clock reset, a replay that loops, a daemon restarted on a recording.
VMC receivers (VSeeFace, EVMC4U, VirtualMotionCapture) take T as a time that only moves forward; a jump back
can make one drop frames as stale or interpolate backwards. A stamp can also be one bad value (a driver that
stamped one frame 0 in a stream at 3,600 s): following it, T was thrown an hour ahead for good, since the real
stamps after it read as a forward step of an hour (session 71).

So T follows one timeline of stamps. A stamp that leaves it (earlier than the one before, or later by more than
``JUMP_FRAMES`` frame intervals) reads the last T sent plus one frame interval; the timeline before is kept. If a
later stamp is back on it (at most ``JUMP_FRAMES`` frame intervals past its last stamp, plus one per odd frame
since), T resumes from it as if the odd frames were normal ones: a glitch (``glitches``). A stamp also one frame on
from the odd one before it, and more than a frame short of where the timeline's stamps would be by then, is not
back: the stamps went back a frame or two and stay (a clock resync; read as a glitch until session 73, T repeating
for two or three frames); an extra odd stamp a frame or two back leaves the stream at most a frame short. If the
stamps stay on the new timeline for ``NEW_TIMELINE_FRAMES`` frames, T follows them: a jump back (a reset, a loop:
``jumps_back``) counts on from the first odd frame's T, as T did before anyway; a jump forward (a pause) adds the
pause to T in one step, on the last of those frames, so a receiver that interpolates on T still sees the pause, two
frames late. T is never below the last T sent: a lone stamp a few frames ahead (a step T follows) moves T on by at
most ``JUMP_FRAMES`` intervals, and the stamps after it, a little back, then read the same T until they pass it.
The first glitch and the first jump back are each logged once per sink; later ones only counted.

Before the first forward step the frame interval is a nominal one: the sink's ``fps`` (the producer's rate), else
``DEFAULT_FPS``, capped at its ``max_fps``. So a glitched second stamp leaves the timeline like any other, and a
glitched first one is left by the stamps after it: until session 72 every first forward step was followed, and
either moved T by the glitch (an hour), once. A first stamp that the next ``NEW_TIMELINE_FRAMES`` leave forward is
no timeline to pause on: T counts on from it, as after a jump back (a real pause after the first frame is not added
to T); stamps that come back to it settle it only as a new timeline is settled, ``NEW_TIMELINE_FRAMES`` distinct
ones (until session 73 two, near a glitched first, took the stream after them for a pause of the glitch). A camera
under a quarter of the nominal rate leaves it too at its first two frames, which read one nominal interval on each;
their steps, alike, become the interval, and T catches up on the third frame (not sooner: two glitched stamps an
hour apart step alike too); stamps that only stepped forward and come back are no glitch (not counted, not logged).
A stamp repeated on a new timeline is no evidence for it: T follows it only once its stamps move on (a driver that
stamped three frames with one bad value moved T to it, then an hour on when the stamps came back, until session
72).

The frame interval is the lower median of the last ``STEPS_KEPT`` forward steps between stamps on one timeline:
jittery stamps, a driver hiccup that stamps two frames 1 ms apart, or a gap of a few frames each move it by at most
one rank. Until session 71 it was the smallest step seen, which jitter made far shorter than a frame. Stamps that
leave the timeline at every frame, stepping on at a steady pace (within ``JUMP_FRAMES`` times the step before), add
their steps too: a camera slowed to under a quarter of its rate, or a first step of 1 ms (a hiccup), left it at
every frame for good, T creeping on by the stale interval. Only frames leaving one after another keep a pace, and
the steps of odd frames the stream then comes back below are dropped: two glitches an hour apart stepped alike, and
until session 73 that hour became the interval, which T moved on by at the next jump. So are those of odd frames
before one that goes back (a steady pace never does), and a step from a frame that went back keeps no pace: at 10
or 5 fps a glitched first stamp, the stream, then a glitch an hour on stepped alike, and that hour moved T on.

Seconds since the first frame, not since boot: OSC floats are float32, whose steps grow with T (0.25 ms after an
hour, 1 ms after four, 16 ms after 36 hours). From 2**19 s (six days) on a step is 62.5 ms, so two frames of a
30 fps stream can send the same T; never a smaller one, since rounding keeps the order.
"""
from __future__ import annotations

import logging
from collections import deque
from typing import Optional

_log = logging.getLogger(__name__)

#: Forward steps whose median is the frame interval: odd, so the median is a step that was seen; half a second at
#: 30 fps, so a camera switched to another rate is followed within 8 frames, and up to 7 odd steps (jitter, a
#: hiccup, a gap, frames the sink dropped) leave it alone.
STEPS_KEPT = 15

#: A forward step of more than this many frame intervals leaves the timeline. Three frames lost in a row (by the
#: camera, or the sink's queue) are still a step T follows at once; beyond, one frame cannot tell a pause from a
#: lone stamp far ahead, and T waits. It is also the most a lone stamp a little ahead can move T forward.
JUMP_FRAMES = 4

#: The frame rate assumed before the first forward step, where the sink names none: most cameras here run at 30
#: fps. A camera under a quarter of it (7.5 fps) leaves the timeline at its first steps, and T catches up with it
#: in one step on the third frame (its steady steps become the interval).
DEFAULT_FPS = 30.0

#: Frames in a row on a new timeline (the first odd one included) before T follows it: one or two glitched stamps
#: in a row are stepped over, and a pause reaches T two frames (67 ms at 30 fps) late. Not one: a pause's first two
#: frames look like two glitched stamps a frame apart, and following those threw T an hour ahead for good.
NEW_TIMELINE_FRAMES = 3


class _Timeline:
    """Stamps that read T by one offset: ``base_us`` reads ``base_t_us``."""

    def __init__(self, base_us: int, base_t_us: int) -> None:
        self.base_us = base_us
        self.base_t_us = base_t_us

    def t_us(self, capture_time_us: int) -> int:
        return self.base_t_us + capture_time_us - self.base_us


def nominal_step_us(fps: Optional[float] = None, max_fps: Optional[float] = None) -> int:
    """The frame interval (us) before any step is seen: the producer's rate ``fps``, else ``DEFAULT_FPS``, capped
    at ``max_fps`` (the frames it lets through); a cap alone says only how fast the frames can come."""
    rate = DEFAULT_FPS if fps is None else fps
    return max(1, round(1e6 / min(rate, max_fps if max_fps is not None else rate)))


class VmcClock:
    """Capture stamps (microseconds) -> /VMC/Ext/T seconds, monotonic non-decreasing; one per sink."""

    def __init__(self, shown: str, nominal_us: Optional[int] = None) -> None:
        self._shown = shown  # the sink as its logs name it
        self._nominal_us = nominal_step_us() if nominal_us is None else nominal_us  # the interval before a step
        self._line: Optional[_Timeline] = None  # the timeline T follows
        self._line_last_us = 0  # the last stamp on it
        self._line_step_us = 0  # the forward step into it on the line (0: none, or the stamps came back to it)
        self._line_stamps = 0  # distinct stamps read on it frame after frame (a taken new line counts as settled)
        self._line_settles_at = 2  # stamps that settle it: a pause from it is added to T (more after a way back)
        self._new: Optional[_Timeline] = None  # where the stamps went when they left it, until decided
        self._new_frames = 0  # frames in a row on ``_new``
        self._leave_step_us = 0  # the forward step into the last frame that left a timeline (0: none, -1: back)
        self._left_forward = False  # every frame off the line so far stepped forward
        self._first_us = 0  # the first frame's stamp
        self._last_us = 0  # the previous frame's stamp
        self._last_t_us = 0  # the T sent with it
        self._steps_us: deque[int] = deque(maxlen=STEPS_KEPT)  # the last forward steps between stamps
        self._steps_on_the_line: tuple[int, ...] = ()  # ``_steps_us`` as the stamps left the line
        self.jumps_back = 0  # new timelines earlier than the one before, followed
        self.glitches = 0  # times the stamps left the timeline for a frame or two, then came back to it

    def seconds(self, capture_time_us: int) -> float:
        """T for a frame stamped ``capture_time_us``."""
        if self._line is None:
            self._line = _Timeline(capture_time_us, 0)
            self._first_us = self._line_last_us = capture_time_us  # not 0: a second stamp below it is off the line
            self._line_stamps = 1
            t_us = 0
        elif self._new is None:
            t_us = self._on_the_line(capture_time_us)
        else:
            t_us = self._off_the_line(capture_time_us)
        self._last_us = capture_time_us
        self._last_t_us = max(t_us, self._last_t_us)  # never back, e.g. an extra glitched frame's step
        return self._last_t_us / 1e6

    def frame_step_us(self) -> int:
        """The frame interval T moves on by across a jump: the lower median of the kept forward steps (the
        lower one, so one pause among two steps is not it), the nominal one before the first step."""
        if not self._steps_us:
            return self._nominal_us
        return sorted(self._steps_us)[(len(self._steps_us) - 1) // 2]

    def _follows(self, previous_us: int, capture_time_us: int, frames: int = 1) -> bool:
        """Whether a stamp ``frames`` frames after one stamped ``previous_us`` is on its timeline."""
        ahead_us = capture_time_us - previous_us
        return 0 <= ahead_us <= (frames - 1 + JUMP_FRAMES) * self.frame_step_us()

    def _on_the_line(self, capture_time_us: int) -> int:
        assert self._line is not None
        if not self._follows(self._last_us, capture_time_us):
            return self._leave(capture_time_us)
        self._step(capture_time_us)
        if capture_time_us > self._line_last_us:  # a repeated stamp is no more of the line
            self._line_stamps += 1
            self._line_step_us = capture_time_us - self._line_last_us
        self._line_last_us = capture_time_us
        return self._line.t_us(capture_time_us)

    def _off_the_line(self, capture_time_us: int) -> int:
        assert self._line is not None and self._new is not None
        left_again = not self._follows(self._last_us, capture_time_us)
        on_the_new_line = not left_again and self._short_of_the_line(capture_time_us)
        if self._follows(self._line_last_us, capture_time_us, self._new_frames + 1) and not on_the_new_line:
            return self._back_on_the_line(capture_time_us)
        if left_again:
            return self._leave(capture_time_us)  # off again, elsewhere: the line is still the one to come back to
        self._step(capture_time_us)
        self._new_frames += 1
        self._leave_step_us = 0  # a steady pace is frames leaving one after another, not across frames on ``_new``
        t_us = self._new.t_us(capture_time_us)
        if self._new_frames >= NEW_TIMELINE_FRAMES and capture_time_us > self._new.base_us:  # moved on: no repeat
            t_us = self._take_the_new_line(capture_time_us, t_us)
        return t_us

    def _short_of_the_line(self, capture_time_us: int) -> bool:
        """Whether a stamp one frame on from the last (off the line) is more than a frame short of where the line's
        stamps would be by now: a jump back of a frame or two that stays, not a glitch the stream comes back from
        (read as one until session 73: T repeated for two or three frames). Judged leniently: from the stamp
        before the line's last where that step was long (a stamp a little ahead, the stream then back under it,
        is a glitch), and an extra odd frame a frame back is within the frame."""
        step_us = self.frame_step_us()
        line_us = self._line_last_us + (self._new_frames + 1) * step_us - max(0, self._line_step_us - step_us)
        return line_us - capture_time_us - abs(capture_time_us - self._last_us - step_us) > step_us

    def _leave(self, capture_time_us: int) -> int:
        """The first frame off the line: one frame interval on, the stamps' new timeline kept."""
        if self._new is None:
            self._steps_on_the_line = tuple(self._steps_us)
        elif capture_time_us < self._last_us:
            # a steady pace never goes back: steps of frames off the line before it were glitches stepping alike
            # (two an hour apart after the stream's frame, at 5 fps): that hour moved T on here (session 73 review)
            self._steps_us = deque(self._steps_on_the_line, maxlen=STEPS_KEPT)
        self._left_forward = capture_time_us > self._last_us and (self._new is None or self._left_forward)
        self._new = _Timeline(capture_time_us, self._last_t_us + self._jump_step_us(capture_time_us))
        self._new_frames = 1
        self._count_a_steady_leave(capture_time_us - self._last_us)
        return self._new.base_t_us

    def _jump_step_us(self, capture_time_us: int) -> int:
        """What T moves on by for a frame off the line: the frame interval, but nothing where the one step seen
        so far may be the glitch itself (a second frame stamped a few frames on, then one back, not before the
        first): that step as the interval moved T on by it again at each frame off the line (session 71)."""
        if len(self._steps_us) == 1 and self._first_us <= capture_time_us < self._last_us:
            return 0
        return self.frame_step_us()

    def _count_a_steady_leave(self, step_us: int) -> None:
        """Keep a forward step that left a timeline as the one before did, at a like pace (a camera slowed past
        ``JUMP_FRAMES`` times the interval), so the interval can follow it; a glitch and the stamp back from it
        are no steady pace. Counted once the frame is placed: two steps off the line alike may be two glitched
        stamps alike (an hour apart: counted first, that hour was the interval at once, and T followed it)."""
        before_us = self._leave_step_us
        # a step from a frame that went back may be from a glitch to the stream, then one an hour on: alike (at 10 fps
        # the hour was the interval, T then an hour on at a repeat of it; session 73 review): no pace to count from
        self._leave_step_us = -1 if step_us <= 0 else 0 if before_us < 0 else step_us
        if before_us > 0 and step_us > 0 and step_us <= JUMP_FRAMES * before_us and before_us <= JUMP_FRAMES * step_us:
            self._steps_us.append(step_us)

    def _back_on_the_line(self, capture_time_us: int) -> int:
        assert self._line is not None and self._new is not None
        if not (self._left_forward and capture_time_us >= self._last_us):
            self._count_a_glitch()
            # the odd frames' steps were no camera's: two glitches an hour apart stepped "steadily", and that hour
            # became the interval T then moved on by at a jump (the property check's seed 119515, session 73)
            self._steps_us = deque(self._steps_on_the_line, maxlen=STEPS_KEPT)
        # else no stamp went back: late frames on the line, read again at a longer interval (a slow camera)
        if self._line_stamps < self._line_settles_at:
            self._unsettle_the_line(capture_time_us)
        self._new, self._leave_step_us, self._line_step_us = None, 0, 0
        self._line_last_us = capture_time_us
        return self._line.t_us(capture_time_us)

    def _unsettle_the_line(self, capture_time_us: int) -> None:
        """Stamps back on the first stamp's line, not yet settled (``_line_settles_at``), may be glitches near a
        glitched first: a lone one, or one repeated, took the stream after it for a pause of the glitch (session 72),
        and so did two different ones (until session 73). The line settles as a new one would:
        ``NEW_TIMELINE_FRAMES`` stamps from this one."""
        self._line_stamps = int(capture_time_us > self._line_last_us)
        self._line_settles_at = NEW_TIMELINE_FRAMES

    def _count_a_glitch(self) -> None:
        assert self._new is not None
        if self.glitches == 0:  # once: a driver that glitches every minute would otherwise log every minute
            _log.warning("%s: %d capture stamp(s) left the stream's timeline (%+.3f s) and it came back; "
                         "/VMC/Ext/T stepped over them (later glitches are not logged)", self._shown,
                         self._new_frames, (self._new.base_us - self._line_last_us) / 1e6)
        self.glitches += 1

    def _take_the_new_line(self, capture_time_us: int, t_us: int) -> int:
        """The stamps stayed on the new timeline: a pause keeps the line (T catches up), a jump back follows it, and
        so does a jump forward from a line that read no second stamp frame after frame: a glitched first stamp (a later
        glitch back near it, a stamp repeated, came back to it, not after it): no pause to add."""
        assert self._line is not None and self._new is not None
        paused = self._new.base_us >= self._line_last_us
        if paused and self._line_stamps >= self._line_settles_at:
            t_us = self._line.t_us(capture_time_us)
        else:
            if not paused:
                self._log_jump_back(self._new)
            self._line = self._new
            self._line_stamps = NEW_TIMELINE_FRAMES
        self._new, self._leave_step_us, self._line_step_us = None, 0, 0
        self._line_last_us = capture_time_us
        return t_us

    def _log_jump_back(self, new: _Timeline) -> None:
        if self.jumps_back == 0:  # once: a looping replay would otherwise log every loop
            _log.warning("%s: capture time went back %.3f s (camera clock reset or replay loop); /VMC/Ext/T "
                         "counts on from %.3f s (later jumps back are not logged)", self._shown,
                         (self._line_last_us - new.base_us) / 1e6, new.base_t_us / 1e6)
        self.jumps_back += 1

    def _step(self, capture_time_us: int) -> None:
        # steps on a new timeline count before it is decided: two glitched stamps in a row add one odd step
        if capture_time_us > self._last_us:
            self._steps_us.append(capture_time_us - self._last_us)
