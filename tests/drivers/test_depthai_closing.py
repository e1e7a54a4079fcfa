"""A ``depthai://`` source closed from another thread while it opens, and while a read holds a frame.

A close during the open was seen only once ``_open`` had returned: the device had its pipeline built and started and
its EEPROM read for a source already closed. Now the open stops at its next step (the production link once it has
connected, the source before each of its own) and raises ``RigInitializationError``, with the device closed. A read
whose group came out of the queue as the close landed handed its frames out, a pair of a closed source; now it
refuses them as ``sim://`` and ``replay://`` do. Threads wait on Events, never on a sleep being long enough.
"""
from __future__ import annotations

import threading

import depthai as dai
import pytest

from drivers import FramePair, RigInitializationError, RigOperationError, create_rig_source
from drivers.backends.depthai.link import DaiDeviceLink, StereoRequest
from tests.drivers.contract import opened_in_a_thread
from tests.drivers.depthai_host import HostBackedPipeline, ScriptedLink, StandInDevice

URL = "depthai://?width=160&height=100&fps=30&mount_height=1.2"
WHERE = f"depthai device (first found) ({URL}), cameras left (CAM_B) and right (CAM_C)"
CANCELLED = f"{WHERE}: closed while open() started the device: the open was cancelled"
WAIT_S = 30.0  # generous: only a hang reaches it


def closed_on_a_thread(source) -> None:
    """``source.close()`` from another thread, which must return without waiting for the open in progress."""
    closer = threading.Thread(target=source.close, name="test close", daemon=True)
    closer.start()
    closer.join(WAIT_S)
    assert not closer.is_alive(), "close() waited for the open"


class _SlowToConnect:
    """The production link on a stand-in device that takes until ``go_on`` to connect (depthai booting it)."""

    def __init__(self) -> None:
        self.device = StandInDevice()
        self.pipeline: HostBackedPipeline | None = None
        self.connecting = threading.Event()
        self.go_on = threading.Event()

    def _connect(self, request: StereoRequest) -> StandInDevice:
        self.connecting.set()
        assert self.go_on.wait(WAIT_S)
        return self.device

    def _pipeline_for(self, device: StandInDevice) -> HostBackedPipeline:
        self.pipeline = HostBackedPipeline(device)
        return self.pipeline

    def link(self) -> DaiDeviceLink:
        return DaiDeviceLink(connect=self._connect, pipeline_for=self._pipeline_for)


def test_a_close_while_the_device_connects_cancels_the_open_before_any_camera_streams():
    rig = _SlowToConnect()
    source = create_rig_source(URL, link_factory=rig.link)
    thread, outcome = opened_in_a_thread(source)
    assert rig.connecting.wait(WAIT_S)
    closed_on_a_thread(source)
    rig.go_on.set()  # the connect returns after the close
    thread.join(WAIT_S)
    assert not thread.is_alive()
    assert rig.pipeline is None  # no pipeline built, so none started: nothing keeps running
    assert rig.device.called("readCalibration") == []
    assert rig.device.closed and not source.is_open
    assert len(outcome) == 1 and isinstance(outcome[0], RigInitializationError), outcome
    assert str(outcome[0]) == CANCELLED
    assert "start cancelled" in str(outcome[0].__cause__)  # the link's own words, kept as the cause


class _HeldStart(ScriptedLink):
    """A link whose start() waits for ``go_on`` and cannot be cut short (its cancel() does nothing)."""

    def __init__(self) -> None:
        super().__init__([(0, 0)])
        self.starting = threading.Event()
        self.go_on = threading.Event()
        self.calibrations_read = 0

    def start(self, request: StereoRequest) -> None:
        super().start(request)
        self.starting.set()
        assert self.go_on.wait(WAIT_S)

    def calibration(self) -> dai.CalibrationHandler:
        self.calibrations_read += 1
        return super().calibration()


def test_a_close_while_a_link_starts_stops_the_open_before_the_eeprom_is_read_and_closes_the_link():
    link = _HeldStart()
    source = create_rig_source(URL, link_factory=lambda: link)
    thread, outcome = opened_in_a_thread(source)
    assert link.starting.wait(WAIT_S)
    closed_on_a_thread(source)
    assert source.lingering() == (WHERE,)  # the open still holds the device it is starting
    link.go_on.set()
    thread.join(WAIT_S)
    assert not thread.is_alive()
    assert link.calibrations_read == 0
    assert link.closed == 1 and not source.is_open
    assert len(outcome) == 1 and isinstance(outcome[0], RigInitializationError), outcome
    assert str(outcome[0]) == CANCELLED
    assert source.lingering() == ()
    source.close()
    assert link.closed == 1  # released once, by the cancelled open


def test_a_record_wrapper_closed_while_its_depthai_source_starts_says_the_device_is_still_held(tmp_path):
    """lingering() said nothing while the cancelled open still held the device it was starting (depthai's connect
    cannot be cut short), though the close had returned: the base class's, empty, for a source without threads."""
    link = _HeldStart()
    out = tmp_path / "take"
    source = create_rig_source(f"record+{URL}&out={out}", link_factory=lambda: link)
    thread, outcome = opened_in_a_thread(source)
    assert link.starting.wait(WAIT_S)
    closed_on_a_thread(source)
    assert source.lingering() == source.inner.lingering() == (WHERE,)
    link.go_on.set()
    thread.join(WAIT_S)
    assert not thread.is_alive()
    assert len(outcome) == 1 and str(outcome[0]) == CANCELLED, outcome
    assert source.lingering() == () and link.closed == 1
    assert not out.exists()


class _GroupInHand(ScriptedLink):
    """Its first ``next_group`` takes a group out of the queue, then waits for ``go_on`` before handing it over: a
    close lands while the reader holds it."""

    def __init__(self) -> None:
        super().__init__([(k, k) for k in range(3)])
        self.in_hand = threading.Event()
        self.go_on = threading.Event()

    def next_group(self, timeout_s: float) -> dai.MessageGroup | None:
        group = super().next_group(timeout_s)
        if not self.in_hand.is_set():
            self.in_hand.set()
            assert self.go_on.wait(WAIT_S)
        return group


@pytest.mark.parametrize("policy", ["all", "latest"])
def test_a_group_a_read_had_in_hand_as_another_thread_closed_is_not_handed_out(policy):
    link = _GroupInHand()
    source = create_rig_source(f"{URL}&policy={policy}", link_factory=lambda: link).open()
    outcome: list = []

    def read() -> None:
        try:
            outcome.append(source.read(timeout_s=WAIT_S))
        except Exception as e:  # noqa: BLE001 - handed to the test
            outcome.append(e)

    reader = threading.Thread(target=read, name="test read", daemon=True)
    reader.start()
    assert link.in_hand.wait(WAIT_S)
    source.close()
    link.go_on.set()
    reader.join(WAIT_S)
    assert not reader.is_alive()
    assert len(outcome) == 1 and not isinstance(outcome[0], FramePair), outcome
    assert type(outcome[0]) is RigOperationError, outcome[0]
    assert str(outcome[0]) == (f"depthai device 14442C10D1 ({URL}&policy={policy}) at 1.3, cameras left (CAM_B) and "
                               "right (CAM_C): source closed while a read waited for its frame")
    assert sum(source.stats.frames_in.values()) == 0  # nothing of the group reached the pairer
