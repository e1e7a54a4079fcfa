"""depthai without hardware, for real: host-only pipelines, the production Sync stage, real messages and errors."""
import datetime
import logging
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import depthai as dai
import numpy as np
import pytest

from drivers import (
    FrameSizeError,
    RigConfigError,
    RigDisconnectedError,
    RigInitializationError,
    RigOperationError,
    RigTimeoutError,
    create_rig_source,
    open_rig,
)
from drivers.backends.depthai.convert import (
    LEFT,
    RIGHT,
    depthai_errors,
    frame_from_img,
    frames_from_group,
    timedelta_to_ns,
)
from drivers.backends.depthai.link import StereoRequest
from drivers.backends.depthai.options import DepthaiOptions
from drivers.url import RigUrl
from tests.drivers.depthai_host import HostPipelineLink, ScriptedLink, image_group, stamp
from tests.drivers.reopens import open_sources_sharing_a_logged_set

URL = "depthai://?width=160&height=100&mount_height=1.2"


def request(**changes) -> StereoRequest:
    base = dict(device_id=None, left="CAM_B", right="CAM_C", fps=30.0, width=160, height=100,
                tolerance_ms=5.0, queue_size=4)
    base.update(changes)
    return StereoRequest(**base)


@pytest.fixture
def link():
    link = HostPipelineLink()
    yield link
    link.close()


@pytest.fixture(scope="module")
def rig():
    source = create_rig_source(URL, link_factory=HostPipelineLink)
    with source:
        return source.rig


# ----------------------------------------------------------------- clocks and conversion
def test_depthai_host_clock_is_time_monotonic_ns():
    """``getTimestamp()`` is on dai::Clock, i.e. the clock our timestamps use."""
    before = time.monotonic_ns()
    now = timedelta_to_ns(dai.Clock.now())
    after = time.monotonic_ns()
    assert before - 1_000 <= now <= after + 1_000  # timedelta keeps microseconds


def test_timedelta_to_ns_is_exact():
    delta = datetime.timedelta(days=2, seconds=3, microseconds=456_789)
    assert timedelta_to_ns(delta) == (2 * 86_400 + 3) * 10**9 + 456_789_000


def test_gray_img_frame_becomes_a_bgr_frame(rig):
    message = dai.ImgFrame()
    message.setCvFrame(np.arange(160 * 100, dtype=np.uint32).reshape(100, 160).astype(np.uint8), dai.ImgFrame.Type.GRAY8)
    stamp(message, 1_234_567_000)
    message.setSequenceNum(42)
    frame = frame_from_img(message, "left", rig)
    assert frame.image.shape == (100, 160, 3) and frame.image.dtype == np.uint8
    assert np.array_equal(frame.image[..., 0], frame.image[..., 2])
    assert (frame.timestamp_ns, frame.index, frame.camera) == (1_234_567_000, 42, "left")


def test_colour_img_frame_keeps_its_colours(rig):
    bgr = np.zeros((100, 160, 3), np.uint8)
    bgr[..., 2] = 200  # red
    message = dai.ImgFrame()
    message.setCvFrame(bgr, dai.ImgFrame.Type.BGR888i)
    assert np.array_equal(frame_from_img(message, "right", rig).image, bgr)


def test_wrong_size_image_is_a_typed_operation_error(rig):
    """Typed (session 58): the daemon tells cameras that never deliver the rig's size by it (it was a plain
    RigOperationError, retried for ever); still a RigOperationError, so readers that read past one go on."""
    message = dai.ImgFrame()
    message.setCvFrame(np.zeros((10, 16), np.uint8), dai.ImgFrame.Type.GRAY8)
    with pytest.raises(FrameSizeError, match="16x10") as caught:
        frame_from_img(message, "left", rig)
    assert isinstance(caught.value, RigOperationError)
    assert (caught.value.camera, caught.value.expected, caught.value.delivered) == ("left", (160, 100), (16, 10))


def test_group_without_both_cameras_is_an_operation_error(rig):
    group = dai.MessageGroup()
    message = dai.ImgFrame()
    message.setCvFrame(np.zeros((100, 160), np.uint8), dai.ImgFrame.Type.GRAY8)
    group[LEFT] = message
    with pytest.raises(RigOperationError, match="'right'"):
        frames_from_group(group, rig)
    group[RIGHT] = dai.Buffer()
    with pytest.raises(RigOperationError, match="not an ImgFrame"):
        frames_from_group(group, rig)


# ----------------------------------------------------------------- the Sync stage on a host pipeline
def test_sync_stage_groups_real_frames_within_tolerance(link, rig):
    link.offset_ms = 2.0
    link.start(request(tolerance_ms=5.0))
    groups = [link.next_group(2.0) for _ in range(10)]
    assert all(isinstance(g, dai.MessageGroup) for g in groups)
    sent = {cam: dict(node.sent) for cam, node in zip((LEFT, RIGHT), link.cameras)}
    for group in groups:
        assert group.isSynced(5_000_000)
        left, right = frames_from_group(group, rig)
        assert left.index == right.index
        assert right.timestamp_ns - left.timestamp_ns == 2_000_000
        # the timestamps the camera nodes stamped, to the microsecond
        assert left.timestamp_ns == sent[LEFT][left.index] // 1000 * 1000
        assert int(left.image[0, 0, 0]) == left.index % 256


def test_sync_stage_never_emits_pairs_further_apart_than_the_threshold(link):
    link.offset_ms = 12.0
    link.start(request(tolerance_ms=5.0))
    assert link.next_group(0.4) is None


def test_a_host_pipeline_closed_then_dropped_ends_whatever_its_sync_node_still_holds():
    """The pipeline's destructor joins its node threads holding the GIL; the Sync node's thread, letting go of frames
    the Python cameras made, waits for the GIL: a fixture's teardown hung the test run at load ~10 (2 to 20 cycles
    of these on a loaded host). ``HostPipelineLink.close`` joins them first, the GIL released. In a process of its
    own, so that a hang fails this test instead of stopping the run."""
    code = textwrap.dedent(
        """
        from tests.drivers.depthai_host import HostPipelineLink
        from tests.drivers.test_depthai_pipeline import request

        for cycle in range(40):
            link = HostPipelineLink(offset_ms=12.0)  # past the tolerance: the Sync node drops what it gets
            link.start(request(tolerance_ms=5.0))
            link.next_group(0.05)
            link.close()
            link = None  # the pipeline's destructor runs here
        print("40 cycles")
        """
    )
    try:
        result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                                cwd=Path(__file__).resolve().parents[2])
    except subprocess.TimeoutExpired as e:
        pytest.fail(f"a host pipeline's destructor hung: {e.stdout!r}")
    assert "40 cycles" in result.stdout, result.stdout + result.stderr


def test_closed_queue_becomes_rig_disconnected_with_the_cause(link):
    link.start(request())
    assert link.next_group(2.0) is not None
    link.unplug()
    with pytest.raises(RigDisconnectedError, match="queue closed") as info:
        with depthai_errors("reading", RigDisconnectedError):
            link.next_group(1.0)
    assert isinstance(info.value.__cause__, dai.MessageQueue.QueueException)


def test_runtime_errors_become_the_requested_error_with_the_cause():
    with pytest.raises(RigInitializationError, match="opening: no device") as info:
        with depthai_errors("opening", RigInitializationError):
            raise RuntimeError("no device")
    assert isinstance(info.value.__cause__, RuntimeError)
    with pytest.raises(RigConfigError):  # our own errors pass through untouched
        with depthai_errors("opening", RigInitializationError):
            raise RigConfigError("bad")


def test_a_device_closed_under_depthai_is_converted_too():
    """depthai-core's DeviceBase::checkClosed() throws std::invalid_argument, which Python sees as ValueError."""
    with pytest.raises(RigInitializationError, match="Device already closed") as info:
        with depthai_errors("opening", RigInitializationError):
            raise ValueError("Device already closed or disconnected")
    assert isinstance(info.value.__cause__, ValueError)


class _LostDuringStart(ScriptedLink):
    """Connects, then the device drops off the bus: its next device call fails as depthai's would."""

    def __init__(self, fails: str, error: Exception) -> None:
        super().__init__([(0, 0)])
        self.fails, self.error = fails, error

    def calibration(self) -> dai.CalibrationHandler:
        if self.fails == "calibration":
            raise self.error
        return super().calibration()

    def device_id(self) -> str:
        if self.fails == "device_id" and not self.closed:
            raise self.error
        return super().device_id()


def test_a_device_lost_while_its_calibration_is_read_is_an_initialization_error():
    link = _LostDuringStart("calibration", ValueError("Device already closed or disconnected"))
    with pytest.raises(RigInitializationError, match="starting depthai device.*Device already closed"):
        open_rig(URL, link_factory=lambda: link)
    assert link.closed == 1


def test_a_device_lost_when_asked_its_id_is_an_initialization_error_and_the_link_is_closed(rig):
    """With a rig given, the device id is first asked after the calibration step: still a typed error, and
    the link (the device) closed, since a source whose open() failed is never closed by its owner."""
    link = _LostDuringStart("device_id", RuntimeError("Couldn't read data from stream (X_LINK_ERROR)"))
    source = create_rig_source(URL.replace("&mount_height=1.2", ""), rig=rig, link_factory=lambda: link)
    with pytest.raises(RigInitializationError, match="X_LINK_ERROR"):
        source.open()
    assert link.closed == 1 and not source.is_open


# ----------------------------------------------------------------- the backend on the host link
def test_backend_delivers_pairs_from_real_groups():
    link = HostPipelineLink(offset_ms=1.0)
    with open_rig(f"{URL}&tolerance_ms=4", link_factory=lambda: link) as source:
        assert source.rig.rig_id == "oak-host-pipeline"
        assert source.rig.baseline == pytest.approx(0.075, abs=1e-3)
        pairs = [source.read(timeout_s=3.0) for _ in range(15)]
        assert link.request.tolerance_ms == 4.0  # the Sync threshold is the pairing tolerance
    assert [p.frames[0].index for p in pairs] == sorted({p.frames[0].index for p in pairs})
    assert all(p.skew_ns == 1_000_000 for p in pairs)
    assert link.closed == 1


def test_frames_a_camera_loses_are_lost_pairs():
    """Sync discards the partner of a frame one camera lost: both indices jump together, as for a group the
    host queue dropped, and the reader lost a pair either way (sequence gaps, ``pairs_dropped``)."""
    link = HostPipelineLink(drop=0.3)
    with open_rig(f"{URL}&policy=all", link_factory=lambda: link) as source:
        pairs = [source.read(timeout_s=3.0) for _ in range(15)]
        stats = source.stats
    assert stats.pairs_dropped > 0
    assert stats.pairs_out + stats.pairs_dropped == pairs[-1].sequence + 1
    assert [p.sequence - p.frames[0].index for p in pairs] == [pairs[0].sequence - pairs[0].frames[0].index] * 15


def test_unplug_while_reading_raises_rig_disconnected():
    link = HostPipelineLink()
    with open_rig(URL, link_factory=lambda: link) as source:
        source.read(timeout_s=3.0)
        link.unplug()
        with pytest.raises(RigDisconnectedError):
            for _ in range(10):  # the queue may still hold a group or two
                source.read(timeout_s=10.0)  # the closed queue ends it: seconds for a loaded host to get there


def test_a_lost_device_is_named_with_its_id_and_the_url():
    link = HostPipelineLink()
    with open_rig(URL, link_factory=lambda: link) as source:
        source.read(timeout_s=3.0)
        link.unplug()
        with pytest.raises(RigDisconnectedError) as info:
            for _ in range(10):  # the queue may still hold a group or two
                source.read(timeout_s=10.0)
    assert "host-pipeline" in str(info.value) and URL in str(info.value)


def test_a_device_that_stops_without_closing_its_queue_is_a_disconnect_not_a_timeout():
    link = ScriptedLink([(0, 0), (1, 1)], stops=True)
    with open_rig(f"{URL}&policy=all", link_factory=lambda: link) as source:
        assert [source.read(timeout_s=0.1).sequence for _ in range(2)] == [0, 1]
        with pytest.raises(RigDisconnectedError, match=r"depthai device 14442C10D1 \(depthai://\?width=160"):
            source.read(timeout_s=0.1)


class _XLinkLost(ScriptedLink):
    """Streams its groups, then the cable is pulled: depthai's read fails as it does on an unplug."""

    def next_group(self, timeout_s: float) -> dai.MessageGroup | None:
        if not self.groups:
            raise RuntimeError("Communication exception - possible device error/misconfiguration. Original "
                               "message 'Couldn't read data from stream: '__x_0_0' (X_LINK_ERROR)'")
        return super().next_group(timeout_s)


def test_an_xlink_error_mid_stream_is_a_disconnect_naming_the_device_its_port_and_cameras():
    """What the daemon logs on an unplug: which OAK (id, USB port) and which of its cameras (name and socket)."""
    link = _XLinkLost([(0, 0)])
    with open_rig(f"{URL}&policy=all", link_factory=lambda: link) as source:
        source.read(timeout_s=0.1)
        with pytest.raises(RigDisconnectedError) as caught:
            source.read(timeout_s=0.1)
    message = str(caught.value)
    assert "reading from depthai device 14442C10D1 (depthai://?width=160" in message
    assert "at 1.3, cameras left (CAM_B) and right (CAM_C)" in message and "X_LINK_ERROR" in message
    assert isinstance(caught.value.__cause__, RuntimeError)


class _Paced(ScriptedLink):
    """A reader that keeps up: each read finds one group, the host queue holds nothing more."""

    def next_group(self, timeout_s: float) -> dai.MessageGroup | None:
        return super().next_group(timeout_s) if timeout_s > 0 else None


def _rate_warnings(link: ScriptedLink, reads: int, url: str = URL, caplog=None) -> list[str]:
    with caplog.at_level(logging.WARNING, logger="drivers.backends.depthai.source"):
        with open_rig(url, link_factory=lambda: link) as source:
            for _ in range(reads):
                source.read(timeout_s=0.1)
    return [r.getMessage() for r in caplog.records if "pairs/s arrive" in r.getMessage()]


def test_a_stream_slower_than_the_requested_fps_is_warned_once_with_the_measured_rate(caplog):
    # every second frame arrives (a USB2 link): 15 pairs/s of 30, over 80 frame times (2.7 s of capture)
    warnings = _rate_warnings(_Paced([(2 * k, 2 * k) for k in range(41)]), 41, caplog=caplog)
    assert len(warnings) == 1
    assert "15.0 pairs/s arrive of the 30 fps requested" in warnings[0]
    assert "depthai device 14442C10D1" in warnings[0] and "use USB3" in warnings[0]


def test_a_stream_at_the_requested_fps_is_not_warned(caplog):
    assert _rate_warnings(_Paced([(k, k) for k in range(90)]), 90, caplog=caplog) == []


def test_groups_a_slow_reader_let_the_queue_drop_are_not_taken_for_a_slow_link(caplog):
    # every read finds the queue full (4 groups, then more): what it lost is the reader's doing
    assert _rate_warnings(ScriptedLink([(2 * k, 2 * k) for k in range(200)]), 30, caplog=caplog) == []
    # under policy=all nothing tells the two apart: no measurement
    caplog.clear()
    assert _rate_warnings(_Paced([(2 * k, 2 * k) for k in range(41)]), 41, f"{URL}&policy=all", caplog) == []


def test_groups_lost_whole_are_dropped_pairs_not_camera_gaps():
    # (3, 3) and (4, 4) never reached the reader (the full host queue dropped them); then the left
    # camera alone skips one frame: that one is a camera gap
    link = ScriptedLink([(0, 0), (1, 1), (2, 2), (5, 5), (6, 6), (8, 7)])
    with open_rig(f"{URL}&policy=all", link_factory=lambda: link) as source:
        pairs = [source.read(timeout_s=0.1) for _ in range(6)]
        stats = source.stats
    assert [p.sequence for p in pairs] == [0, 1, 2, 5, 6, 7]
    assert stats.pairs_dropped == 2 and stats.pairs_out == 6
    assert stats.pairs_out + stats.pairs_dropped == pairs[-1].sequence + 1
    assert stats.camera_gaps == {"left": 1, "right": 0}


def test_recording_a_depthai_source_keeps_its_lost_groups_as_dropped_pairs(tmp_path):
    link = ScriptedLink([(0, 0), (3, 3)])
    with open_rig(f"record+{URL}&policy=all&out={tmp_path / 'take'}", link_factory=lambda: link) as source:
        assert [source.read(timeout_s=0.1).sequence for _ in range(2)] == [0, 3]
        assert source.stats.pairs_dropped == 2 and source.stats.camera_gaps == {"left": 0, "right": 0}


def _every_ten_seconds() -> HostPipelineLink:
    """A host pipeline whose groups are 10 s apart: a short read after the first one times out, however late a
    loaded host returned that first one (at fps=1 the next group came within a 0.2 s read)."""
    return HostPipelineLink(fps=0.1)


def test_no_group_in_time_is_a_timeout():
    with open_rig(f"{URL}&fps=1", link_factory=_every_ten_seconds) as source:
        source.read(timeout_s=3.0)
        with pytest.raises(RigTimeoutError):
            source.read(timeout_s=0.2)


def test_rig_file_overrides_the_device_calibration(tmp_path, rig):
    from ghnerf_runtime.rig_file import save_rig

    save_rig(rig, tmp_path / "rig.json")
    source = create_rig_source(f"depthai://?width=160&height=100&rig={tmp_path / 'rig.json'}", link_factory=HostPipelineLink)
    assert source.rig.baseline == pytest.approx(rig.baseline)  # known before open: no device needed
    source.close()
    with pytest.raises(RigConfigError, match="width=/height="):
        create_rig_source(f"depthai://?width=320&height=200&rig={tmp_path / 'rig.json'}")
    with pytest.raises(RigConfigError, match="rig="):
        create_rig_source(f"depthai://?rig={tmp_path / 'rig.json'}&mount_height=1")
    with pytest.raises(RigConfigError, match="mount_roll"):
        create_rig_source(f"depthai://?rig={tmp_path / 'rig.json'}&mount_roll=180")
    with pytest.raises(RigConfigError, match="nope.json"):
        create_rig_source(f"depthai://?rig={tmp_path / 'nope.json'}")


def test_a_rig_file_s_warnings_are_logged_at_open_once_by_sources_sharing_a_logged_set(tmp_path, rig, caplog):
    """``load_rig`` warned of a rig file at each ``create_rig_source``, which a daemon calls at each reopen: the
    journal repeated the warnings (session 66). Here the rig's frame moved 50 m up: each camera's height is
    warned of once over two opens sharing ``log_rig_warnings_once``'s set, naming the file."""
    from ghnerf_runtime.geometry import Camera, Rig, WorkingVolume
    from ghnerf_runtime.rig_file import save_rig

    shift = np.array([0.0, -50.0, 0.0])
    cams = tuple(Camera(c.name, c.width, c.height, c.K, c.dist, c.R, c.t - c.R @ shift) for c in rig.cameras)
    path = tmp_path / "high.json"
    save_rig(Rig(cams, WorkingVolume(rig.volume.min_corner + shift, rig.volume.max_corner + shift), "high"), path)
    url = f"depthai://?width=160&height=100&rig={path}"
    with caplog.at_level(logging.WARNING):
        open_sources_sharing_a_logged_set(lambda _: create_rig_source(url, link_factory=HostPipelineLink), 2)
    heights = [r.getMessage() for r in caplog.records if "CAMERA_HEIGHT_RANGE_M" in r.getMessage()]
    assert [m.split(" stands")[0] for m in heights] == [f"{path}: camera 'left'", f"{path}: camera 'right'"], heights


def test_mount_roll_reaches_the_rig_from_the_device_calibration():
    with open_rig(f"{URL}&mount_roll=180", link_factory=HostPipelineLink) as source:
        left = source.rig.pair[0]
        assert np.allclose(left.R, np.diag([-1.0, -1.0, 1.0])) and source.rig.metadata["mount_roll_deg"] == 180.0


def test_rig_is_unknown_until_open():
    source = create_rig_source(URL, link_factory=HostPipelineLink)
    with pytest.raises(RigOperationError, match="open"):
        source.rig
    source.close()


def test_record_a_depthai_source_and_replay_it(tmp_path):
    """kwargs pass through record+ to the inner backend; frames without truth record without truth files."""
    with open_rig(f"record+{URL}&out={tmp_path / 'oak'}", link_factory=HostPipelineLink) as source:
        live = [source.read(timeout_s=3.0) for _ in range(5)]
    with open_rig(f"replay://{tmp_path / 'oak'}?speed=free&policy=all&keep_time=1") as replay:
        replayed = list(replay)
    # Every live pair replays, in order. The live read (policy latest) may skip a pair the recorder still wrote
    # (it records every frame), so the replay's first pairs need not be the live ones.
    stamps = [p.timestamps_ns for p in replayed]
    at = [stamps.index(p.timestamps_ns) for p in live]
    assert at == sorted(at)
    assert all(f.truth is None and f.joints_3d is None for p in replayed for f in p.frames)
    assert np.array_equal(replayed[at[0]].images[0], live[0].images[0])


# ----------------------------------------------------------------- options and the real link without a device
@pytest.mark.parametrize(
    ("url", "word"),
    [
        ("depthai://A,B", "two-device"),
        # an empty name opened the first device found, or the one named, as if the ',' were not there
        ("depthai://,", r"device ',' has an empty name around ','"),
        ("depthai://1.3,", r"device '1.3,' has an empty name"),
        ("depthai://,,A", r"device ',,A' has an empty name"),
        ("depthai://?left=CAM_B&right=CAM_B", "same socket"),
        ("depthai://?left=CAM_Z", "left"),
        ("depthai://?fps=0", "fps"),
        ("depthai://?fps=-30", r"fps='-30' must be in \[1.0, 240.0\]"),
        ("depthai://?fps=nan", r"fps='nan' must be a finite number"),
        ("depthai://?fps=inf", r"fps='inf' must be a finite number"),
        ("depthai://?fps=3_0", r"fps='3_0' must be a number, without '_'"),  # a typo for 3.0 ran at 30
        ("depthai://?fps=abc", r"fps='abc' must be a number"),
        ("depthai://?right=cam_c", r"right='cam_c' must be one of \['CAM_A'"),
        ("depthai://?left=RGB", r"left='RGB' must be one of"),
        ("depthai://?width=641", r"width=641 must be even"),
        ("depthai://?height=401", r"height=401 must be even"),
        ("depthai://?width=8", r"width='8' must be an integer in \[16, 8192\]"),
        ("depthai://?height=4.5", r"height='4.5'"),
        ("depthai://?queue=0", "queue"),
        ("depthai://?mount_roll=400", "mount_roll"),
    ],
)
def test_option_errors(url, word):
    with pytest.raises(RigConfigError, match=word):
        DepthaiOptions.from_url(RigUrl.parse(url))


def test_options_defaults():
    options = DepthaiOptions.from_url(RigUrl.parse("depthai://14442C10D13EABCE00"))
    assert (options.device_id, options.left, options.right, options.fps) == ("14442C10D13EABCE00", "CAM_B", "CAM_C", 30.0)
    assert (options.width, options.height, options.mount_height_m, options.pairing.policy.value) == (640, 400, None, "latest")
    assert options.mount_roll_deg == 0.0
    assert DepthaiOptions.from_url(RigUrl.parse("depthai://?mount_roll=180")).mount_roll_deg == 180.0


def test_real_link_without_a_device_is_an_initialization_error():
    """The production DaiDeviceLink, for real: depthai searches, finds nothing, we convert its error."""
    code = textwrap.dedent(
        """
        from drivers import RigInitializationError, open_rig
        try:
            open_rig("depthai://?fps=30")
        except RigInitializationError as e:
            print("converted:", type(e.__cause__).__name__, e)
        """
    )
    env = {"DEPTHAI_SEARCH_TIMEOUT": "300", "PATH": "/usr/bin:/bin"}
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env,
                            cwd=Path(__file__).resolve().parents[2])
    assert "converted: RuntimeError" in result.stdout, result.stdout + result.stderr
    # depthai's own listing ran too (getAllConnectedDevices), and the message says what it found
    assert "cannot connect to a depthai device: No available devices; connected devices: none" in result.stdout


def test_timeouts_run_on_the_injected_clock():
    """A link that waited in real time still moves a ManualClock to the deadline (no endless read loop)."""
    from drivers import ManualClock

    clock = ManualClock(7_000_000_000)
    with open_rig(f"{URL}&fps=1", link_factory=_every_ten_seconds, clock=clock) as source:
        source.read(timeout_s=3.0)
        t0 = clock.now_ns()
        with pytest.raises(RigTimeoutError):
            source.read(timeout_s=0.2)
        assert clock.now_ns() - t0 == 200_000_000


class _OtherSize(ScriptedLink):
    """A device that streams ``size`` whatever width=/height= it was asked for."""

    def __init__(self, size: tuple[int, int]) -> None:
        super().__init__([(k, k) for k in range(4)])
        self.size = size

    def start(self, request: StereoRequest) -> None:
        super().start(request)
        self.groups = [image_group(ix, self.size) for ix in self.indices]


def test_frames_of_another_size_than_the_rig_file_name_the_device_camera_file_and_both_sizes(tmp_path, rig):
    """A frame of another size mid-stream was a plain RigOperationError naming neither the rig file nor the URL:
    now a FrameSizeError (camera, both sizes) whose message names the device, the rig file and what to do."""
    from ghnerf_runtime.rig_file import save_rig

    save_rig(rig, tmp_path / "rig.json")
    url = f"depthai://?width=160&height=100&rig={tmp_path / 'rig.json'}"
    with open_rig(url, link_factory=lambda: _OtherSize((320, 200))) as source:
        with pytest.raises(FrameSizeError) as caught:
            source.read(timeout_s=1.0)
    assert (caught.value.camera, caught.value.expected, caught.value.delivered) == ("left", (160, 100), (320, 200))
    assert str(caught.value) == (
        f"depthai device 14442C10D1 ({url}) at 1.3, cameras left (CAM_B) and right (CAM_C): camera 'left' delivered "
        f"320x200, but its rig camera in {tmp_path / 'rig.json'} is 160x100, the size the device was asked for "
        f"(width=160&height=100): ask for a size its sensors deliver (width=/height=) with a rig file calibrated at "
        f"it (ghcal, docs/calibration.md)")
    with open_rig(URL, link_factory=lambda: _OtherSize((320, 200))) as source:  # the device's calibration
        with pytest.raises(FrameSizeError, match=r"camera 'left' delivered 320x200, but its rig camera \(the "
                                                 r"device's calibration, at the width=/height= asked\) is 160x100, "
                                                 r"the size the device was asked for \(width=160&height=100\): ask "
                                                 r"for another width=/height=, one its sensors deliver$"):
            source.read(timeout_s=1.0)


class _OddlyNamed(_OtherSize):
    """:class:`_OtherSize` at an XLink name holding an ESC sequence (the device's text, not the user's)."""

    def device_name(self) -> str:
        return "1.3\x1b[2J"


def test_a_device_or_camera_name_holding_a_control_character_is_escaped_in_the_device_s_words(tmp_path, rig):
    """The device's XLink name and a rig file's camera names reached the log and the daemon's STATUS line raw: an
    ESC sequence in one rewrote the terminal (session 74). Escaped as repr now; plain names as before."""
    import json

    from ghnerf_runtime.rig_file import save_rig

    save_rig(rig, tmp_path / "rig.json")
    data = json.loads((tmp_path / "rig.json").read_text())
    data["cameras"][0]["name"] = "le\x9bft"
    (tmp_path / "rig.json").write_text(json.dumps(data))
    url = f"depthai://?width=160&height=100&rig={tmp_path / 'rig.json'}"
    with open_rig(url, link_factory=lambda: _OddlyNamed((320, 200))) as source:
        with pytest.raises(FrameSizeError) as caught:
            source.read(timeout_s=1.0)
    said = str(caught.value)
    assert said.startswith(f"depthai device 14442C10D1 ({url}) at '1.3\\x1b[2J', cameras 'le\\x9bft' (CAM_B) and "
                           "right (CAM_C): "), said
    assert "\x1b" not in said and "\x9b" not in said


def test_a_read_waiting_when_another_thread_closes_says_the_source_closed_not_that_the_device_was_lost():
    # it raised RigDisconnectedError ("reading from depthai device ..."): a daemon reopens a lost device, and one
    # closing its source from another thread (a stop) was told its device was gone; sim:// and opencv:// say closed
    import threading

    link = HostPipelineLink()
    source = open_rig(f"{URL}&policy=all", link_factory=lambda: link)
    source.read(timeout_s=3.0)
    errors: list[Exception] = []

    def read_on() -> None:
        try:
            while True:
                source.read(timeout_s=5.0)
        except Exception as e:  # noqa: BLE001 - kept for the test to look at
            errors.append(e)

    reader = threading.Thread(target=read_on)
    reader.start()
    time.sleep(0.3)
    source.close()
    reader.join(timeout=60.0)  # an unwoken read ends at its 5 s timeout, a RigTimeoutError
    assert not reader.is_alive() and len(errors) == 1
    # the read in flight says so; one the loop began just after the close (a loaded host) says it was closed
    said = str(errors[0])
    assert type(errors[0]) is RigOperationError, errors[0]
    assert "source closed while a read waited" in said or said.endswith("was closed; open a new source"), said


def test_a_read_in_flight_finding_the_link_closed_says_the_source_closed():
    # the read's next group, after another thread's close dropped the link, said "depthai link is not open" (a
    # read of a source it had found open); the reader's loop above saw it on a loaded host
    link = HostPipelineLink()
    source = open_rig(f"{URL}&policy=all", link_factory=lambda: link)
    source.read(timeout_s=3.0)
    source.close()
    with pytest.raises(RigOperationError, match=r"\): source closed while a read waited for its frame$"):
        source._read_frame(1.0)  # where read() was, inside its loop, when the close came
