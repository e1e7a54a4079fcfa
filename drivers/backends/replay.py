"""``replay:///path/to/take``: play back a recording made by ``record+<url>``.

URL options:

* ``speed``: ``recorded`` (default) honours the recorded inter-frame timing on the
  injected clock; ``free`` delivers frames as fast as they decode; a number
  (``speed=2``) plays at that multiple of real time.
* ``loop``: ``1`` starts over at the end instead of raising :class:`EndOfStream`.
* ``tolerance_ms``, ``policy``: pairing (default policy ``all``: a recording is
  usually processed offline, every pair counts). ``policy=latest`` with a paced
  ``speed`` plays like a live rig: a slow reader gets the newest pair due and the
  older ones are dropped (counted); free-running playback never skips ahead.

Frames carry the recorded timestamps, indices and ground truth unchanged on the
first pass. Each further ``loop`` pass shifts timestamps by the recording's span
(plus one frame period) and indices by the per-camera count, so both keep
increasing per camera. Layout and validation: docs/recording-format.md.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from drivers.backends.recording_format import FrameRow, Manifest, load_image, load_truth, read_manifest, read_rows
from drivers.base import RigSource
from drivers.clock import Clock
from drivers.errors import EndOfStream, RigConfigError, RigInitializationError, RigOperationError
from drivers.frames import Frame
from drivers.pairing import DropPolicy, PairingConfig
from drivers.url import RigUrl

log = logging.getLogger(__name__)


def _parse_speed(url: RigUrl) -> float | None:
    """``None`` for free-running, else the playback rate (1.0 = as recorded)."""
    raw = url.take_str("speed", "recorded")
    if raw == "recorded":
        return 1.0
    if raw == "free":
        return None
    try:
        speed = float(raw)  # type: ignore[arg-type]
    except ValueError:
        speed = float("nan")
    if not speed > 0 or speed == float("inf"):
        raise RigConfigError(f"rig URL {url.url!r}: option speed={raw!r} must be 'recorded', 'free' or a number > 0")
    return speed


class ReplayRigSource(RigSource):
    """A recording played back as a rig.

    Args:
        directory: the recording directory.
        manifest, rows: the loaded recording (see :mod:`drivers.backends.recording_format`).
        speed: playback rate, ``None`` for free-running.
        loop: start over at the end.
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
        pairing: PairingConfig | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(manifest.rig, pairing=pairing, clock=clock)
        self.directory = directory
        self.manifest = manifest
        # Capture order across cameras; stable, so each camera keeps its recorded order.
        self._rows = sorted(rows, key=lambda r: r.timestamp_ns)
        self.speed = speed
        self.loop = loop
        self._cursor = 0
        self._pass = 0
        self._anchor_ns: int | None = None  # clock time at which the first frame is due (set by the first read)
        self._time_span_ns, self._index_span = self._loop_spans()

    @classmethod
    def from_url(cls, url: RigUrl, *, clock: Clock | None = None, pairing: PairingConfig | None = None) -> "ReplayRigSource":
        if not url.target:
            raise RigConfigError(f"rig URL {url.url!r}: give the recording directory, e.g. replay:///data/take1")
        speed = _parse_speed(url)
        loop = url.take_bool("loop", False)
        tolerance = url.take_float("tolerance_ms", PairingConfig.tolerance_ms, lo=0.001)
        policy = url.take_str("policy", DropPolicy.ALL.value, choices=tuple(p.value for p in DropPolicy))
        url.finish()
        directory = Path(url.target)
        manifest = read_manifest(directory)
        rows = read_rows(directory, manifest)
        if not manifest.complete:
            log.warning("recording %s was not closed cleanly; playing the %d frames it holds", directory, len(rows))
        return cls(
            directory, manifest, rows, speed=speed, loop=loop,
            pairing=pairing or PairingConfig(tolerance_ms=tolerance, policy=DropPolicy(policy)), clock=clock,
        )

    def _loop_spans(self) -> tuple[int, dict[str, int]]:
        """How far timestamps and per-camera indices move on each loop pass."""
        if not self._rows:
            return 0, {}
        periods = []
        index_span: dict[str, int] = {}
        for cam in self.rig.names:
            mine = [r for r in self._rows if r.camera == cam]
            if not mine:
                continue
            stamps = np.array([r.timestamp_ns for r in mine], dtype=np.int64)
            if stamps.size > 1:
                periods.append(float(np.median(np.diff(stamps))))
            indices = [r.index for r in mine]
            index_span[cam] = max(indices) - min(indices) + 1
        period = int(np.median(periods)) if periods else 33_333_333
        return self._rows[-1].timestamp_ns - self._rows[0].timestamp_ns + max(period, 1), index_span

    def _open(self) -> None:
        missing = []
        for row in self._rows:
            for rel in (row.image, row.truth):
                if rel is not None and not (self.directory / rel).is_file():
                    missing.append(rel)
        if missing:
            raise RigInitializationError(
                f"recording {self.directory}: {len(missing)} file(s) listed in frames.jsonl are missing, "
                f"first: {self.directory / missing[0]}"
            )
        log.info("replaying %s: %d frames, speed %s", self.directory, len(self._rows), self.speed or "free")

    def _read_frame(self, timeout_s: float) -> Frame | None:
        if self._cursor >= len(self._rows):
            if not (self.loop and self._rows):
                raise EndOfStream(f"recording {self.directory} ended after {len(self._rows)} frames")
            self._cursor = 0
            self._pass += 1
        row = self._rows[self._cursor]
        shift_ns = self._pass * self._time_span_ns
        if self.speed is not None:
            if self._anchor_ns is None:
                self._anchor_ns = self.clock.now_ns()
            due = self._due_ns(row, shift_ns, self._anchor_ns, self.speed)
            deadline = self.clock.now_ns() + int(timeout_s * 1e9)
            if due > deadline:
                self.clock.sleep_until(deadline)
                return None
            self.clock.sleep_until(due)
        self._cursor += 1
        return self._load(row, shift_ns)

    def _due_ns(self, row: FrameRow, shift_ns: int, anchor_ns: int, speed: float) -> int:
        """Clock time at which ``row`` (on the loop pass shifted by ``shift_ns``) plays."""
        return anchor_ns + int((row.timestamp_ns + shift_ns - self._rows[0].timestamp_ns) / speed)

    def _frame_available(self) -> bool:
        # Unpaced playback has every frame at hand: draining would read the whole recording.
        if self.speed is None or self._anchor_ns is None:
            return False
        cursor, shift_ns = self._cursor, self._pass * self._time_span_ns
        if cursor >= len(self._rows):
            if not (self.loop and self._rows):
                return False  # the end: the next read raises EndOfStream, after the pairs already due
            cursor, shift_ns = 0, shift_ns + self._time_span_ns
        return self._due_ns(self._rows[cursor], shift_ns, self._anchor_ns, self.speed) <= self.clock.now_ns()

    def _load(self, row: FrameRow, shift_ns: int) -> Frame:
        path = self.directory / row.image
        image = load_image(path)
        cam = self.rig.camera(row.camera)
        if image.shape != (cam.height, cam.width, 3):
            raise RigOperationError(
                f"recording image {path} is {image.shape[1]}x{image.shape[0]}, but the rig's camera "
                f"{row.camera!r} is {cam.width}x{cam.height}"
            )
        truth, joints_3d = load_truth(self.directory / row.truth) if row.truth is not None else (None, None)
        return Frame(
            camera=row.camera,
            image=image,
            timestamp_ns=row.timestamp_ns + shift_ns,
            index=row.index + self._pass * self._index_span.get(row.camera, 0),
            truth=truth,
            scene_time_s=row.scene_time_s,
            joints_3d=joints_3d,
        )

    def _close(self) -> None:
        pass  # files are opened per frame; nothing held
