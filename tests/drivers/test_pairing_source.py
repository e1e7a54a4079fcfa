"""The base class and a pairer that holds a pair back: it is read before the end of the stream or a disconnect."""
from __future__ import annotations

import numpy as np
import pytest

from drivers import EndOfStream, Frame, ManualClock, PairingConfig, RigDisconnectedError, RigSource
from drivers.sim import RigPlacement

MS = 1_000_000


class ScriptedSource(RigSource):
    """Delivers ``script`` (frames of cameras 0 and 1, or errors to raise) in order, then raises ``end`` for good."""

    scheme = "scripted"

    def __init__(self, script: list, end: Exception, policy: str = "all") -> None:
        super().__init__(RigPlacement(width=16, height=16).build("scripted"), pairing=PairingConfig(policy=policy),
                         clock=ManualClock())
        self.script, self.end = list(script), end

    @classmethod
    def from_url(cls, url, **kwargs):  # pragma: no cover - built directly
        raise NotImplementedError

    def _open(self) -> None:
        pass

    def _read_frame(self, timeout_s: float) -> Frame | None:
        item = self.script.pop(0) if self.script else self.end
        if isinstance(item, Exception):
            raise item
        camera, index, t_ms = item
        return Frame(camera=self.rig.pair[camera].name, image=np.zeros((16, 16, 3), np.uint8),
                     timestamp_ns=int(t_ms * MS), index=index)

    def _close(self) -> None:
        pass


# b 3 ms after a: a later frame of a could still be closer to it, so the pairer holds the pair back
HELD = [(0, 0, 0.0), (1, 0, 3.0)]


@pytest.mark.parametrize("policy", ["all", "latest"])
def test_the_last_pair_is_read_before_the_end_of_the_stream(policy):
    with ScriptedSource(HELD, EndOfStream("done"), policy) as source:
        pair = source.read(timeout_s=1.0)
        assert pair.sequence == 0 and [f.index for f in pair.frames] == [0, 0]
        with pytest.raises(EndOfStream):
            source.read(timeout_s=1.0)
    with ScriptedSource(HELD, EndOfStream("done"), policy) as source:
        assert len(list(source)) == 1


def test_a_disconnect_is_raised_after_the_pair_captured_before_it():
    with ScriptedSource(HELD, RigDisconnectedError("unplugged")) as source:
        assert [f.index for f in source.read(timeout_s=1.0).frames] == [0, 0]
        for _ in range(2):
            with pytest.raises(RigDisconnectedError, match="unplugged"):
                source.read(timeout_s=1.0)


def test_a_disconnect_raised_once_is_raised_once_and_the_source_goes_on():
    # a backend that reconnects: the frames after it are a new timeline (clock and indices start over)
    script = [*HELD, RigDisconnectedError("unplugged"), (0, 0, 0.0), (1, 0, 0.0)]
    with ScriptedSource(script, EndOfStream("done")) as source:
        assert source.read(timeout_s=1.0).sequence == 0
        with pytest.raises(RigDisconnectedError):
            source.read(timeout_s=1.0)
        assert source.read(timeout_s=1.0).sequence == 1
        stats = source.stats
        assert stats.unpaired == {"left": 0, "right": 0} and stats.camera_gaps == {"left": 0, "right": 0}
