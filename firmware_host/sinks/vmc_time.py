"""/VMC/Ext/T: seconds since the sink's first frame, never going back.

Capture stamps can go back: a camera clock reset, a replay that loops, a daemon restarted on a recording.
VMC receivers (VSeeFace, EVMC4U, VirtualMotionCapture) take T as a time that only moves forward; a jump back
can make one drop frames as stale or interpolate backwards. So a stamp earlier than the one before it starts a
new stretch: its frame reads the last T sent plus the smallest forward step seen so far (about one frame
interval, whatever gaps came before; nothing before the first step), and the frames after it count on from
there. The first jump back is logged once per sink; later ones only counted (``jumps_back``).

Seconds since the first frame, not since boot: OSC floats are float32 (about 1 ms resolution after an hour,
2 ms after four).
"""
from __future__ import annotations

import logging
from typing import Optional

_log = logging.getLogger(__name__)


class VmcClock:
    """Capture stamps (microseconds) -> /VMC/Ext/T seconds, monotonic non-decreasing; one per sink."""

    def __init__(self, shown: str) -> None:
        self._shown = shown  # the sink as its logs name it
        self._base_us: Optional[int] = None  # the stamp that reads ``_base_t_us``
        self._base_t_us = 0
        self._last_us: Optional[int] = None  # the previous frame's stamp
        self._last_t_us = 0  # the T sent with it
        self._frame_step_us = 0  # the smallest forward step between stamps: about one frame interval
        self.jumps_back = 0

    def seconds(self, capture_time_us: int) -> float:
        """T for a frame stamped ``capture_time_us``."""
        if self._last_us is None:
            self._base_us = capture_time_us
        elif capture_time_us < self._last_us:
            self._restart_after_jump_back(capture_time_us)
        elif capture_time_us > self._last_us:
            self._note_step(capture_time_us - self._last_us)
        assert self._base_us is not None
        self._last_us = capture_time_us
        self._last_t_us = self._base_t_us + capture_time_us - self._base_us
        return self._last_t_us / 1e6

    def _restart_after_jump_back(self, capture_time_us: int) -> None:
        assert self._last_us is not None
        if self.jumps_back == 0:  # once: a looping replay would otherwise log every loop
            _log.warning("%s: capture time went back %.3f s (camera clock reset or replay loop); /VMC/Ext/T "
                         "counts on from %.3f s (later jumps back are not logged)", self._shown,
                         (self._last_us - capture_time_us) / 1e6, self._last_t_us / 1e6)
        self.jumps_back += 1
        self._base_us = capture_time_us
        self._base_t_us = self._last_t_us + self._frame_step_us

    def _note_step(self, step_us: int) -> None:
        self._frame_step_us = min(self._frame_step_us, step_us) if self._frame_step_us else step_us
