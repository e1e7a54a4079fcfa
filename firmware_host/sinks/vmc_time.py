"""/VMC/Ext/T: seconds since the sink's first frame, never going back.

Capture stamps can go back: a camera clock reset, a replay that loops, a daemon restarted on a recording.
VMC receivers (VSeeFace, EVMC4U, VirtualMotionCapture) take T as a time that only moves forward; a jump back
can make one drop frames as stale or interpolate backwards. So a stamp earlier than the one before it starts a
new stretch: its frame reads the last T sent plus one frame interval, and the frames after it count on from
there. The frame interval is the lower median of the last ``STEPS_KEPT`` forward steps between stamps (nothing
before the first step): jittery stamps, a driver hiccup that stamps two frames 1 ms apart, or a pause of seconds
each move it by at most one rank. Until session 71 it was the smallest step seen, which jitter made far shorter
than a frame. The first jump back is logged once per sink; later ones only counted (``jumps_back``).

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
#: hiccup, a pause, frames the sink dropped) leave it alone.
STEPS_KEPT = 15


class VmcClock:
    """Capture stamps (microseconds) -> /VMC/Ext/T seconds, monotonic non-decreasing; one per sink."""

    def __init__(self, shown: str) -> None:
        self._shown = shown  # the sink as its logs name it
        self._base_us: Optional[int] = None  # the stamp that reads ``_base_t_us``
        self._base_t_us = 0
        self._last_us: Optional[int] = None  # the previous frame's stamp
        self._last_t_us = 0  # the T sent with it
        self._steps_us: deque[int] = deque(maxlen=STEPS_KEPT)  # the last forward steps between stamps
        self.jumps_back = 0

    def seconds(self, capture_time_us: int) -> float:
        """T for a frame stamped ``capture_time_us``."""
        if self._last_us is None:
            self._base_us = capture_time_us
        elif capture_time_us < self._last_us:
            self._restart_after_jump_back(capture_time_us)
        elif capture_time_us > self._last_us:
            self._steps_us.append(capture_time_us - self._last_us)
        assert self._base_us is not None
        self._last_us = capture_time_us
        self._last_t_us = self._base_t_us + capture_time_us - self._base_us
        return self._last_t_us / 1e6

    def frame_step_us(self) -> int:
        """The frame interval T moves on by across a jump back: the lower median of the kept forward steps (the
        lower one, so one pause among two steps is not it), 0 before the first step."""
        if not self._steps_us:
            return 0
        return sorted(self._steps_us)[(len(self._steps_us) - 1) // 2]

    def _restart_after_jump_back(self, capture_time_us: int) -> None:
        assert self._last_us is not None
        if self.jumps_back == 0:  # once: a looping replay would otherwise log every loop
            _log.warning("%s: capture time went back %.3f s (camera clock reset or replay loop); /VMC/Ext/T "
                         "counts on from %.3f s (later jumps back are not logged)", self._shown,
                         (self._last_us - capture_time_us) / 1e6, self._last_t_us / 1e6)
        self.jumps_back += 1
        self._base_us = capture_time_us
        self._base_t_us = self._last_t_us + self.frame_step_us()
