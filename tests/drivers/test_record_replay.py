"""``record+<url>`` and ``replay://``: exact round trips, the file format, and every way a take can be broken."""
import errno
import json
import logging
import os
import re
import struct
import threading
import time
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers import (
    EndOfStream,
    FrameSizeError,
    ManualClock,
    RecordingError,
    RigConfigError,
    RigInitializationError,
    RigOperationError,
    create_rig_source,
    open_rig,
)
from drivers.backends import record as record_module
from drivers.backends.record import inner_url_text
from drivers.backends.recording_format import (
    FRAMES,
    MANIFEST,
    encode_image,
    image_is_whole,
    load_image,
    load_truth,
    payload_is_whole,
    read_manifest,
)
from benchmarks import time_replay_open
from ghnerf_runtime.cli.recorded_take import RecordedTake
from drivers.url import RigUrl
from tests.drivers.contract import opened_in_a_thread
from tests.drivers.reopens import warnings_shared_and_alone
from tests.odd_images import (
    bmp_built,
    riff_chunk,
    tiff_entries,
    tiff_laid_out,
    tiff_with_strip_count,
    webp_extended,
)

SIM = "sim://?width=40&height=30&jitter_ms=1.5&offset_ms=2&drop=0.1&seed=8&policy=all"


def record(out, cache, pairs=30, sim=SIM, **record_options):
    extra = "".join(f"&{k}={v}" for k, v in record_options.items())
    with open_rig(f"record+{sim}&cache={cache}&out={out}{extra}", clock=ManualClock()) as source:
        read = [source.read(timeout_s=5.0) for _ in range(pairs)]
    return read, source.stats  # after close: the writers have finished


def replay_all(take, options="speed=free&keep_time=1"):
    """Every pair of ``take``; by default with its recorded stamps (keep_time=1), to compare with the live pairs."""
    with open_rig(f"replay://{take}?{options}&policy=all") as source:
        return list(source)


@pytest.fixture(scope="module")
def take(tmp_path_factory, sim_cache):
    out = tmp_path_factory.mktemp("rr") / "take"
    pairs, stats = record(out, sim_cache, lossless=1)  # the ManualClock reads faster than real time
    return out, pairs, stats


def assert_same_frame(a, b, exact_image=True):
    assert (a.camera, a.index, a.timestamp_ns, a.scene_time_s) == (b.camera, b.index, b.timestamp_ns, b.scene_time_s)
    if exact_image:
        assert np.array_equal(a.image, b.image)
    for name in ("joints_2d", "visible", "mask", "depth", "part_labels"):
        x, y = getattr(a.truth, name), getattr(b.truth, name)
        assert x.dtype == y.dtype and np.array_equal(x, y), name
    assert np.array_equal(a.joints_3d, b.joints_3d)


# ----------------------------------------------------------------- round trip
def test_round_trip_is_exact(take):
    out, live, _ = take
    replayed = replay_all(out)
    assert len(replayed) == len(live)
    for a, b in zip(live, replayed):
        assert a.sequence == b.sequence
        for fa, fb in zip(a.frames, b.frames):
            assert_same_frame(fa, fb)
    assert replayed[0].rig.names == live[0].rig.names
    for ca, cb in zip(live[0].rig.cameras, replayed[0].rig.cameras):
        assert np.allclose(ca.K, cb.K) and np.allclose(ca.R, cb.R) and np.allclose(ca.t, cb.t)


def test_replay_reproduces_the_live_pairing_situation(take):
    """Every delivered frame is recorded (paired or not), so drops and unpaired frames replay too."""
    out, _, live_stats = take
    with open_rig(f"replay://{out}?speed=free&policy=all") as source:
        list(source)
        stats = source.stats
    assert stats.frames_in == live_stats.frames_in
    assert stats.camera_gaps == live_stats.camera_gaps
    assert live_stats.frames_written == sum(live_stats.frames_in.values())
    assert live_stats.writes_dropped == 0


def test_manifest_and_journal_describe_the_take(take):
    out, _, stats = take
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["format"] == "ghnerf-rig-recording" and manifest["version"] == 1
    assert manifest["complete"] is True and manifest["image_format"] == "png"
    assert manifest["rig"]["format"] == "ghnerf-rig"
    assert manifest["source"].startswith("sim://") and "out=" not in manifest["source"]
    assert manifest["counters"]["frames_written"] == stats.frames_written
    rows = [json.loads(line) for line in (out / FRAMES).read_text().splitlines()]
    assert len(rows) == stats.frames_written
    assert set(rows[0]) == {"camera", "index", "timestamp_ns", "image", "truth", "scene_time_s"}
    assert (out / rows[0]["image"]).is_file() and rows[0]["image"].endswith(".png")
    assert (out / rows[0]["truth"]).is_file()


def test_recorded_speed_honours_the_recorded_timing(take):
    out, live, _ = take
    clock = ManualClock(123_000_000_000)
    with open_rig(f"replay://{out}?policy=all&keep_time=1", clock=clock) as source:
        assert not source.live_timestamps
        t_first = live[0].frames[0].timestamp_ns
        for k, pair in enumerate(live[:10]):
            got = source.read(timeout_s=5.0)
            assert got.timestamps_ns == pair.timestamps_ns  # keep_time=1: recorded stamps, unchanged
            # delivered when the clock reached the later frame's recorded offset; the first pair waits for
            # one more frame (no frame interval seen yet, so a closer frame could still come: FramePairer)
            delay = clock.now_ns() - 123_000_000_000 - (max(got.timestamps_ns) - t_first)
            assert delay == 0 if k else 0 < delay <= 33_333_333


def test_replay_stamps_frames_on_the_clock_with_the_recorded_spacing(take):
    """A replay streamed the recorded stamps as capture times: a receiver's latency (send - capture, on the
    sender's clock) was the distance to another boot's clock, hours or days. Now the first frame is stamped
    with the clock time playback started and every frame keeps its recorded distance from it."""
    out, live, _ = take
    start = 123_000_000_000
    clock = ManualClock(start)
    t_first = min(json.loads(line)["timestamp_ns"] for line in (out / FRAMES).read_text().splitlines())
    with open_rig(f"replay://{out}?policy=all", clock=clock) as source:
        assert source.live_timestamps
        for k, pair in enumerate(live[:10]):
            got = source.read(timeout_s=5.0)
            assert got.timestamps_ns == tuple(t - t_first + start for t in pair.timestamps_ns)
            # stamped with the time it played: latency 0 here, but for the first pair, which waits one frame
            # for a closer partner that could still come (FramePairer)
            delay = clock.now_ns() - max(got.timestamps_ns)
            assert delay == 0 if k else 0 < delay <= 33_333_333
    # Any speed keeps the recorded spacing (pairing, smoothing and tracking see the take as it was);
    # free-running playback is anchored where it started.
    for options in ("speed=2", "speed=free"):
        clock = ManualClock(start)
        with open_rig(f"replay://{out}?policy=all&{options}", clock=clock) as source:
            assert not source.live_timestamps
            got = [source.read(timeout_s=5.0) for _ in range(10)]
        assert [p.timestamps_ns for p in got] == [tuple(t - t_first + start for t in p.timestamps_ns)
                                                  for p in live[:10]], options


def test_a_recorder_tells_its_inner_replays_kind_of_stamps(take, tmp_path):
    """record+replay:// passes the replay's stamps through: the demo's latency figure asks the wrapper."""
    out, _, _ = take
    assert create_rig_source(f"record+replay://{out}?out={tmp_path / 'a'}").live_timestamps
    assert not create_rig_source(f"record+replay://{out}?keep_time=1&out={tmp_path / 'b'}").live_timestamps


def test_a_take_s_rig_warning_is_logged_at_open_once_by_sources_sharing_a_logged_set(tmp_path, sim_cache, caplog):
    """``replay://`` read its take's manifest with ``rig_from_dict``, which warned of the rig (here a narrow pair) at
    each ``create_rig_source``: the daemon creates a source at each reopen (each loop of the take, each lost
    camera) and at each reload's check of the URL, and the journal repeated the warning (session 66). It is logged
    at open now, naming the manifest, once over the sources sharing ``log_rig_warnings_once``'s set, as a rig file
    named in ``opencv://`` is; a source only created (a check) says nothing, a one-shot tool's open says it once."""
    take = tmp_path / "narrow"
    record(take, sim_cache, pairs=3, sim=f"{SIM}&baseline=0.05")  # (sim:// warns of the rig it builds, too)
    url = f"replay://{take}?speed=free"
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        create_rig_source(url)  # the daemon's check of a reloaded rig.url: opens nothing
    shared, alone = warnings_shared_and_alone(caplog, url)
    assert len(shared) == 1 and len(alone) == 1, caplog.text
    assert shared[0].startswith(f"{take / MANIFEST}: cameras 'left' and 'right' are 50 mm apart"), shared


def test_speed_factor_scales_waiting(take):
    out, live, _ = take
    clock = ManualClock()
    with open_rig(f"replay://{out}?speed=2&policy=all", clock=clock) as source:
        first = source.read(timeout_s=5.0)
        for _ in range(9):
            last = source.read(timeout_s=5.0)
    assert clock.now_ns() == pytest.approx((max(last.timestamps_ns) - min(first.timestamps_ns[:1])) / 2, abs=2)


def test_end_of_stream_and_loop(take):
    out, live, _ = take
    with open_rig(f"replay://{out}?speed=free&policy=all") as source:
        for _ in live:
            source.read(timeout_s=1.0)
        with pytest.raises(EndOfStream):
            source.read(timeout_s=1.0)
    with open_rig(f"replay://{out}?speed=free&loop=1&policy=all") as source:
        pairs = [source.read(timeout_s=1.0) for _ in range(2 * len(live) + 5)]
    for cam in (0, 1):
        stamps = [p.frames[cam].timestamp_ns for p in pairs]
        indices = [p.frames[cam].index for p in pairs]
        assert all(b > a for a, b in zip(stamps, stamps[1:]))
        assert all(b > a for a, b in zip(indices, indices[1:]))
    assert np.array_equal(pairs[len(live)].images[0], pairs[0].images[0])  # second pass, same pictures


def test_a_loop_pass_of_a_take_whose_stamps_are_all_one_comes_a_frame_period_later(copy_of_take):
    """Repeated stamps gave a 1 ns loop period: each pass 1 ns after the last, so a paced policy=latest read
    after a 10 ms stall had ten million passes due, and hung. The period is the default frame period then."""
    rows = [json.loads(line) for line in (copy_of_take / FRAMES).read_text().splitlines()][:8]
    for row in rows:
        row["timestamp_ns"] = 5_000
    (copy_of_take / FRAMES).write_text("".join(json.dumps(r) + "\n" for r in rows))
    with open_rig(f"replay://{copy_of_take}?speed=free&loop=1&keep_time=1&policy=all") as source:
        stamps = sorted({f.timestamp_ns for _ in range(8) for f in source.read(timeout_s=1.0).frames})
    assert stamps[0] == 5_000 and stamps[1] - stamps[0] >= 30_000_000, stamps


def _take_ending_in_a_held_pair(out):
    """Cut the take's journal after its fourth pair's frames, the second moved to 15 ms after the first: a frame of
    the first camera 3/4 of a period later (25 ms) could still be closer to it, so the pairer holds that pair back
    for a frame that never comes. Returns the (camera, index, timestamp_ns) of the pair's two frames."""
    lines = (out / FRAMES).read_text().splitlines()
    rows = [json.loads(line) for line in lines]
    first = next(r for r in rows if r["camera"] == "left" and r["index"] == 3)
    second = next(r for r in rows if r["camera"] == "right" and r["index"] == 3)
    second["timestamp_ns"] = first["timestamp_ns"] + 15_000_000
    kept = [r for r in rows if r["timestamp_ns"] < first["timestamp_ns"]] + [first, second]
    (out / FRAMES).write_text("".join(json.dumps(r) + "\n" for r in kept))
    return [(r["camera"], r["index"], r["timestamp_ns"]) for r in (first, second)]


@pytest.mark.parametrize("options", ["speed=free&policy=all", "speed=free&policy=latest",
                                     "speed=recorded&policy=latest"])
def test_the_end_of_a_replay_delivers_the_pair_it_held_then_stays_ended(copy_of_take, options):
    # The end of the recording decides the pair the pairer held (RigSource._take_frame): it is read before
    # EndOfStream, which every later read raises again.
    last = _take_ending_in_a_held_pair(copy_of_take)
    with open_rig(f"replay://{copy_of_take}?{options}&keep_time=1&tolerance_ms=20", clock=ManualClock()) as source:
        pairs = []
        with pytest.raises(EndOfStream, match="ended after"):
            while True:
                pairs.append(source.read(timeout_s=1.0))
        for _ in range(2):
            with pytest.raises(EndOfStream):
                source.read(timeout_s=1.0)
        stats = source.stats
    assert [(f.camera, f.index, f.timestamp_ns) for f in pairs[-1].frames] == last
    assert stats.pairs_out == len(pairs) and sum(stats.unpaired.values()) == 0


def test_jpeg_recording(tmp_path, sim_cache):
    live, _ = record(tmp_path / "jpg", sim_cache, pairs=5, image_format="jpg", jpeg_quality=90, lossless=1)
    assert read_manifest(tmp_path / "jpg").image_format == "jpg"
    replayed = replay_all(tmp_path / "jpg")
    for a, b in zip(live, replayed):
        for fa, fb in zip(a.frames, b.frames):
            assert_same_frame(fa, fb, exact_image=False)
            error = float(np.abs(fa.image.astype(int) - fb.image.astype(int)).mean())
            assert error < 8, error  # noisy 40x30 images: JPEG at 90 keeps them close


# ----------------------------------------------------------------- recorder behaviour
def test_drawing_on_a_delivered_image_does_not_reach_the_recording(tmp_path, sim_cache):
    captured = []
    with open_rig(f"record+{SIM}&cache={sim_cache}&out={tmp_path / 'drawn'}&lossless=1", clock=ManualClock()) as source:
        for _ in range(8):
            pair = source.read(timeout_s=5.0)
            captured.append([f.image.copy() for f in pair.frames])
            for frame in pair.frames:
                frame.image[:] = 0  # a consumer annotating the picture in place, before the writers ran
    replayed = replay_all(tmp_path / "drawn")
    for images, pair in zip(captured, replayed):
        for image, frame in zip(images, pair.frames):
            assert np.array_equal(image, frame.image)


def test_recorder_options_never_reach_the_inner_backend(tmp_path):
    url = RigUrl.parse("sim://?fps=30&out=/tmp/x&image_format=jpg&width=64")
    options = record_module.RecordOptions.take_from(url)
    assert (str(options.out), options.image_format) == ("/tmp/x", "jpg")
    assert inner_url_text(url) == "sim://?fps=30&width=64"
    assert inner_url_text(RigUrl.parse("replay:///data/my%20take?loop=1")) == "replay:///data/my%20take?loop=1"
    with pytest.raises(RigConfigError, match="image_format"):
        create_rig_source(f"record+sim://?out={tmp_path}&image_format=tiff")


def test_the_inner_url_keeps_option_values_as_written():
    """The recorder hands the inner backend a URL rebuilt from the options left: urlencode wrote a space as '+',
    which a rig URL reads as a plus, so record+opencv://?first=/v/my%20take.mp4 opened /v/my+take.mp4."""
    url = RigUrl.parse("opencv://?first=/v/my%20take.mp4&second=/v/a%2Bb%26c%3Dd%25e%23f.mp4&out=/tmp/x")
    record_module.RecordOptions.take_from(url)
    inner = RigUrl.parse(inner_url_text(url))
    assert inner.options == {"first": "/v/my take.mp4", "second": "/v/a+b&c=d%e#f.mp4"}


def test_out_keyword_and_non_empty_directory(tmp_path, sim_cache):
    source = create_rig_source(f"record+sim://?width=32&height=24&cache={sim_cache}", out=tmp_path / "kw",
                               clock=ManualClock())
    with source:
        source.read(timeout_s=1.0)
    assert (tmp_path / "kw" / MANIFEST).is_file()
    with pytest.raises(RigInitializationError, match="not empty"):
        open_rig(f"record+sim://?width=32&height=24&cache={sim_cache}&out={tmp_path / 'kw'}", clock=ManualClock())


def test_a_slow_disk_never_stalls_the_reader(tmp_path, sim_cache, monkeypatch):
    # The writer takes no frame at all while the reader reads (a disk far too slow): a reader that waited for it
    # would never finish its reads. Not timed: a loaded host's scheduler stretched the reads past a time bound.
    real_encode, released = record_module.encode_image, threading.Event()

    def held_encode(*args):
        assert released.wait(60), "the test never released the writer"
        return real_encode(*args)

    monkeypatch.setattr(record_module, "encode_image", held_encode)
    url = (f"record+sim://?width=40&height=30&fps=100&policy=all&cache={sim_cache}&out={tmp_path / 'slow'}"
           "&write_queue=2&writers=1")
    source, pairs = open_rig(url, clock=ManualClock()), []
    reader = threading.Thread(target=lambda: pairs.extend(source.read(timeout_s=5.0) for _ in range(40)), daemon=True)
    try:
        reader.start()
        reader.join(60)  # only a reader stalled on the held writer reaches it
        assert not reader.is_alive(), "the reader waited for the writer"
    finally:
        released.set()
        reader.join(60)
        source.close()
    stats = source.stats
    assert [p.sequence for p in pairs] == list(range(40))
    # the writer's one frame and the queue's two are written, the others dropped, every one counted
    assert 0 < stats.frames_written <= 3
    assert stats.frames_written + stats.writes_dropped == sum(stats.frames_in.values()) >= 80
    with open_rig(f"replay://{tmp_path / 'slow'}?speed=free&policy=all") as source:
        list(source)
        assert sum(source.stats.frames_in.values()) == stats.frames_written


def test_a_failing_writer_is_reported_once_then_frames_pass_through(tmp_path, sim_cache, monkeypatch):
    def broken(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(record_module, "encode_image", broken)
    out = tmp_path / "full"
    with open_rig(f"record+sim://?width=32&height=24&cache={sim_cache}&out={out}", clock=ManualClock()) as source:
        source.read(timeout_s=1.0)
        # the writer thread meets the error in its own time (a loaded host: seconds); the next read raises it
        deadline = time.monotonic() + 60
        while source._writer.error is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert source._writer.error is not None, "the writer never tried the frame"
        with pytest.raises(RecordingError, match="No space left") as info:
            source.read(timeout_s=1.0)
        assert isinstance(info.value, RigOperationError)  # readers catching the base go on as before
        source.read(timeout_s=1.0)  # the camera keeps working
    assert read_manifest(out).complete is False


def test_after_a_write_error_every_frame_is_written_or_counted(tmp_path, sim_cache, monkeypatch):
    # the failed frame and those drained from the queue after it were counted nowhere (2 + 4 of 20)
    real, calls, gate = record_module.encode_image, [0], threading.Event()

    def fails_third(*args):
        calls[0] += 1
        if calls[0] == 3:
            gate.wait(2.0)  # the queue fills behind it
            raise OSError(28, "No space left on device")
        return real(*args)

    monkeypatch.setattr(record_module, "encode_image", fails_third)
    out = tmp_path / "full"
    url = f"record+sim://?width=32&height=24&cache={sim_cache}&out={out}&writers=1&write_queue=16"
    with open_rig(url, clock=ManualClock()) as source:
        for _ in range(10):
            try:
                source.read(timeout_s=1.0)
            except RigOperationError:
                pass  # the failure, reported once
        gate.set()
    stats = source.stats
    assert stats.frames_written + stats.writes_dropped == sum(stats.frames_in.values()) == 20
    counters = read_manifest(out).counters
    assert counters["frames_written"] + counters["writes_dropped"] == 20


def test_a_frame_the_full_disk_cut_short_leaves_no_file_behind(tmp_path, sim_cache, monkeypatch):
    """Its image was written, its truth half: both are in no row; kept, they hold the space that close needs
    to rewrite the manifest with the counters (seen on a 300 kB tmpfs: close failed, counters lost)."""
    real, calls = record_module.write_truth, [0]

    def fills_the_disk(path, *args):
        calls[0] += 1
        if calls[0] == 3:
            Path(path).write_bytes(b"PK\x03\x04")
            raise OSError(28, "No space left on device")
        return real(path, *args)

    monkeypatch.setattr(record_module, "write_truth", fills_the_disk)
    out = tmp_path / "full"
    url = f"record+sim://?width=32&height=24&cache={sim_cache}&out={out}&writers=1&lossless=1"
    with open_rig(url, clock=ManualClock()) as source:
        for _ in range(4):
            try:
                source.read(timeout_s=1.0)
            except RigOperationError:
                pass  # the failure, reported once
    listed = {r[key] for r in journal(out) for key in ("image", "truth") if r[key]}
    on_disk = {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()} - {MANIFEST, FRAMES}
    assert len(listed) == 4 and on_disk == listed  # two whole frames, nothing of the third
    assert read_manifest(out).counters["writes_dropped"] == source.stats.writes_dropped > 0


def test_a_journal_the_full_disk_cannot_take_still_closes_with_the_counters(tmp_path, sim_cache, monkeypatch):
    """The rows left in the journal's buffer fail again at close: that raised OSError before the manifest's
    last rewrite, so close failed and the counters were lost."""
    if not os.path.exists("/dev/full"):
        pytest.skip("needs /dev/full (every write: ENOSPC)")
    real_start = record_module.RecordingWriter.start

    def start(self):
        real_start(self)
        self._journal.close()
        self._journal = open("/dev/full", "w", encoding="utf-8")

    monkeypatch.setattr(record_module.RecordingWriter, "start", start)
    out = tmp_path / "full"
    url = f"record+sim://?width=32&height=24&cache={sim_cache}&out={out}&writers=1&lossless=1"
    with open_rig(url, clock=ManualClock()) as source:
        for _ in range(3):
            try:
                source.read(timeout_s=1.0)
            except RigOperationError:
                pass  # the failure, reported once
    manifest = read_manifest(out)
    assert manifest.complete is False
    assert manifest.counters["writes_dropped"] == source.stats.writes_dropped == sum(source.stats.frames_in.values())


def test_a_close_whose_disk_stops_answering_gives_up_after_close_timeout_s(tmp_path, sim_cache, monkeypatch, caplog):
    """A writer stuck in a write for good (a USB stick pulled, an NFS mount gone): close joined it with no timeout,
    so the close of a record+ source, and every stop held while it ran, hung for good. Not timed: the close only has
    to return while the write is still blocked."""
    real, calls, entered, released = record_module.encode_image, [0], threading.Event(), threading.Event()

    def dead_disk_from_the_third_frame(*args):
        calls[0] += 1
        if calls[0] >= 3:
            entered.set()
            released.wait(120)  # the disk answers only once the test is done
        return real(*args)

    monkeypatch.setattr(record_module, "encode_image", dead_disk_from_the_third_frame)
    out = tmp_path / "dead"
    url = f"record+sim://?width=32&height=24&cache={sim_cache}&out={out}&writers=1&lossless=1&close_timeout_s=0.2"
    source = open_rig(url, clock=ManualClock())
    closer = threading.Thread(target=source.close, name="test-closer", daemon=True)
    try:
        source.read(timeout_s=5.0)  # a pair: the two frames written
        source.read(timeout_s=5.0)  # the third frame's write never ends; the fourth, queued behind it, is lost
        assert entered.wait(60), "the writer never reached the third frame"
        closer.start()
        closer.join(60)  # the old close waited on the stuck writer for good
        assert not closer.is_alive(), "close waited for a writer stuck in a write"
        manifest = read_manifest(out)
        assert manifest.complete is False
        assert manifest.counters["close_timed_out_s"] == 0.2
        assert manifest.counters["frames_written"] == 2 == len(journal(out))
        failure = RecordedTake(source, "prog").failure()  # what ghnerf-demo and ghcal capture say, exit 2
        assert failure and "the take's last frames were not written: the disk stopped answering" in failure
        assert any(name.startswith("rig-recorder-0 ") for name in source.lingering()), source.lingering()
        with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"):
            with open_rig(f"replay://{out}?speed=free&policy=all") as replay:
                list(replay)
                assert sum(replay.stats.frames_in.values()) == 2
        assert "the disk stopped answering" in caplog.text
    finally:
        released.set()
        closer.join(60) if closer.is_alive() else None
    deadline = time.monotonic() + 60  # the writer, released, ends; no longer lingering
    while source.lingering() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert source.lingering() == ()


def test_a_close_whose_last_fsync_never_returns_gives_up_after_close_timeout_s(tmp_path, sim_cache, monkeypatch):
    """The writers finished, the disk died before the take's fsyncs at close: the close gives up there too."""
    entered, released = threading.Event(), threading.Event()

    def dead_disk(path):
        entered.set()
        released.wait(120)

    out = tmp_path / "dead"
    url = f"record+sim://?width=32&height=24&cache={sim_cache}&out={out}&writers=1&lossless=1&close_timeout_s=0.2"
    source = open_rig(url, clock=ManualClock())
    closer = threading.Thread(target=source.close, name="test-closer", daemon=True)
    try:
        source.read(timeout_s=5.0)
        monkeypatch.setattr(record_module, "_fsync", dead_disk)
        closer.start()
        closer.join(60)
        assert not closer.is_alive(), "close waited for an fsync stuck for good"
        assert entered.is_set()
        manifest = read_manifest(out)
        assert manifest.complete is False and manifest.counters["close_timed_out_s"] == 0.2
        assert "the disk stopped answering" in source.unreported_failure()
        assert any(name.startswith("rig-recorder-close ") for name in source.lingering()), source.lingering()
    finally:
        released.set()
        closer.join(60) if closer.is_alive() else None


# ----------------------------------------------------------------- broken takes
@pytest.fixture
def copy_of_take(take, tmp_path):
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(take[0], out)
    return out


def edit_manifest(path, change):
    data = json.loads((path / MANIFEST).read_text())
    change(data)
    (path / MANIFEST).write_text(json.dumps(data))


def test_not_a_recording(tmp_path):
    with pytest.raises(RigInitializationError, match="does not exist"):
        create_rig_source(f"replay://{tmp_path / 'nowhere'}")
    with pytest.raises(RigInitializationError, match="manifest.json"):
        create_rig_source(f"replay://{tmp_path}")


def test_a_file_for_the_take_is_named_as_a_file(tmp_path):
    (tmp_path / "take.json").write_text("{}")
    with pytest.raises(RigInitializationError) as info:  # was "does not exist"
        create_rig_source(f"replay://{tmp_path / 'take.json'}")
    assert f"recording directory {tmp_path / 'take.json'} is a file, not a folder" in str(info.value)


@pytest.mark.parametrize("text, says", [
    # each was a RecursionError or ValueError traceback from the replay's open (and the daemon's config check)
    ("[" * 100_000 + "]" * 100_000, "invalid JSON: nested too deeply"),
    ('{"rig": ' + "[" * 500 + "]" * 500 + "}", "invalid JSON: nested too deeply"),  # parsed: a RecursionError
    ('{"version": 1' + "0" * 5000 + "}", "invalid JSON: Exceeds the limit (4300 digits)"),
    # JSON keeps the last: a hand-edited manifest's first value was lost without a word
    ('{"format": "ghnerf-rig-recording", "version": 1, "version": 1}', "duplicate key 'version'"),
    ('{"rig": {"cameras": [{"K": 1, "K": 2}]}}', "duplicate key 'rig.cameras[0].K'"),
])
def test_manifest_json_past_the_parser_names_the_file(copy_of_take, text, says):
    (copy_of_take / MANIFEST).write_text(text)
    with pytest.raises(RigInitializationError) as info:
        create_rig_source(f"replay://{copy_of_take}")
    assert f"recording file {copy_of_take / MANIFEST}: {says}" in str(info.value)


@pytest.mark.parametrize("line, says", [
    ("[" * 100_000 + "]" * 100_000, "invalid JSON: nested too deeply"),  # was a RecursionError traceback
    ('{"camera": "left", "index": 0, "index": 7}', "duplicate key 'index'"),
])
def test_journal_line_past_the_parser_names_file_and_line(copy_of_take, line, says):
    lines = (copy_of_take / FRAMES).read_text().splitlines()
    lines[4] = line
    (copy_of_take / FRAMES).write_text("\n".join(lines) + "\n")
    with pytest.raises(RigInitializationError) as info:
        create_rig_source(f"replay://{copy_of_take}")
    assert f"recording file {copy_of_take / FRAMES}: line 5: {says}" in str(info.value)


def test_manifest_that_is_not_json_names_the_file_and_line(copy_of_take):
    (copy_of_take / MANIFEST).write_text('{"format": "ghnerf-rig-recording",\n "version": }')
    with pytest.raises(RigInitializationError) as info:
        create_rig_source(f"replay://{copy_of_take}")
    assert str(copy_of_take / MANIFEST) in str(info.value) and "line 2" in str(info.value)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (lambda d: d.update(version=99), "version"),
        (lambda d: d.pop("rig"), "rig"),
        (lambda d: d.update(image_format="bmp"), "image_format"),
        (lambda d: d.update(complete="yes"), "complete"),
        (lambda d: d.update(extra=1), "extra"),
        (lambda d: d["rig"]["cameras"][1].pop("K"), "rig.cameras[1].K"),
        (lambda d: d["rig"]["cameras"][0].update(width=-5), "rig.cameras[0].width"),
    ],
)
def test_corrupt_manifest_names_the_file_and_the_field(copy_of_take, change, field):
    edit_manifest(copy_of_take, change)
    with pytest.raises(RigInitializationError) as info:
        create_rig_source(f"replay://{copy_of_take}")
    assert str(copy_of_take / MANIFEST) in str(info.value)
    assert f"field {field!r}" in str(info.value)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (lambda r: r.update(timestamp_ns="soon"), "timestamp_ns"),
        # beyond 64 bits: taken, then a bare OverflowError from numpy when the source was made
        (lambda r: r.update(timestamp_ns=2**70), "timestamp_ns"),
        (lambda r: r.update(index=-(2**63) - 1), "index"),
        (lambda r: r.update(camera="middle"), "camera"),
        (lambda r: r.pop("index"), "index"),
        (lambda r: r.update(image="../../etc/passwd"), "image"),
        (lambda r: r.update(scene_time_s=float("nan")), "scene_time_s"),
    ],
)
def test_corrupt_journal_row_names_file_line_and_field(copy_of_take, change, field):
    lines = (copy_of_take / FRAMES).read_text().splitlines()
    row = json.loads(lines[4])
    change(row)
    lines[4] = json.dumps(row)
    (copy_of_take / FRAMES).write_text("\n".join(lines) + "\n")
    with pytest.raises(RigInitializationError) as info:
        create_rig_source(f"replay://{copy_of_take}")
    message = str(info.value)
    assert str(copy_of_take / FRAMES) in message and "line 5" in message and f"field {field!r}" in message


def test_torn_last_line_is_tolerated_only_in_an_interrupted_take(copy_of_take):
    with open(copy_of_take / FRAMES, "a") as f:
        f.write('{"camera": "left", "ind')
    with pytest.raises(RigInitializationError, match="invalid JSON"):
        create_rig_source(f"replay://{copy_of_take}")
    edit_manifest(copy_of_take, lambda d: d.update(complete=False))
    source = create_rig_source(f"replay://{copy_of_take}")  # plays what it holds
    source.close()


def journal(take):
    return [json.loads(line) for line in (take / FRAMES).read_text().splitlines()]


def tear_the_tail(take):
    """What a power cut can leave: the last rows' files empty or missing, the journal ending in NULs."""
    rows = journal(take)
    (take / rows[-1]["image"]).write_bytes(b"")
    (take / rows[-2]["truth"]).unlink()
    with open(take / FRAMES, "ab") as f:
        f.write(b"\0" * 300)
    return rows


def _frames_played_when_interrupted(take, caplog) -> int:
    """Mark ``take`` interrupted (``complete: false``), play it whole; the frames it delivered."""
    edit_manifest(take, lambda d: d.update(complete=False))
    with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"):
        with open_rig(f"replay://{take}?speed=free&policy=all") as source:
            list(source)
            return sum(source.stats.frames_in.values())


def test_an_interrupted_take_plays_without_its_torn_tail(copy_of_take, caplog):
    rows = tear_the_tail(copy_of_take)
    assert _frames_played_when_interrupted(copy_of_take, caplog) == len(rows) - 2
    assert "dropped 2 journal row(s)" in caplog.text


def test_a_complete_take_with_a_torn_tail_is_an_error_naming_file_and_line(copy_of_take):
    rows = tear_the_tail(copy_of_take)
    with pytest.raises(RigInitializationError) as info:  # the NUL line
        create_rig_source(f"replay://{copy_of_take}")
    assert str(copy_of_take / FRAMES) in str(info.value) and f"line {len(rows) + 1}" in str(info.value)
    (copy_of_take / FRAMES).write_text("".join(json.dumps(row) + "\n" for row in rows))  # without the NULs
    source = create_rig_source(f"replay://{copy_of_take}")
    with pytest.raises(RigInitializationError) as info:  # the files: missing or empty
        source.open()
    message = str(info.value)
    assert "2 file(s)" in message and str(copy_of_take / rows[-2]["truth"]) in message
    assert f"{copy_of_take / FRAMES} line {len(rows) - 1}" in message


def test_broken_rows_anywhere_in_an_interrupted_take_are_dropped(copy_of_take, caplog):
    """Two writer threads and no per-frame fsync: a power cut can leave empty files before whole rows."""
    rows = journal(copy_of_take)
    (copy_of_take / rows[2]["image"]).write_bytes(b"")
    (copy_of_take / rows[-3]["image"]).unlink()
    source = create_rig_source(f"replay://{copy_of_take}")  # complete: true: still an error
    with pytest.raises(RigInitializationError, match="line 3"):
        source.open()
    assert _frames_played_when_interrupted(copy_of_take, caplog) == len(rows) - 2
    assert "dropped 2 journal row(s)" in caplog.text


def test_files_a_power_cut_left_half_written_are_dropped_not_replayed(copy_of_take, caplog, tmp_path):
    """Only a file's first blocks reached the disk: not empty, but undecodable; the take plays without them."""
    rows = journal(copy_of_take)
    for path in (copy_of_take / rows[3]["image"], copy_of_take / rows[-1]["truth"]):
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    assert _frames_played_when_interrupted(copy_of_take, caplog) == len(rows) - 2  # no RigOperationError
    assert "dropped 2 journal row(s)" in caplog.text
    image = np.zeros((30, 40, 3), np.uint8)
    for image_format in ("png", "jpg"):
        path = tmp_path / f"x.{image_format}"
        path.write_bytes(encode_image(image, image_format, 90))
        assert payload_is_whole(path)
        path.write_bytes(path.read_bytes()[:-1])
        assert not payload_is_whole(path)


def jpegs_another_tool_writes() -> dict[str, bytes]:
    """A 40x30 JPEG as the recorder writes it, progressive (ten scans, tables between them), and with a restart
    marker inside its scan."""
    image = np.random.default_rng(4).integers(0, 256, (30, 40, 3), np.uint8)
    options = {"baseline": [], "progressive": [cv2.IMWRITE_JPEG_PROGRESSIVE, 1],
               "restarts": [cv2.IMWRITE_JPEG_RST_INTERVAL, 1]}
    return {name: cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 90, *extra])[1].tobytes()
            for name, extra in options.items()}


#: What some tools write after a JPEG's end-of-image marker: a trailer of 100 bytes (not ending as a JPEG does),
#: padding, and an MPF ("multi-picture") second image.
AFTER_THE_END = {"trailer": bytes(range(100)), "padding": bytes(4096),
                 "second image": encode_image(np.zeros((6, 8, 3), np.uint8), "jpg", 90)}


@pytest.mark.parametrize("kind", sorted(jpegs_another_tool_writes()))
@pytest.mark.parametrize("after", sorted(AFTER_THE_END))
def test_a_jpeg_with_bytes_after_its_end_is_whole_and_one_cut_before_its_end_is_not(tmp_path, kind, after):
    """Cut after every byte: whole (and decoded as the image) exactly where the cut is past the end-of-image marker.
    Before, only a file ending at the marker was whole: a phone's JPEG with a trailer was dropped from a take cut
    short."""
    assert_whole_exactly_past_its_end(tmp_path / "image.jpg", jpegs_another_tool_writes()[kind], AFTER_THE_END[after])


@pytest.mark.parametrize("after", sorted(AFTER_THE_END))
def test_a_phone_jpeg_cut_at_its_exif_thumbnail_s_end_is_not_whole(tmp_path, after):
    """A phone's JPEG (benchmarks/time_replay_open.py's: APP1 EXIF holding a thumbnail, a comment), cut after every
    byte. Before, one cut right after its thumbnail (inside APP1) ended at an end-of-image marker and was whole:
    played, then a corrupt frame mid-take."""
    thumbnail = encode_image(np.zeros((12, 16, 3), np.uint8), "jpg", 80)
    image = time_replay_open.encoded(np.random.default_rng(7).integers(0, 256, (30, 40, 3), np.uint8), "exif-jpg",
                                     thumbnail)
    path = tmp_path / "phone.jpg"
    path.write_bytes(image[:image.index(thumbnail) + len(thumbnail)])
    assert not payload_is_whole(path)
    assert_whole_exactly_past_its_end(path, image, AFTER_THE_END[after])


def assert_whole_exactly_past_its_end(path, image: bytes, after: bytes) -> None:
    """``image`` followed by ``after``, written to ``path`` cut after every byte, is whole exactly where the cut is
    past the image's end, and whole it decodes as the image."""
    data = image + after
    wrong = []
    for end in range(1, len(data) + 1):
        path.write_bytes(data[:end])
        if payload_is_whole(path) != (end >= len(image)):
            wrong.append(end)
    assert wrong == []
    path.write_bytes(data)
    assert np.array_equal(load_image(path), cv2.imdecode(np.frombuffer(image, np.uint8), cv2.IMREAD_COLOR))


def as_jpeg_take(take):
    """``take``'s PNG images converted to JPEGs (the journal and manifest naming those), as another tool would."""
    for path in take.glob("images/*/*.png"):
        path.with_suffix(".jpg").write_bytes(encode_image(cv2.imread(str(path)), "jpg", 90))
        path.unlink()
    (take / FRAMES).write_text((take / FRAMES).read_text().replace(".png", ".jpg"))
    edit_manifest(take, lambda d: d.update(image_format="jpg"))


def test_an_interrupted_take_plays_a_jpeg_with_a_trailer_and_drops_one_cut_in_its_scan(copy_of_take, caplog):
    as_jpeg_take(copy_of_take)
    rows = journal(copy_of_take)
    with_trailer, cut = copy_of_take / rows[3]["image"], copy_of_take / rows[6]["image"]
    with_trailer.write_bytes(with_trailer.read_bytes() + AFTER_THE_END["trailer"])
    data = cut.read_bytes()
    cut.write_bytes(data[:data.index(b"\xff\xda") + 40])  # its scan header and a few bytes of its scan data
    assert _frames_played_when_interrupted(copy_of_take, caplog) == len(rows) - 1
    assert "dropped 1 journal row(s)" in caplog.text


def pngs_and_bmps_another_tool_writes() -> dict[str, bytes]:
    """A 40x30 image as PNG (as the recorder writes it, and with a text chunk after its image data) and as BMP
    (as OpenCV writes it; with its file size left 0, so its pixel data's offset and rows tell; 8-bit with a
    palette; run-length coded, whose image size the header gives)."""
    image = np.random.default_rng(5).integers(0, 256, (30, 40, 3), np.uint8)
    png = encode_image(image, "png", 90)
    text = b"tEXtComment\x00made elsewhere"
    text_chunk = struct.pack(">I", len(text) - 4) + text + struct.pack(">I", zlib.crc32(text))
    bmp = cv2.imencode(".bmp", image)[1].tobytes()
    bmp_size_left_0 = bmp[:2] + bytes(4) + bmp[6:]
    return {"png": png, "png with a text chunk": png[:-12] + text_chunk + png[-12:], "bmp": bmp,
            "bmp of size 0": bmp_size_left_0, "bmp 8-bit": cv2.imencode(".bmp", image[:, :, 0])[1].tobytes(),
            "bmp rle": bmp_built(8, 1, 40, width=40, height=30)}


@pytest.mark.parametrize("kind", sorted(pngs_and_bmps_another_tool_writes()))
@pytest.mark.parametrize("after", sorted(AFTER_THE_END))
def test_a_png_or_bmp_with_bytes_after_its_end_is_whole_and_one_cut_before_its_end_is_not(tmp_path, kind, after):
    """Cut after every byte: whole (and decoded as the image) exactly where the cut is past the PNG's IEND chunk or
    the BMP's last pixel row. Before, a PNG with a trailer was dropped from a take cut short, and a BMP cut short
    was played (then failed to decode mid-take)."""
    assert_whole_exactly_past_its_end(tmp_path / f"image.{kind[:3]}", pngs_and_bmps_another_tool_writes()[kind],
                                      AFTER_THE_END[after])


@pytest.mark.parametrize("name", ["image.jpeg", "image.JPG", "image.JPEG", "image.PNG", "image.BMP"])
def test_another_tool_s_suffixes_are_checked_whatever_their_case(tmp_path, name):
    """A .jpeg is a JPEG; upper case is the same suffix. Before, a .jpeg or .bmp cut short was whole (not empty)."""
    image = np.random.default_rng(6).integers(0, 256, (30, 40, 3), np.uint8)
    kind = {"JPEG": ".jpg", "JPG": ".jpg", "PNG": ".png", "BMP": ".bmp"}[name.split(".")[1].upper()]
    data = cv2.imencode(kind, image)[1].tobytes()
    path = tmp_path / name
    for cut, whole in ((data, True), (data + AFTER_THE_END["trailer"], True), (data[:-20], False)):
        path.write_bytes(cut)
        assert payload_is_whole(path) == whole, (len(cut), len(data))


def tiffs_and_webps_another_tool_writes() -> dict[str, bytes]:
    """A 40x30 image as TIFF: as OpenCV writes it (LZW; its directory, then the values it holds elsewhere, after
    the image data), uncompressed in four strips, laid out again as a big-endian BigTIFF, and a 16x16 one in one
    tile (BGRA: 1024-byte tiles, which OpenCV 5.0 decodes from memory: test_replay_image_sizes.py); and as WebP: lossy, lossless, and extended (VP8X)
    with an EXIF chunk after its image."""
    image = np.random.default_rng(9).integers(0, 256, (30, 40, 3), np.uint8)
    lzw = cv2.imencode(".tiff", image)[1].tobytes()
    strips = cv2.imencode(".tiff", image, [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1].tobytes()
    lossy = cv2.imencode(".webp", image, [cv2.IMWRITE_WEBP_QUALITY, 90])[1].tobytes()
    return {"tiff": lzw, "tiff in strips": strips, "bigtiff": tiff_laid_out(lzw, ">", big=True),
            "tiff in a tile": tiled_tiff(), "webp": lossy,
            "webp lossless": cv2.imencode(".webp", image, [cv2.IMWRITE_WEBP_QUALITY, 101])[1].tobytes(),
            "webp with exif": webp_extended(lossy, flags=0x08, after=riff_chunk(b"EXIF", b"II*\x00" + bytes(4)))}


def tiled_tiff() -> bytes:
    """A 16x16 BGRA TIFF in one 16x16 tile: OpenCV's uncompressed single strip, its strip tags made tile tags."""
    image = np.random.default_rng(10).integers(0, 256, (16, 16, 4), np.uint8)
    data = cv2.imencode(".tiff", image, [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1].tobytes()
    entries = tiff_entries(data)
    assert len(entries[273][1]) == 1
    tiled = tiff_laid_out(data, changed={273: None, 278: None, 279: None, 322: (3, (16,)), 323: (3, (16,)),
                                         324: (4, entries[273][1]), 325: (4, entries[279][1])})
    assert np.array_equal(cv2.imdecode(np.frombuffer(tiled, np.uint8), cv2.IMREAD_UNCHANGED), image)
    return tiled


@pytest.mark.parametrize("kind", sorted(tiffs_and_webps_another_tool_writes()))
@pytest.mark.parametrize("after", sorted(AFTER_THE_END))
def test_a_tiff_or_webp_with_bytes_after_its_end_is_whole_and_one_cut_before_its_end_is_not(tmp_path, kind, after):
    """Cut after every byte: whole (and decoded as the image) exactly where the cut is past the TIFF's first
    directory, the values it points at and its strips or tiles, or past the WebP's RIFF size. Before session 63
    every cut was whole (not empty): played, then a corrupt frame mid-take."""
    suffix = ".webp" if kind.startswith("webp") else ".tiff"
    assert_whole_exactly_past_its_end(tmp_path / f"image{suffix}", tiffs_and_webps_another_tool_writes()[kind],
                                      AFTER_THE_END[after])


@pytest.mark.parametrize("name", ["image.tif", "image.TIF", "image.TIFF", "image.WEBP"])
def test_tiff_and_webp_suffixes_are_checked_whatever_their_case(tmp_path, name):
    kind = "webp" if name.lower().endswith(".webp") else "tiff"
    data = tiffs_and_webps_another_tool_writes()[kind]
    path = tmp_path / name
    for cut, whole in ((data, True), (data + AFTER_THE_END["trailer"], True), (data[:-1], False)):
        path.write_bytes(cut)
        assert payload_is_whole(path) == whole, (len(cut), len(data))


def test_a_tiff_whose_directory_or_image_data_cannot_be_located_is_not_whole(tmp_path):
    """No strips nor tiles, offsets without byte counts or of another number, offsets beyond any file: libtiff
    decodes none of these; nothing raises."""
    data = tiffs_and_webps_another_tool_writes()["tiff"]
    path = tmp_path / "image.tiff"
    for changed in ({273: None, 279: None}, {279: None}, {279: (4, (1, 2))}, {273: (4, (2**32 - 1,))}):
        path.write_bytes(tiff_laid_out(data, changed=changed))
        assert not payload_is_whole(path), changed
    huge_strips = b"II+\x00" + struct.pack("<HHQQHHQQ", 8, 0, 16, 1, 273, 16, 2**64 - 1, 0)  # 2**64 - 1 offsets
    for name, broken in (("image.tiff", b"II*\x00" + struct.pack("<I", 2**32 - 1)), ("image.tif", b"MM\x00*"),
                         ("image.tiff", huge_strips),
                         ("image.webp", b"RIFF" + bytes(8)), ("image.webp", b"RIFF\x04\x00\x00\x00WEBP")):
        (tmp_path / name).write_bytes(broken)
        assert not payload_is_whole(tmp_path / name), broken


def pnms_and_avifs_another_tool_writes() -> dict[str, bytes]:
    """A 16x12 image as binary PPM, PGM (8 and 16 bits) and PBM as OpenCV writes them, and a PPM whose header holds
    comments (as other tools write); a 40x30 one as AVIF: OpenCV's (ftyp, meta, mdat), and with alpha (a second
    item)."""
    image = np.random.default_rng(14).integers(0, 256, (30, 40, 3), np.uint8)
    small = image[:12, :16]
    ppm = cv2.imencode(".ppm", small)[1].tobytes()
    pixels = ppm[len(b"P6\n16 12\n255\n"):]
    return {"ppm": ppm, "ppm with comments": b"P6\n# by a tool\n16 # width\n12\n#\n255\r" + pixels,
            "pgm": cv2.imencode(".pgm", small[:, :, 0])[1].tobytes(),
            "pgm 16-bit": cv2.imencode(".pgm", small[:, :, 0].astype(np.uint16) * 257)[1].tobytes(),
            "pbm": cv2.imencode(".pbm", image[:, :, 0])[1].tobytes(), "avif": cv2.imencode(".avif", image)[1].tobytes(),
            "avif with alpha": cv2.imencode(".avif", np.dstack([image, image[:, :, :1]]))[1].tobytes()}


@pytest.mark.parametrize("kind", sorted(pnms_and_avifs_another_tool_writes()))
@pytest.mark.parametrize("after", sorted(AFTER_THE_END))
def test_a_pnm_or_avif_with_bytes_after_its_end_is_whole_and_one_cut_before_its_end_is_not(tmp_path, kind, after):
    """Cut after every byte: whole (and decoded as the image) exactly where the cut is past a PNM's pixel data
    (the size its header gives) or past an AVIF's meta box and its items' data (its iloc extents). Before session
    63 every cut was whole (not empty): played, then a corrupt frame mid-take."""
    suffix = {"ppm": ".ppm", "pgm": ".pgm", "pbm": ".pbm", "avi": ".avif"}[kind[:3]]
    assert_whole_exactly_past_its_end(tmp_path / f"image{suffix}", pnms_and_avifs_another_tool_writes()[kind],
                                      AFTER_THE_END[after])


@pytest.mark.parametrize("name", ["image.PPM", "image.pnm", "image.pxm", "image.AVIF"])
def test_pnm_and_avif_suffixes_are_checked_whatever_their_case(tmp_path, name):
    data = pnms_and_avifs_another_tool_writes()["avif" if name.lower().endswith(".avif") else "ppm"]
    path = tmp_path / name
    for cut, whole in ((data, True), (data + AFTER_THE_END["trailer"], True), (data[:-1], False)):
        path.write_bytes(cut)
        assert payload_is_whole(path) == whole, (len(cut), len(data))


def ascii_pnms() -> dict[str, bytes]:
    """A 16x12 image as ASCII PPM, PGM and PBM (P3, P2, P1) as OpenCV writes them (each sample followed by a space
    or a line end)."""
    image = np.random.default_rng(15).integers(0, 256, (12, 16, 3), np.uint8)
    plain = [cv2.IMWRITE_PXM_BINARY, 0]
    return {".ppm": cv2.imencode(".ppm", image, plain)[1].tobytes(),
            ".pgm": cv2.imencode(".pgm", image[:, :, 0], plain)[1].tobytes(),
            ".pbm": cv2.imencode(".pbm", image[:, :, 0], plain)[1].tobytes()}


@pytest.mark.parametrize("suffix", sorted(ascii_pnms()))
def test_an_ascii_pnm_cut_short_is_not_whole(tmp_path, suffix):
    """P1 to P3 give no length: before session 66 any not empty was whole (a take cut short played its last frame,
    then a corrupt frame). Now decoded: cut after every byte, whole exactly where OpenCV decodes it (the whole file,
    or all but bytes after the last sample's separator), and never where a sample is lost."""
    data = ascii_pnms()[suffix]
    path = tmp_path / f"image{suffix}"
    for end in range(1, len(data) + 1):
        path.write_bytes(data[:end])
        decodes = cv2.imdecode(np.frombuffer(data[:end], np.uint8), cv2.IMREAD_COLOR) is not None
        assert payload_is_whole(path) == decodes, end
    assert payload_is_whole(path)
    path.write_bytes(data[:-3])  # the last sample cut in its digits (P1: lost)
    assert not payload_is_whole(path)


def test_a_binary_pnm_whose_header_is_too_long_to_read_is_whole_where_it_decodes(tmp_path):
    """A header of comments past the 4096 bytes read: decoded, not taken as whole (its pixels lost: not whole)."""
    path = tmp_path / "image.ppm"
    long_header = b"P6\n" + b"#" * 5000 + b"\n4 3\n255\n"
    for data, whole in ((long_header + bytes(36), True), (long_header + bytes(35), False), (long_header, False),
                        (long_header[:4500], False)):
        path.write_bytes(data)
        assert payload_is_whole(path) == whole, len(data)


#: Formats OpenCV writes whose suffix no walk here knows: each is whole where it decodes (image_is_whole).
RARER_SUFFIXES = (".sr", ".ras", ".pam", ".pfm", ".hdr", ".jp2", ".gif", ".jpe", ".dib")


@pytest.mark.parametrize("suffix", RARER_SUFFIXES)
def test_an_image_of_a_rarer_suffix_cut_short_is_not_whole(tmp_path, suffix):
    """Before session 66 such a file was whole where not empty: now an image is decoded (image_is_whole); a truth
    file (payload_is_whole) of another suffix is still checked for being there and not empty only."""
    image = np.random.default_rng(16).integers(0, 256, (48, 64, 3), np.uint8)  # (JPEG 2000: at least 32x32)
    data = cv2.imencode(suffix, image.astype(np.float32) / 255 if suffix in (".pfm", ".hdr") else image)[1].tobytes()
    path = tmp_path / f"image{suffix}"
    path.write_bytes(data)
    assert image_is_whole(path)
    for end in (len(data) // 2, len(data) - 1):
        path.write_bytes(data[:end])
        assert not image_is_whole(path), end
        assert payload_is_whole(path)


def test_a_pnm_or_avif_whose_header_cannot_be_followed_is_not_whole_and_nothing_raises(tmp_path):
    """Another magic number, a header cut short, an AVIF with no meta or iloc, an iloc of another version or
    locating its data in another file or item, an iloc cut short or claiming 65535 items in a few bytes."""
    avif = pnms_and_avifs_another_tool_writes()["avif"]
    iloc_at = avif.index(b"iloc") + 4  # its version
    def iloc_changed(at: int, new: bytes) -> bytes:
        return avif[:iloc_at + at] + new + avif[iloc_at + at + len(new):]
    broken = {"image.ppm": [b"P7\n16 12\n255\n" + bytes(576), b"PNG", b"P6\n16 x\n", b"P6\n16 12\n255\n" + bytes(575)],
              "image.avif": [avif.replace(b"meta", b"free"), avif.replace(b"iloc", b"free"), iloc_changed(0, b"\x03"),
                             iloc_changed(1 + 3 + 2 + 2 + 2, b"\x00\x01"),  # data reference index 1: another file
                             iloc_changed(1 + 3 + 2, b"\xff\xff"), iloc_changed(1, b"\x00\x00\x00\xff\xff"),
                             b"\x00\x00\x00\x10ftypavif" + bytes(4)]}
    for name, datas in broken.items():
        for data in datas:
            (tmp_path / name).write_bytes(data)
            assert not payload_is_whole(tmp_path / name), data[:40]


def progressive_jpeg_with_a_comment_between_its_scans() -> tuple[bytes, int]:
    """A 40x30 progressive JPEG as OpenCV writes it, with a comment holding the bytes FF D9 before its second scan
    (a segment allowed there, as the next scan's tables are); and how far in those bytes end."""
    image = np.random.default_rng(11).integers(0, 256, (30, 40, 3), np.uint8)
    data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 90, cv2.IMWRITE_JPEG_PROGRESSIVE, 1])[1].tobytes()
    second_scan = data.index(b"\xff\xda", data.index(b"\xff\xda") + 2)
    comment = time_replay_open.jpeg_segment(0xFE, b"cut here: \xff\xd9, and on")
    with_comment = data[:second_scan] + comment + data[second_scan:]
    decoded = cv2.imdecode(np.frombuffer(with_comment, np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(decoded, cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))
    return with_comment, second_scan + comment.index(b"\xff\xd9", 4) + 2


@pytest.mark.parametrize("after", sorted(AFTER_THE_END))
def test_a_progressive_jpeg_cut_between_its_scans_on_the_bytes_ff_d9_is_not_whole(tmp_path, after):
    """Cut right after FF D9 in a segment between two scans, the file ends as a JPEG ends, and its segments reach
    its first scan: before session 63 it was whole (played, then a corrupt frame). Its scans are walked to its end
    now; cut after every byte, it is whole exactly past its end."""
    image, cut = progressive_jpeg_with_a_comment_between_its_scans()
    path = tmp_path / "progressive.jpg"
    path.write_bytes(image[:cut])
    assert not payload_is_whole(path)
    assert_whole_exactly_past_its_end(path, image, AFTER_THE_END[after])


def test_a_sequential_jpeg_of_one_component_a_scan_is_walked_to_its_end_too(tmp_path):
    """A sequential frame of three components whose first scan holds one: more scans follow, and a cut between
    them may end on FF D9 (headers only, built by hand: OpenCV writes no such file). One scan holding every
    component is the only one: its file ending on FF D9 ends at its marker, and is not walked."""
    frame = time_replay_open.jpeg_segment(0xC0, struct.pack(">BHHB", 8, 30, 40, 3) + bytes([1, 0x11, 0, 2, 0x11, 0,
                                                                                                 3, 0x11, 0]))
    comment = time_replay_open.jpeg_segment(0xFE, b"tables: \xff\xd9, and on")
    path = tmp_path / "sequential.jpg"

    def scan(*components: int) -> bytes:
        return time_replay_open.jpeg_segment(0xDA, bytes([len(components)]) + b"".join(
            bytes([c, 0]) for c in components) + bytes([0, 63, 0])) + b"\x12\x34\xff\x00\x56"

    cut_between_scans = b"\xff\xd8" + frame + scan(1) + comment
    path.write_bytes(cut_between_scans[:cut_between_scans.rindex(b"\xff\xd9") + 2])
    assert not payload_is_whole(path)
    path.write_bytes(b"\xff\xd8" + frame + scan(1) + scan(2) + scan(3) + b"\xff\xd9")
    assert payload_is_whole(path)
    path.write_bytes(b"\xff\xd8" + frame + scan(1, 2, 3) + b"\xff\xd9")
    assert payload_is_whole(path)


def as_take_of(take, suffix: str, encode):
    """``take``'s PNG images as another tool's files (``suffix``, bytes from ``encode(image)``), the journal naming
    them."""
    for path in take.glob("images/*/*.png"):
        path.with_suffix(suffix).write_bytes(encode(cv2.imread(str(path))))
        path.unlink()
    (take / FRAMES).write_text((take / FRAMES).read_text().replace(".png", suffix))


@pytest.mark.parametrize("suffix", [".png", ".bmp", ".jpeg", ".tiff", ".webp"])
def test_an_interrupted_take_plays_other_tools_files_with_a_trailer_and_drops_one_cut_short(copy_of_take, caplog,
                                                                                            suffix):
    if suffix != ".png":
        as_take_of(copy_of_take, suffix, lambda image: cv2.imencode(suffix, image)[1].tobytes())
    rows = journal(copy_of_take)
    with_trailer, cut = copy_of_take / rows[3]["image"], copy_of_take / rows[6]["image"]
    with_trailer.write_bytes(with_trailer.read_bytes() + AFTER_THE_END["trailer"])
    cut.write_bytes(cut.read_bytes()[:-30])  # its last pixels (PNG: its image data's end, CRC and IEND)
    assert _frames_played_when_interrupted(copy_of_take, caplog) == len(rows) - 1
    assert "dropped 1 journal row(s)" in caplog.text


@pytest.mark.parametrize("suffix", [".ppm", ".sr", ".pam"])
def test_an_interrupted_take_drops_its_last_frame_cut_short_in_a_rarer_format_naming_it(copy_of_take, caplog,
                                                                                       suffix):
    """A take cut short by a power loss, its files ASCII PPMs (or Sun raster, PAM), its last frame's file cut
    short: before session 66 played, then a corrupt frame at its end; dropped now, the warning naming it (the user
    replays what the take holds, as for a PNG cut short: the frame was never whole)."""
    params = [cv2.IMWRITE_PXM_BINARY, 0] if suffix == ".ppm" else []
    as_take_of(copy_of_take, suffix, lambda image: cv2.imencode(suffix, image, params)[1].tobytes())
    rows = journal(copy_of_take)
    last = max(rows, key=lambda row: row["index"])["image"]
    (copy_of_take / last).write_bytes((copy_of_take / last).read_bytes()[:-3])
    assert _frames_played_when_interrupted(copy_of_take, caplog) == len(rows) - 1
    assert "dropped 1 journal row(s)" in caplog.text and f"(image {last})" in caplog.text


def test_complete_is_marked_only_once_the_take_is_on_disk(tmp_path, sim_cache, monkeypatch):
    if not os.path.isdir("/proc/self/fd"):
        pytest.skip("needs /proc to name fsynced files")
    synced, at_complete = set(), []
    real_fsync, real_write = os.fsync, record_module.write_manifest

    def fsync(fd):
        synced.add(os.readlink(f"/proc/self/fd/{fd}"))
        real_fsync(fd)

    def write_manifest(directory, manifest):
        if manifest.complete:
            at_complete.append(set(synced))
        real_write(directory, manifest)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(record_module, "write_manifest", write_manifest)
    out = tmp_path / "take"
    record(out, sim_cache, pairs=4, lossless=1)
    root = Path(os.path.realpath(out))
    needed = {str(root / FRAMES)} | {str(root / r[key]) for r in journal(out) for key in ("image", "truth") if r[key]}
    assert len(at_complete) == 1 and not needed - at_complete[0]
    assert read_manifest(out).complete is True


def test_the_writers_fsync_as_they_go_so_the_backlog_stays_bounded(take, tmp_path, monkeypatch):
    """An hour at 30 fps stereo must not leave 216k files for close to fsync one by one."""
    from drivers.frames import Frame

    monkeypatch.setattr(record_module, "SYNC_BATCH", 4, raising=False)
    synced = []
    real_fsync = record_module._fsync
    monkeypatch.setattr(record_module, "_fsync", lambda path: (synced.append(Path(path)), real_fsync(path)))
    manifest = read_manifest(take[0])
    manifest.complete, manifest.counters = False, {}
    writer = record_module.RecordingWriter(
        tmp_path / "take", manifest, record_module.RecordOptions(out=tmp_path / "take", lossless=True))
    writer.start()
    n = 60
    try:
        for i in range(n):
            cam = manifest.rig.cameras[i % 2]
            writer.submit(Frame(cam.name, np.zeros((cam.height, cam.width, 3), np.uint8), 1000 * i, i // 2))
        deadline = time.monotonic() + 60  # 60 lossless encodes and fsyncs: seconds on a loaded host and disk
        while writer.frames_written < n and writer.error is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert writer.frames_written == n and writer.error is None
        assert len(writer._unsynced) < 4
        while sum(p.is_file() for p in synced) <= n - 4 and time.monotonic() < deadline:
            time.sleep(0.01)  # the last batch's fsyncs, off the lock
        assert sum(p.is_file() for p in synced) > n - 4  # fsynced before close
    finally:
        writer.close({})
    assert read_manifest(tmp_path / "take").complete
    images = {str(tmp_path / "take" / r["image"]) for r in journal(tmp_path / "take")}
    assert {str(p) for p in synced if p.is_file()} == images


def test_of_two_recorders_started_on_one_empty_folder_only_one_records(take, tmp_path, monkeypatch):
    """Both find the folder empty; rigs with other camera names made no folder in common: both recorded."""
    import dataclasses

    out = tmp_path / "take"
    manifest = read_manifest(take[0])
    other = dataclasses.replace(manifest.rig, cameras=tuple(
        dataclasses.replace(cam, name=cam.name.upper()) for cam in manifest.rig.cameras))
    both_looked = threading.Barrier(2)
    real_iterdir = Path.iterdir

    def iterdir(self):
        found = list(real_iterdir(self))
        if self == out:
            both_looked.wait(timeout=60)  # the other thread may start seconds later on a loaded host
        return iter(found)

    monkeypatch.setattr(Path, "iterdir", iterdir)
    outcomes = {}

    def start(rig):
        writer = record_module.RecordingWriter(
            out, record_module.Manifest(rig), record_module.RecordOptions(out=out))
        try:
            writer.start()
        except RigInitializationError as e:
            outcomes[rig.names] = e
        else:
            outcomes[rig.names] = None
            writer.close({})

    threads = [threading.Thread(target=start, args=(rig,)) for rig in (manifest.rig, other)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(120)
        assert not thread.is_alive(), "a recorder's start did not return"
    errors = [e for e in outcomes.values() if e is not None]
    assert len(outcomes) == 2 and len(errors) == 1
    assert "another recorder" in str(errors[0]) and str(out) in str(errors[0])
    winner = next(names for names, e in outcomes.items() if e is None)
    assert sorted(p.name for p in (out / "images").iterdir()) == sorted(winner)
    assert read_manifest(out).rig.names == winner


def test_a_rig_replay_would_refuse_is_not_recorded(take, tmp_path):
    """rig_from_dict (replay) checks the principal point: the recorder must not write a take it cannot open."""
    import dataclasses

    manifest = read_manifest(take[0])
    cam = manifest.rig.cameras[1]
    K = cam.K.copy()
    K[0, 2] = 0.9 * cam.width
    manifest.rig = dataclasses.replace(
        manifest.rig, cameras=(manifest.rig.cameras[0], dataclasses.replace(cam, K=K)))
    out = tmp_path / "take"
    writer = record_module.RecordingWriter(out, manifest, record_module.RecordOptions(out=out))
    with pytest.raises(RigInitializationError) as info:
        writer.start()
    assert repr(cam.name) in str(info.value) and "principal point" in str(info.value)
    assert not out.exists()


def test_missing_image_file_is_named_at_open(copy_of_take):
    row = json.loads((copy_of_take / FRAMES).read_text().splitlines()[3])
    (copy_of_take / row["image"]).unlink()
    source = create_rig_source(f"replay://{copy_of_take}")
    with pytest.raises(RigInitializationError) as info:
        source.open()
    assert str(copy_of_take / row["image"]) in str(info.value)


def first_row(take):
    """The journal row replayed first (the earliest capture)."""
    rows = [json.loads(line) for line in (take / FRAMES).read_text().splitlines()]
    return min(rows, key=lambda r: r["timestamp_ns"])


@pytest.mark.parametrize(("key", "garbage"), [("image", b"\x89PNG garbage"), ("truth", b"PK nonsense")])
def test_corrupt_image_or_truth_file_is_named_when_read(copy_of_take, key, garbage):
    row = first_row(copy_of_take)
    (copy_of_take / row[key]).write_bytes(garbage)
    with open_rig(f"replay://{copy_of_take}?speed=free") as source:
        with pytest.raises(RigOperationError) as info:
            source.read(timeout_s=1.0)
    assert str(copy_of_take / row[key]) in str(info.value) and "corrupt" in str(info.value)



def _npz_member(name: str, data: bytes, method: int) -> bytes:
    """A one-member zip holding ``data`` as stored, its CRC right, its compression method field set to ``method``
    in both headers (8: the stored bytes are inflated, as deflate data damaged on the disk)."""
    import io
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_STORED) as archive:
        archive.writestr(name, data)
    raw = bytearray(buffer.getvalue())
    for signature, offset in ((b"PK\x03\x04", 8), (b"PK\x01\x02", 10)):
        at = raw.find(signature)
        raw[at + offset:at + offset + 2] = struct.pack("<H", method)
    return bytes(raw)


#: An .npy header whose dict is cut off mid-tuple: numpy's header parse raises tokenize's TokenError.
_NPY_HEADER_CUT = b"\x93NUMPY\x01\x00" + struct.pack("<H", 38) + b"{'descr': '<f8', 'shape': (25,".ljust(37) + b"\n"


@pytest.mark.parametrize("damage", [
    pytest.param(_npz_member("joints_2d.npy", b"\xff" * 64, 8), id="deflate-data"),  # zlib.error
    pytest.param(_npz_member("joints_2d.npy", b"\0" * 64, 99), id="compression-method"),  # NotImplementedError
    pytest.param(_npz_member("joints_2d.npy", _NPY_HEADER_CUT, 0), id="npy-header"),  # tokenize.TokenError
])
def test_a_damaged_truth_file_is_a_corrupt_frame_named_when_read(copy_of_take, damage):
    """Damage inside a truth file's zip (not its end record) escaped load_truth as zlib's, zipfile's or tokenize's
    own error: a traceback from the read (ghnerf-demo exit 1), not a corrupt frame naming the file."""
    row = first_row(copy_of_take)
    (copy_of_take / row["truth"]).write_bytes(damage)
    with open_rig(f"replay://{copy_of_take}?speed=free") as source:
        with pytest.raises(RigOperationError, match="is corrupt") as info:
            source.read(timeout_s=1.0)
    assert str(copy_of_take / row["truth"]) in str(info.value)


def test_a_truth_file_it_may_not_read_is_told_with_the_os_reason_not_as_corrupt(tmp_path, monkeypatch):
    """A PermissionError (or any OS-level read failure) was reported "is corrupt": the file may be whole."""
    def refused(path, **kwargs):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))

    monkeypatch.setattr(np, "load", refused)  # the host runs as root: a chmod would not refuse the read
    path = tmp_path / "0.npz"
    with pytest.raises(RigOperationError) as info:
        load_truth(path)
    assert str(info.value) == f"recording truth file {path} cannot be read: {os.strerror(errno.EACCES)}"


def test_a_folder_where_the_truth_file_goes_is_told_as_a_folder_not_as_corrupt(tmp_path):
    path = tmp_path / "0.npz"
    path.mkdir()
    with pytest.raises(RigOperationError) as info:
        load_truth(path)
    assert str(info.value) == f"recording truth file {path} is a folder, not a file"


def test_an_image_of_the_wrong_size_is_named_at_open(copy_of_take):
    import cv2

    row = first_row(copy_of_take)
    cv2.imwrite(str(copy_of_take / row["image"]), np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(FrameSizeError, match=f"1 of its [0-9]+ images is 10x10 \\({row['image']};"):
        create_rig_source(f"replay://{copy_of_take}?speed=free").open()


def test_an_image_of_the_wrong_size_whose_name_holds_a_control_character_is_named_escaped(copy_of_take):
    """The size refusal listed frames.jsonl's image names raw: an escape sequence in one reached the terminal."""
    import cv2

    row = first_row(copy_of_take)
    odd = str(Path(row["image"]).with_name("odd\x1b[31m.png"))
    cv2.imwrite(str(copy_of_take / odd), np.zeros((10, 10, 3), np.uint8))
    rows = [json.loads(line) for line in (copy_of_take / FRAMES).read_text().splitlines()]
    (copy_of_take / FRAMES).write_text("".join(json.dumps(dict(r, image=odd) if r == row else r) + "\n"
                                               for r in rows))
    with pytest.raises(FrameSizeError) as info:
        create_rig_source(f"replay://{copy_of_take}?speed=free").open()
    assert "\x1b" not in str(info.value) and "1 of its " in str(info.value)
    assert f"is 10x10 ({odd!r};" in str(info.value)


def resize_images(take, camera, size):
    """Every image of ``camera`` in ``take`` rescaled to ``size`` (width, height), as an image tool would."""
    import cv2

    for path in sorted((take / "images" / camera).iterdir()):
        cv2.imwrite(str(path), cv2.resize(cv2.imread(str(path)), size))


def test_a_take_resized_throughout_is_refused_at_open_naming_a_file_and_both_sizes(copy_of_take):
    """Every image of a camera at another size than the take's rig (resized by a tool after recording): each read
    failed on its image, so nothing played, and a reader going past failed frames (the daemon) reopened the take for
    ever. Refused at open, typed as the other backends' cameras of another size than their rig file's."""
    resize_images(copy_of_take, "right", (20, 15))
    source = create_rig_source(f"replay://{copy_of_take}?speed=free")
    with pytest.raises(FrameSizeError) as info:
        source.open()
    error = info.value
    assert isinstance(error, RigInitializationError)  # an open that failed, as the registry's contract has it
    assert (error.camera, error.expected, error.delivered) == ("right", (40, 30), (20, 15))
    message = str(error)
    images = sorted(path.relative_to(copy_of_take).as_posix() for path in (copy_of_take / "images" / "right").iterdir())
    assert f"camera 'right': {len(images)} of its {len(images)} images are 20x15 ({', '.join(images[:3])}, ...; read " \
        f"from each image's header at open), but its rig camera in {copy_of_take / MANIFEST} is 40x30" in message
    assert not source.is_open


def test_a_take_whose_manifest_rig_was_replaced_by_one_of_another_size_is_refused_at_open(copy_of_take):
    """The rig in manifest.json swapped for one calibrated at twice the size: every image is of another size."""
    import dataclasses

    from ghnerf_runtime.rig_file import rig_to_dict

    rig = read_manifest(copy_of_take).rig
    bigger = dataclasses.replace(rig, cameras=tuple(cam.resized(80, 60) for cam in rig.cameras))
    edit_manifest(copy_of_take, lambda m: m.__setitem__("rig", rig_to_dict(bigger)))
    with pytest.raises(FrameSizeError) as info:
        create_rig_source(f"replay://{copy_of_take}").open()
    assert (info.value.camera, info.value.expected, info.value.delivered) == ("left", (80, 60), (40, 30))
    assert "images are 40x30 (" in str(info.value) and "is 80x60" in str(info.value)


def test_replay_option_errors():
    with pytest.raises(RigConfigError, match="speed"):
        create_rig_source("replay:///x?speed=fast")
    with pytest.raises(RigConfigError, match="speed"):
        create_rig_source("replay:///x?speed=-1")
    with pytest.raises(RigConfigError, match="directory"):
        create_rig_source("replay://")


@pytest.mark.parametrize("speed", ["1e-320", "0.0001"])
def test_a_speed_too_slow_to_time_is_refused_by_name(take, speed):
    """speed=1e-320 was taken, and read() then failed with an OverflowError (a due time of inf ns)."""
    out, _, _ = take
    with pytest.raises(RigConfigError) as info:
        create_rig_source(f"replay://{out}?speed={speed}")
    assert f"speed='{speed}'" in str(info.value) and ">= 0.001" in str(info.value)
    with open_rig(f"replay://{out}?speed=0.001", clock=ManualClock()) as source:  # the floor plays, 1000x slower
        assert source.read(timeout_s=600.0).sequence == 0


def test_camera_folder_names_are_safe_and_distinct():
    from drivers.backends.recording_format import camera_dir_name
    from drivers.sim import RigPlacement
    from ghnerf_runtime.geometry import Rig

    base = RigPlacement().build()
    a, b = base.pair
    rig = Rig((_renamed(a, "cam1"), _renamed(b, "cam 2")), base.volume)
    names = [camera_dir_name(rig, n) for n in rig.names]
    assert names == ["cam1", "_cam1"]  # "cam 2" is unsafe; its fallback cam1 is taken


def _renamed(camera, name):
    from dataclasses import replace

    return replace(camera, name=name)


# ----------------------------------------------------------------- a clock reset mid-take
BACK_NS = 10_000_000_000  # the clock reset: stamps from the middle of the take on are 10 s earlier


def _reset_the_clock_mid_take(take, live):
    """Send the stamps of every frame from the middle of the take on 10 s back (both cameras, as a device
    reset does), and shuffle the journal (writer threads swap its rows: its order is not the recorded one).
    Returns the stamp from which the clock was reset."""
    import random

    half = len(live) // 2
    reset_at = (max(live[half - 1].timestamps_ns) + min(live[half].timestamps_ns)) // 2
    rows = journal(take)
    for row in rows:
        if row["timestamp_ns"] >= reset_at:
            row["timestamp_ns"] -= BACK_NS
    random.Random(5).shuffle(rows)
    (take / FRAMES).write_text("".join(json.dumps(r) + "\n" for r in rows))
    return reset_at


def test_a_clock_reset_mid_take_plays_in_the_recorded_order_with_the_recorded_pairs(take, copy_of_take, caplog):
    """Replay sorted the rows by stamp: the frames after a clock reset played first, silently, and the pairs
    across it were lost. Each camera now plays in the order its files were numbered, the reset warned of."""
    _, live, _ = take
    reset_at = _reset_the_clock_mid_take(copy_of_take, live)
    with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"):
        replayed = replay_all(copy_of_take)  # keep_time=1: the recorded stamps up to the reset, re-based after
    assert len(replayed) == len(live)
    shifts = set()
    for a, b in zip(live, replayed):
        for fa, fb in zip(a.frames, b.frames):
            assert (fb.camera, fb.index, fb.scene_time_s) == (fa.camera, fa.index, fa.scene_time_s)
            assert np.array_equal(fa.image, fb.image)
            if fa.timestamp_ns < reset_at:
                assert fb.timestamp_ns == fa.timestamp_ns
            else:
                shifts.add(fb.timestamp_ns - (fa.timestamp_ns - BACK_NS))
    (shift,) = shifts  # one shift for both cameras: their relative timing kept
    rows = journal(copy_of_take)
    for cam in live[0].rig.names:
        first_after = min((r for r in rows if r["camera"] == cam and r["timestamp_ns"] < reset_at - BACK_NS / 2),
                          key=lambda r: r["image"])
        warned = [m for m in caplog.messages if f"camera {cam!r}" in m]
        assert len(warned) == 1 and "clock reset" in warned[0] and first_after["image"] in warned[0]
        assert f"played stamp - {shift} ns" in warned[0]


def test_after_a_clock_reset_the_replay_stamps_follow_on_at_the_recorded_pace(take, copy_of_take):
    """Re-stamped (the default), the frames after the reset follow those before one frame period on."""
    _, live, _ = take
    reset_at = _reset_the_clock_mid_take(copy_of_take, live)
    clock = ManualClock(7_000_000_000)
    with open_rig(f"replay://{copy_of_take}?policy=all", clock=clock) as source:
        replayed = [source.read(timeout_s=5.0) for _ in live]
        played_at = clock.now_ns()
    for cam in (0, 1):
        stamps = [p.frames[cam].timestamp_ns for p in replayed]
        assert all(b > a for a, b in zip(stamps, stamps[1:]))
    moved = {fb.timestamp_ns - fa.timestamp_ns
             for a, b in zip(live, replayed) for fa, fb in zip(a.frames, b.frames)}
    before = {fb.timestamp_ns - fa.timestamp_ns
              for a, b in zip(live, replayed) for fa, fb in zip(a.frames, b.frames) if fa.timestamp_ns < reset_at}
    assert len(before) == 1 and len(moved) == 2  # one shift before the reset, one after: the spacing kept
    (after,) = moved - before
    assert abs(after - before.pop()) < 34_000_000  # the unknown gap at the reset: about one frame period
    assert played_at == max(replayed[-1].timestamps_ns)  # paced: a stamp is the time its frame played


def test_a_reset_of_one_camera_keeps_it_beside_the_other():
    """Only one camera's stamps went back: its later frames continue where its own left off."""
    from drivers.backends.recording_format import FrameRow
    from drivers.backends.replay import playback_order

    ms = 1_000_000
    left = [FrameRow("left", i, t * ms, f"images/left/{i:08d}.png") for i, t in enumerate([0, 33, 66, 5, 38])]
    right = [FrameRow("right", i, t * ms, f"images/right/{i:08d}.png") for i, t in enumerate([1, 34, 67, 100, 133])]
    played = playback_order(right[::-1] + left[::-1])
    assert [(r.camera, r.index, r.timestamp_ns // ms) for r in played] == [
        ("left", 0, 0), ("right", 0, 1), ("left", 1, 33), ("right", 1, 34), ("left", 2, 66), ("right", 2, 67),
        ("left", 3, 99), ("right", 3, 100), ("left", 4, 132), ("right", 4, 133)]


@pytest.mark.parametrize("glitch_ms", [3_600_000, -3_600_000])
def test_one_bad_stamp_is_mended_not_taken_as_a_reset(glitch_ms):
    """One stamp an hour ahead or back, its neighbours in line: taken as a clock reset, every later frame of that
    camera was re-based by the hour, and no pair formed again. Played at its neighbours' midpoint instead."""
    from drivers.backends.recording_format import FrameRow
    from drivers.backends.replay import playback_order

    ms = 1_000_000
    left = [FrameRow("left", i, t * ms, f"images/left/{i:08d}.png")
            for i, t in enumerate([0, 33, 66 + glitch_ms, 100, 133])]
    right = [FrameRow("right", i, t * ms, f"images/right/{i:08d}.png") for i, t in enumerate([1, 34, 67, 101, 134])]
    played = playback_order(right[::-1] + left[::-1])
    assert [(r.camera, r.index, r.timestamp_ns // ms) for r in played] == [
        ("left", 0, 0), ("right", 0, 1), ("left", 1, 33), ("right", 1, 34), ("left", 2, 66), ("right", 2, 67),
        ("left", 3, 100), ("right", 3, 101), ("left", 4, 133), ("right", 4, 134)]


@pytest.mark.parametrize(("left_ms", "mended_ms"), [
    ([3_600_000, 33, 66, 100, 133], [0, 33, 66, 100, 133]),  # the first an hour ahead: a "reset" after it moved all
    ([0, 33, 66, 100, 3_600_133], [0, 33, 66, 100, 134]),  # the last an hour ahead: a paced replay waited the hour
    ([-3_600_000, 33, 66, 100, 133], [0, 33, 66, 100, 133]),  # the first an hour back: the same, after it
    ([0, 33, 66, 100, 133 - 3_600_000], [0, 33, 66, 100, 134]),  # the last an hour back: a "reset" at the end
], ids=["first-ahead", "last-ahead", "first-back", "last-back"])
def test_a_bad_first_or_last_stamp_is_mended_where_the_other_camera_says_so(left_ms, mended_ms, caplog):
    """A camera's first or last stamp far out of line with the next two, the other camera's stamps at that end in
    line with those two: a bad stamp, played one step from its neighbour (it was played as recorded)."""
    from drivers.backends.recording_format import FrameRow
    from drivers.backends.replay import playback_order

    ms, hour_ms = 1_000_000, 3_600_000
    left = [FrameRow("left", i, (t + hour_ms) * ms, f"images/left/{i:08d}.png") for i, t in enumerate(left_ms)]
    right = [FrameRow("right", i, (t + hour_ms) * ms, f"images/right/{i:08d}.png")
             for i, t in enumerate([1, 34, 67, 101, 134])]
    with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"):
        played = playback_order(right[::-1] + left[::-1], "take")
    expected = sorted([("right", i, r.timestamp_ns // ms - hour_ms) for i, r in enumerate(right)]
                      + [("left", i, t) for i, t in enumerate(mended_ms)], key=lambda row: (row[2], row[0] == "left"))
    assert [(r.camera, r.index, r.timestamp_ns // ms - hour_ms) for r in played] == expected
    (warned,) = [r.getMessage() for r in caplog.records]
    frame = 0 if left_ms[0] != 0 else 4
    assert "bad stamp" in warned and f"images/left/{frame:08d}.png" in warned and "take" in warned


def test_a_reset_after_one_camera_s_first_frame_stays_a_reset():
    """Left's clock went back after its first frame, right's did not: left's later frames follow its first, beside
    right's, as before; its first is not taken as the bad stamp (right's first is in line with it)."""
    from drivers.backends.recording_format import FrameRow
    from drivers.backends.replay import playback_order

    ms = 1_000_000
    left = [FrameRow("left", i, t * ms, f"images/left/{i:08d}.png") for i, t in enumerate([1000, 0, 33, 66])]
    right = [FrameRow("right", i, t * ms, f"images/right/{i:08d}.png")
             for i, t in enumerate([1001, 1034, 1067, 1100])]
    played = playback_order(right[::-1] + left[::-1])
    assert [(r.camera, r.index, r.timestamp_ns // ms) for r in played] == [
        ("left", 0, 1000), ("right", 0, 1001), ("left", 1, 1033), ("right", 1, 1034), ("left", 2, 1066),
        ("right", 2, 1067), ("left", 3, 1099), ("right", 3, 1100)]


def _played_ms(left_ms: list[int], right_ms: list[int], caplog) -> tuple[list[tuple[str, int, int]], list[str]]:
    """``playback_order`` of two cameras stamped ``left_ms`` and ``right_ms`` (journal shuffled): (camera, index,
    played stamp in ms) in playing order, and the warnings."""
    from drivers.backends.recording_format import FrameRow
    from drivers.backends.replay import playback_order

    ms = 1_000_000
    left = [FrameRow("left", i, t * ms, f"images/left/{i:08d}.png") for i, t in enumerate(left_ms)]
    right = [FrameRow("right", i, t * ms, f"images/right/{i:08d}.png") for i, t in enumerate(right_ms)]
    with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"):
        played = playback_order(right[::-1] + left[::-1], "take")
    return [(r.camera, r.index, r.timestamp_ns // ms) for r in played], [r.getMessage() for r in caplog.records]


_HOUR_MS = 3_600_000
_RIGHT_MS = [_HOUR_MS + t for t in (1, 34, 67, 101, 134, 167)]


@pytest.mark.parametrize("glitch_ms", [(_HOUR_MS, _HOUR_MS), (-_HOUR_MS, -_HOUR_MS), (_HOUR_MS, -_HOUR_MS),
                                       (-_HOUR_MS, _HOUR_MS)],
                         ids=["ahead", "back", "ahead-then-back", "back-then-ahead"])
def test_two_bad_stamps_in_a_row_are_mended_not_taken_as_a_reset(glitch_ms, caplog):
    """Two frames in a row stamped an hour off, the frames either side in line and the other camera's stamps going
    on between them: played as two resets (the first re-based every later frame of the camera by the hour, so none
    paired again), now spread between their neighbours, with one warning naming the first."""
    left_ms = [_HOUR_MS + t for t in (0, 33, 66 + glitch_ms[0], 100 + glitch_ms[1], 133, 166)]
    played, warned = _played_ms(left_ms, _RIGHT_MS, caplog)
    assert [(cam, i, t - _HOUR_MS) for cam, i, t in played] == [
        ("left", 0, 0), ("right", 0, 1), ("left", 1, 33), ("right", 1, 34), ("left", 2, 66), ("right", 2, 67),
        ("left", 3, 99), ("right", 3, 101), ("left", 4, 133), ("right", 4, 134), ("left", 5, 166), ("right", 5, 167)]
    (message,) = warned
    assert "bad stamp" in message and "images/left/00000002.png" in message and "(2 in this camera)" in message


@pytest.mark.parametrize("left_ms", [
    [0, 33, 66, 100, 5, 38],  # a reset two frames before the end: nothing after it to come back in line
    [0, 33, 66, 100, 5, 38, 71, 104],  # a reset that stays
    [0, 33, 66, 10_066, 10_100, 10_133],  # a pause: the stamps go on from it
    [0, 33, -500, -1_000, -967, -934],  # two resets in a row
    [0, 33, 66 + _HOUR_MS, 100 + _HOUR_MS, 133 + _HOUR_MS, 166],  # three frames off: more than MENDED_RUN
    # a reset back three frames: the frame after next lands just after the frame before the reset, its two
    # neighbours 1 ms apart (two frames spread in that ms until the fix)
    [0, 33, -34, 1, 34, 67, 100],
    # a reset back two frames (a frame and a half): the frame after it lands just after (within a period of) the
    # frame before the one before it, which was mended as one bad stamp until the session 72 review
    [0, 33, 66, 100, 67, 100, 133],
    [0, 33, 66, 100, 83, 116, 149],
], ids=["reset-2-before-the-end", "reset", "pause", "two-resets", "three-off", "reset-back-3-frames",
        "reset-back-2-frames", "reset-back-1.5-frames"])
def test_a_reset_or_a_pause_is_not_mended_as_bad_stamps(left_ms, caplog):
    """What only a real reset or pause does is played as before: no stamp mended, no "bad stamp" warning."""
    played, warned = _played_ms([_HOUR_MS + t for t in left_ms], _RIGHT_MS + [_HOUR_MS + 200, _HOUR_MS + 234],
                                caplog)
    assert not any("bad stamp" in message for message in warned), warned
    left_played = [t - _HOUR_MS for cam, _, t in played if cam == "left"]
    steps = [b - a for a, b in zip(left_ms, left_ms[1:])]
    if min(steps) > 0:  # no reset: played as recorded
        assert left_played == left_ms
    else:  # a reset: the frames after it follow on, spaced as recorded
        assert all(b > a for a, b in zip(left_played, left_played[1:]))
        assert any("clock reset" in message for message in warned)


@pytest.mark.parametrize(("glitch_ms", "first"), [
    ((_HOUR_MS, -_HOUR_MS), True), ((-_HOUR_MS, 5_000), True), ((_HOUR_MS, -_HOUR_MS), False),
    ((-7_000, _HOUR_MS), False),
], ids=["first-ahead-then-back", "first-back-then-ahead", "last-ahead-then-back", "last-back-then-ahead"])
def test_two_bad_stamps_at_a_camera_s_end_are_mended_where_the_other_camera_says_so(glitch_ms, first, caplog):
    """A camera's first (last) two stamps off, and off from each other, the other camera's stamps going on across
    their frames: they played as recorded (a reset after them moved every later frame by the glitch; at the last
    end a paced replay waited on it), or one of them was mended by the one-stamp end check, on its off neighbour.
    Now each is mended one step on from the frames beyond them."""
    left_ms = [0, 33, 66, 99, 132, 165]
    glitched = list(left_ms)
    for k, off in zip((0, 1) if first else (4, 5), glitch_ms):
        glitched[k] += off
    played, warned = _played_ms([_HOUR_MS + t for t in glitched], _RIGHT_MS, caplog)
    assert [t - _HOUR_MS for cam, _, t in played if cam == "left"] == left_ms
    frame = 0 if first else 4
    assert any("bad stamp" in message and f"images/left/{frame:08d}.png" in message for message in warned), warned


@pytest.mark.parametrize("left_ms", [[1_000, 1_033, 66, 99, 132, 165], [0, 33, 66, 99, 132, -900, -867]],
                         ids=["first", "last"])
def test_two_stamps_in_line_at_a_camera_s_end_are_not_mended(left_ms, caplog):
    """A camera's first (last) two stamps out of line with the rest but in line with each other: its clock alone
    set to the others' (or away from them) there, as far as the take shows: played as recorded, a reset."""
    played, warned = _played_ms([_HOUR_MS + t for t in left_ms], _RIGHT_MS + [_HOUR_MS + 200, _HOUR_MS + 234], caplog)
    assert not any("bad stamp" in message for message in warned), warned
    left = [t - _HOUR_MS for cam, _, t in played if cam == "left"]
    assert [b - a for a, b in zip(left, left[1:])][:1] + [b - a for a, b in zip(left, left[1:])][-1:] == [33, 33]


def test_a_reset_then_a_pause_on_both_cameras_is_not_mended_as_a_bad_stamp(caplog):
    """Both clocks went back 40 ms, then the take paused 60 ms: each camera's first frame after the reset lay out of
    line between neighbours 86 ms apart (its own camera alone reads a glitch) and was mended to their midpoint, its
    pair kept only by chance. The other camera jumped with it, at the same place: a reset, the pairs kept."""
    played, warned = _played_ms([0, 33, 66, 100, 93, 186, 219], [1, 34, 67, 101, 94, 187, 220], caplog)
    assert not any("bad stamp" in message for message in warned), warned
    assert sum("clock reset" in message for message in warned) == 2
    left = [t for cam, _, t in played if cam == "left"]
    right = [t for cam, _, t in played if cam == "right"]
    assert [b - a for a, b in zip(left[4:], left[5:])] == [93, 33]  # spaced as recorded after the reset
    assert [r - le for le, r in zip(left, right)] == [1] * 7


@pytest.mark.parametrize("right_ms", [[], [1, 34, 67, 101, 134, 167, 201, 234, 267]], ids=["alone", "beside"])
def test_a_reset_then_a_long_pause_on_one_camera_is_not_mended_as_a_bad_stamp(right_ms, caplog):
    """Left's clock went back 90 ms, then it paused 1.9 s (the other camera, where there is one, went on): its first
    frame after the reset lay out of line between neighbours in line, and was mended to their midpoint (1.05 s). A
    glitch leaves its neighbours a frame or two apart, not 57: a reset, the frames after it spaced as recorded."""
    played, warned = _played_ms([0, 33, 66, 100, 10, 2000, 2033], right_ms, caplog)
    assert not any("bad stamp" in message for message in warned), warned
    left = [t for cam, _, t in played if cam == "left"]
    assert left[:4] == [0, 33, 66, 100] and [b - a for a, b in zip(left[4:], left[5:])] == [1990, 33]


def test_a_reset_back_one_frame_on_both_cameras_plays_as_a_reset_with_its_pairs(caplog):
    """The host clock set back a frame (and 1 ms) mid-take: each camera's frame before the reset lay out of line
    between its neighbours, 33 ms apart, and was moved in there as a bad stamp (breaking its pair). Now a reset: the
    frames after it follow on one period later, every pair kept."""
    played, warned = _played_ms([0, 33, 66, 100, 99, 132, 165], [1, 34, 67, 101, 100, 133, 166], caplog)
    assert played == [("left", 0, 0), ("right", 0, 1), ("left", 1, 33), ("right", 1, 34), ("left", 2, 66),
                      ("right", 2, 67), ("left", 3, 100), ("right", 3, 101), ("left", 4, 134), ("right", 4, 135),
                      ("left", 5, 167), ("right", 5, 168), ("left", 6, 200), ("right", 6, 201)]
    assert not any("bad stamp" in message for message in warned), warned
    assert sum("clock reset" in message for message in warned) == 2


def test_a_reset_back_under_two_frames_does_not_get_the_last_stamp_mended(caplog):
    """Left's stamps 0.07, 35.3, 12.5, 47.2 ms (a reset back under two frames): 35.3 was mended to the midpoint of
    its neighbours (6.3), which made the last stamp a bad end, mended too: left played 0.07, 6.3, 12.5, 18.7.
    Now a reset: the frames after it follow on, spaced as recorded. (Right's last stamp, back under two frames
    too, is the end check's to judge: a reset too, see the test after next.)"""
    from drivers.backends.recording_format import FrameRow
    from drivers.backends.replay import playback_order

    us = 1_000
    left = [FrameRow("left", i, t * us, f"images/left/{i:08d}.png") for i, t in enumerate([70, 35_300, 12_500, 47_200])]
    right = [FrameRow("right", i, t * us, f"images/right/{i:08d}.png") for i, t in enumerate([100, 35_400, 12_600])]
    with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"):
        played = [r.timestamp_ns // us for r in playback_order(right[::-1] + left[::-1], "take") if r.camera == "left"]
    assert played[:2] == [70, 35_300] and played[3] - played[2] == 47_200 - 12_500
    assert played[2] - played[1] > 30_000  # the unknown gap at the reset: a frame period
    assert not any("bad stamp" in r.getMessage() and "'left'" in r.getMessage() for r in caplog.records)


def test_cameras_with_no_step_forward_lend_no_period_to_a_camera_of_a_few_frames(caplog):
    """A 10 fps camera of four frames with a reset after its first (1.6, -52.4, 46.9, 147.0 ms) beside two cameras of
    two frames each, reset after their first: theirs had no step forward, so their period read 1/30 s, which beat its
    own 100 ms; the reset was mended as a bad stamp, then its last stamp as a bad end (the session 72 review's fuzz,
    seed 2999). Now it plays as a reset, its frames after it spaced as recorded."""
    from drivers.backends.recording_format import FrameRow
    from drivers.backends.replay import playback_order

    us = 100_000  # tenths of a millisecond
    takes = {"cam0": [16, -524, 469, 1470], "cam1": [20, -520], "cam2": [25, -515]}
    rows = [FrameRow(cam, i, t * us, f"images/{cam}/{i:08d}.png") for cam, stamps in takes.items()
            for i, t in enumerate(stamps)]
    with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"):
        played = [r.timestamp_ns // us for r in playback_order(rows, "take") if r.camera == "cam0"]
    warned = [r.getMessage() for r in caplog.records]
    assert not any("bad stamp" in message for message in warned), warned
    assert played[2] - played[1] == 469 + 524 and played[3] - played[2] == 1470 - 469


@pytest.mark.parametrize(("left_us", "right_us", "pairs"), [
    ([70, 35_300, 12_500, 47_200], [100, 35_400, 12_600], [(2, 2)]),
    ([0, 33_000, 66_000, 100_000, 83_000, 116_000], [1_000, 34_000, 67_000, 101_000, 84_000], [(4, 4)]),
    ([12_500, 47_200, 70, 35_300], [47_300, 100, 35_400], [(1, 0), (2, 1)]),
], ids=["last-example", "last-back-1.5-frames", "first"])
def test_a_reset_on_both_cameras_at_one_s_end_is_not_mended_as_a_bad_end_stamp(left_us, right_us, pairs, caplog):
    """Both clocks went back at right's last frame (first), left having one more frame across the reset: left's end
    stamp lay nearer right's neighbour than right's, so the end check mended right's as a bad stamp (the fuzz of the
    session 72 review) and its pair broke. Right's lies within a period of left's across the reset: both reset."""
    from drivers.backends.recording_format import FrameRow
    from drivers.backends.replay import playback_order

    us = 1_000
    rows = [FrameRow(cam, i, t * us, f"images/{cam}/{i:08d}.png")
            for cam, stamps in (("right", right_us), ("left", left_us)) for i, t in enumerate(stamps)]
    with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"):
        played = {(r.camera, r.index): r.timestamp_ns // us for r in playback_order(rows[::-1], "take")}
    warned = [r.getMessage() for r in caplog.records]
    assert not any("bad stamp" in message for message in warned), warned
    assert sum("clock reset" in message for message in warned) == 2
    for left, right in pairs:  # the pairs across the reset kept, as recorded
        assert played["right", right] - played["left", left] == right_us[right] - left_us[left]


@pytest.mark.parametrize(("left_ms", "right_ms"), [
    ([0, 33, 66, 100, 133, 40], [1, 34, 67, 101, 134]),
    ([900, 0, 33, 66, 100, 133], [1, 34, 67, 101, 134, 167]),
], ids=["last", "first"])
def test_a_reset_at_one_camera_s_end_beyond_the_other_camera_s_frames_is_not_mended(left_ms, right_ms, caplog):
    """Left's clock went back at its last frame, after right's last (or forward at its first, before right's first):
    right's end stamp lay nearer left's neighbour, and the reset was mended as a bad end stamp. No other camera
    recorded at that frame's time, nothing tells a glitch there: played as recorded (a reset), not mended."""
    played, warned = _played_ms([_HOUR_MS + t for t in left_ms], [_HOUR_MS + t for t in right_ms], caplog)
    assert not any("bad stamp" in message for message in warned), warned
    assert any("clock reset" in message and "'left'" in message for message in warned), warned
    assert len(played) == len(left_ms) + len(right_ms)


@pytest.mark.parametrize("last", [True, False], ids=["last", "first"])
def test_a_pause_of_two_cameras_at_their_end_beside_a_third_that_stopped_is_not_mended(last, caplog):
    """Left's and right's clocks paused 2.25 s at their last frame (before their first), a third camera's take ended
    (began) before it: its end stamp lay nearer their neighbours, so each one's end was mended as a bad stamp, the
    pause gone. Right jumped with left there (and left with right): a pause, played as recorded (session 73 review)."""
    from drivers.backends.recording_format import FrameRow
    from drivers.backends.replay import playback_order

    ms, pause_ms = 1_000_000, 2_250
    stamps_ms = {"left": [2, 101, 200 + pause_ms], "right": [5, 104, 205 + pause_ms], "middle": [3, 102]}
    if not last:
        stamps_ms = {"left": [0, 100 + pause_ms, 200 + pause_ms], "right": [5, 105 + pause_ms, 205 + pause_ms],
                     "middle": [103 + pause_ms, 203 + pause_ms]}
    rows = [FrameRow(cam, i, (_HOUR_MS + t) * ms, f"images/{cam}/{i:08d}.png")
            for cam, ts in stamps_ms.items() for i, t in enumerate(ts)]
    with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"):
        played = playback_order(rows[::-1], "take")
    assert not any("bad stamp" in r.getMessage() for r in caplog.records), caplog.records
    assert sorted((r.camera, r.index, r.timestamp_ns // ms - _HOUR_MS) for r in played) == sorted(
        (cam, i, t) for cam, ts in stamps_ms.items() for i, t in enumerate(ts))


def test_a_bad_last_stamp_beside_a_camera_that_reset_is_still_mended(caplog):
    """Both clocks went back mid-take, then left's last stamp came an hour ahead: right's stamps across its reset lie
    nowhere near it, so it is a bad stamp, mended one step on from its neighbour."""
    left_ms = [_HOUR_MS + t for t in (0, 33, 66, 100, 20, 53, 86 + _HOUR_MS)]
    right_ms = [_HOUR_MS + t for t in (1, 34, 67, 101, 21, 54, 87, 120)]
    played, warned = _played_ms(left_ms, right_ms, caplog)
    left_played = [t for cam, _, t in played if cam == "left"]
    assert [b - a for a, b in zip(left_played[4:], left_played[5:])] == [33, 33]
    assert any("bad stamp" in message and "images/left/00000006.png" in message for message in warned), warned


def test_two_bad_stamps_in_a_camera_of_four_frames_are_mended(caplog):
    """Four frames, the middle two an hour on: the camera's own steps are one frame's and the hour's, no period to
    go by; the other camera's (the shorter) stands for it, and the run is mended."""
    played, warned = _played_ms([0, 33 + _HOUR_MS, 66 + _HOUR_MS, 100], [1, 34, 67, 101], caplog)
    assert [t for cam, _, t in played if cam == "left"] == [0, 33, 66, 100]
    assert "bad stamp" in warned[0] and "(2 in this camera)" in warned[0]


def test_a_slower_camera_s_reset_is_judged_by_its_own_frame_period(caplog):
    """The host clock set back 86 ms (1.3 of left's 66 ms frames): left's 200 ms frame lay out of line between
    frames 47 ms apart, over right's 33 ms period, and was mended by it as a bad stamp (the fuzz of the session 72
    review). Its own period says a reset: both cameras' frames after it follow on, spaced as recorded."""
    right_ms = [1, 34, 67, 101, 134, 167, 201] + [t - 86 for t in (234, 267, 301, 334, 367, 401)]
    played, warned = _played_ms([0, 66, 133, 200, 180, 246, 313], right_ms, caplog)
    assert not any("bad stamp" in message for message in warned), warned
    left_played = [t for cam, _, t in played if cam == "left"]
    assert left_played[:4] == [0, 66, 133, 200] and left_played[4] > 200
    assert [b - a for a, b in zip(left_played[4:], left_played[5:])] == [66, 67]


@pytest.mark.parametrize(("alone_ms", "mended_ms"), [
    ([0, 33, 66 + _HOUR_MS, 100, 133], [0, 33, 66, 100, 133]),  # a glitch: its neighbours two periods apart
    ([0, 100, 200, 300, 250, 350, 450], None),  # 10 fps, a reset back a frame and a half: 50 ms apart
], ids=["glitch", "slow-reset"])
def test_a_camera_alone_mends_a_lone_stamp_by_its_own_frame_period(alone_ms, mended_ms, caplog):
    """A camera alone in a take has no other camera's period: its own says whether its neighbours have room for
    a bad stamp between them (1/30 s, the period of no rows, took a 10 fps camera's reset for one)."""
    played, warned = _played_ms([_HOUR_MS + t for t in alone_ms], [], caplog)
    if mended_ms:
        assert [t - _HOUR_MS for _, _, t in played] == mended_ms and "bad stamp" in warned[0]
    else:
        assert not any("bad stamp" in message for message in warned), warned
        assert [t - _HOUR_MS for _, _, t in played] == [0, 100, 200, 300, 400, 500, 600]


def test_two_frames_off_on_both_cameras_at_once_are_not_mended(caplog):
    """Both cameras stamped two frames an hour on, then back: the other camera does not confirm the old timeline
    (its own stamps are on the run's), so neither is mended: as before, each camera's frames play as resets."""
    left_ms = [_HOUR_MS + t for t in (0, 33, 66 + _HOUR_MS, 100 + _HOUR_MS, 133, 166)]
    right_ms = [_HOUR_MS + t for t in (1, 34, 67 + _HOUR_MS, 101 + _HOUR_MS, 134, 167)]
    _, warned = _played_ms(left_ms, right_ms, caplog)
    assert not any("bad stamp" in message for message in warned), warned


@pytest.mark.parametrize("bad_frames", [1, 2])
def test_a_take_with_one_stamp_an_hour_ahead_replays_every_pair_at_its_pace(take, copy_of_take, caplog, bad_frames):
    """A live camera's one glitched stamp (an hour ahead) is recorded as delivered. Replayed, it was a clock reset:
    that camera's later frames moved an hour on, a paced replay waited the hour for them, and none paired. Two such
    frames in a row were still a reset until session 72."""
    _, live, _ = take
    rows = journal(copy_of_take)
    first_camera = live[0].frames[0].camera
    # in recorded order (the file numbers): the journal's, which writer threads swap, made two frames apart the run
    mine = sorted((r for r in rows if r["camera"] == first_camera), key=lambda r: r["image"])
    bad = mine[len(live) // 2]
    for row in mine[len(live) // 2:len(live) // 2 + bad_frames]:
        row["timestamp_ns"] += 3600 * 10**9
    (copy_of_take / FRAMES).write_text("".join(json.dumps(r) + "\n" for r in rows))
    clock = ManualClock(7_000_000_000)
    with caplog.at_level(logging.WARNING, logger="drivers.backends.replay"), \
            open_rig(f"replay://{copy_of_take}?policy=all", clock=clock) as source:
        replayed = list(source)
    assert len(replayed) == len(live)
    span = max(live[-1].timestamps_ns) - min(live[0].timestamps_ns)
    assert clock.now_ns() - 7_000_000_000 <= span  # paced at the recorded pace: no hour's wait
    warned = [r.getMessage() for r in caplog.records if "bad stamp" in r.getMessage()]
    assert len(warned) == 1 and bad["image"] in warned[0]


def test_a_recorded_stream_url_keeps_no_password_in_the_manifest(tmp_path, sim_cache):
    """record+opencv://?first=rtsp://user:pass@... wrote the password into manifest.json, in plain text."""
    from drivers.backends.record import RecordingRigSource
    from drivers.url import RigUrl

    stream = "rtsp%3A%2F%2Fadmin%3Ahunter2%40cam1%2Fstream%3Ftoken%3Dhunter2"
    url = RigUrl.parse(f"opencv://?first={stream}&second=0&out={tmp_path / 'take'}")
    inner_urls = []

    def factory(text, **kwargs):  # the URL the recorder opens, here played by the simulator
        inner_urls.append(text)
        return create_rig_source(f"{SIM}&cache={sim_cache}", clock=ManualClock())

    with RecordingRigSource.wrap(url, factory) as source:
        source.read(timeout_s=5.0)
    assert "hunter2" in inner_urls[0]  # the stream itself is opened with its credentials
    shown = read_manifest(tmp_path / "take").source
    assert "hunter2" not in shown and "rtsp%3A%2F%2Fadmin%3A***%40cam1" in shown and "token%3D***" in shown


def test_a_resized_take_whose_first_image_is_corrupt_counts_and_names_the_images_it_measured(copy_of_take):
    """The first image undecodable, the rest resized: the corrupt one is no size (left to its read), the others are
    counted and the first of them named."""
    images = sorted((copy_of_take / "images" / "right").iterdir())
    resize_images(copy_of_take, "right", (20, 15))
    images[0].write_bytes(b"not a png")
    with pytest.raises(FrameSizeError) as info:
        create_rig_source(f"replay://{copy_of_take}?speed=free").open()
    second = images[1].relative_to(copy_of_take).as_posix()
    assert f"{len(images) - 1} of its {len(images)} images are 20x15 ({second}, " in str(info.value)
    assert info.value.delivered == (20, 15)


def test_the_recording_doc_quotes_the_refusal_of_a_resized_take_as_open_words_it(copy_of_take):
    """docs/recording-format.md, "Image sizes", quotes the refusal for a made-up take (/data/take1, 900 images a
    camera, 320x240 for 640x480): with this take's path, count and sizes put in, it is the message open gives."""
    import re

    resize_images(copy_of_take, "right", (20, 15))
    source = create_rig_source(f"replay://{copy_of_take}?speed=free")
    with pytest.raises(FrameSizeError) as info:
        source.open()
    images = sorted(path.relative_to(copy_of_take).as_posix() for path in (copy_of_take / "images" / "right").iterdir())
    doc = re.sub(r"\s+", " ", (Path(__file__).resolve().parents[2] / "docs" / "recording-format.md").read_text())
    (quoted,) = re.findall(r"`(recording /data/take1: .*?)`", doc)
    for made_up, here in [("images/left/00000000.png, images/left/00000001.png, images/left/00000002.png",
                           ", ".join(images[:3])), ("/data/take1", str(copy_of_take)), ("'left'", "'right'"),
                          ("320x240", "20x15"), ("640x480", "40x30"),
                          ("900 of its 900", f"{len(images)} of its {len(images)}")]:
        assert made_up in quoted, made_up
        quoted = quoted.replace(made_up, here)
    assert quoted == str(info.value)


def test_a_recorded_tiff_whose_uncompressed_strip_is_short_is_a_corrupt_frame_naming_the_strip(tmp_path):
    """Session 66: OpenCV 5.0 delivered it with its last rows black (a frame of wrong pixels, no error); load_image
    refuses it from its header, naming the file and the strip."""
    path = tmp_path / "00000003.tiff"
    path.write_bytes(tiff_with_strip_count(1, 1, lambda count, size, offset: count - 1))
    with pytest.raises(RigOperationError) as info:
        load_image(path)
    assert str(info.value) == (f"recording image {path} is corrupt: its strip 2 holds 4223 of the 4224 bytes its "
                               f"pixels need (uncompressed): OpenCV would deliver the rest black")


def test_a_bad_last_stamp_back_among_the_stamps_of_an_earlier_reset_is_still_mended(caplog):
    """Both clocks went back mid-take; at the end left's last stamp came back 146 ms, among right's stamps after
    that reset, while right went on: right's reset lies mid-take, not at this end, so the stamp is a bad one, mended
    one step on (it was left as a reset of left's alone: its pair lost, a paced replay waiting on it)."""
    left_ms = [_HOUR_MS + t for t in (0, 33, 66, 100, 20, 53, 86, 120, 153, 186, 40)]
    right_ms = [_HOUR_MS + t for t in (1, 34, 67, 101, 21, 54, 87, 121, 154, 187, 220)]
    played, warned = _played_ms(left_ms, right_ms, caplog)
    left_played = [t for cam, _, t in played if cam == "left"]
    assert [b - a for a, b in zip(left_played[4:], left_played[5:])] == [33, 33, 34, 33, 33, 33]
    assert any("bad stamp" in message and "images/left/00000010.png" in message for message in warned), warned


def test_a_bad_first_stamp_among_the_stamps_before_a_later_reset_is_still_mended(caplog):
    """Left's first stamp came 47 ms late, among right's stamps before a reset that came later (both clocks back a
    second mid-take): that reset lies elsewhere, so the stamp is a bad one, mended one step before its neighbour."""
    left_ms = [_HOUR_MS + t for t in (80, 33, 66, 100, -900, -867, -834)]
    right_ms = [_HOUR_MS + t for t in (1, 34, 67, 101, -899, -866, -833)]
    played, warned = _played_ms(left_ms, right_ms, caplog)
    assert [t - _HOUR_MS for cam, _, t in played if cam == "left"][:4] == [0, 33, 66, 100]
    assert any("bad stamp" in message and "images/left/00000000.png" in message for message in warned), warned


def test_replay_names_a_recording_path_holding_a_control_character_escaped(tmp_path):
    """A decoded %1B reached the terminal raw ('recording directory /tmp/x<ESC>[31m/take does not exist')."""
    with pytest.raises(RigInitializationError) as e:
        create_rig_source(f"replay://{tmp_path}/x%1B[31m/take")
    assert "\x1b" not in str(e.value) and repr(f"{tmp_path}/x\x1b[31m/take") in str(e.value)
    odd = tmp_path / "y\x1b[31m"
    odd.mkdir()
    (odd / "manifest.json").write_text("[]")
    with pytest.raises(RigInitializationError, match="must be a JSON object") as e:
        read_manifest(odd)
    assert "\x1b" not in str(e.value) and repr(str(odd / "manifest.json")) in str(e.value)
    (odd / "0.png").write_bytes(b"not a png")
    (odd / "0.npz").write_bytes(b"not a zip")
    for read, path, what in ((load_image, odd / "0.png", "recording image"),
                             (load_truth, odd / "0.npz", "recording truth file")):
        with pytest.raises(RigOperationError) as e:
            read(path)
        assert "\x1b" not in str(e.value) and str(e.value).startswith(f"{what} {str(path)!r} is corrupt")


def test_replay_names_a_printable_recording_path_as_before(tmp_path):
    with pytest.raises(RigInitializationError, match=f"recording directory {tmp_path}/take does not exist"):
        create_rig_source(f"replay://{tmp_path}/take")


def test_record_names_an_out_directory_holding_a_control_character_escaped(tmp_path, sim_cache):
    odd = tmp_path / "z\x1b[31m"
    odd.mkdir()
    (odd / "other").write_text("")
    with pytest.raises(RigInitializationError, match="not empty") as e:
        open_rig(f"record+sim://?width=32&height=24&cache={sim_cache}&out={tmp_path}/z%1B[31m", clock=ManualClock())
    assert "\x1b" not in str(e.value) and f"recording directory {str(odd)!r} is not empty" in str(e.value)


def test_a_recorded_jpeg_cut_short_is_named_cut_short(tmp_path):
    """imdecode refused it already; the error said only 'corrupt (OpenCV cannot decode it)', where ghnerf-run's and
    ghcal's reads (image_files.unread_cause, the chain they share) now name the cut."""
    data = encode_image(np.random.default_rng(2).integers(0, 256, (24, 32, 3), dtype=np.uint8), "jpg", 90)
    path = tmp_path / "00000000.jpg"
    path.write_bytes(data[:len(data) // 3])
    said = f"recording image {path} is corrupt: it is a JPEG cut short"
    with pytest.raises(RigOperationError, match=re.escape(said)):
        load_image(path)


def test_a_lossless_read_waiting_for_a_queue_slot_ends_when_another_thread_closes(tmp_path, sim_cache, monkeypatch):
    """The writers stop at close: a lossless read waiting on a full queue could wait for good (and held the
    read's thread until the writers were free). It now raises as a read that a close lands in does."""
    import threading

    real, held = record_module.encode_image, threading.Event()

    def held_until_released(*args):
        held.wait(60)  # a slow disk: the writer sits on its frame, so the queue stays full
        return real(*args)

    monkeypatch.setattr(record_module, "encode_image", held_until_released)
    out = tmp_path / "take"
    url = f"record+sim://?width=32&height=24&cache={sim_cache}&out={out}&writers=1&write_queue=1&lossless=1"
    source = open_rig(url, clock=ManualClock())
    inner_read, handed, third_handed = source.inner._read_frame, [], threading.Event()

    def counting(timeout_s):
        frame = inner_read(timeout_s)
        if frame is not None:
            handed.append(frame)
            if len(handed) == 3:  # the writer holds the first, the queue the second: the third's submit waits
                third_handed.set()
        return frame

    monkeypatch.setattr(source.inner, "_read_frame", counting)
    ended, reader_done = [], threading.Event()

    def reader():
        try:
            while True:
                source.read(timeout_s=30.0)
        except Exception as e:  # noqa: BLE001 - the test looks at what it was
            ended.append(e)
        finally:
            reader_done.set()

    reading = threading.Thread(target=reader, daemon=True)
    closing = threading.Thread(target=source.close, daemon=True)  # waits for the held writer: not this test's point
    reading.start()
    try:
        assert third_handed.wait(30), "the reader never got its third frame"
        closing.start()
        ended_while_the_writer_was_held = reader_done.wait(30)
    finally:
        held.set()  # the old code's reader, and the close, go on once the writer is free: the suite does not hang
        if closing.ident is None:  # the reader never got there: close all the same
            closing.start()
        closing.join(30)
        reading.join(30)
    assert ended_while_the_writer_was_held, "the read still waited for a queue slot after the close"
    assert len(ended) == 1 and isinstance(ended[0], RigOperationError), ended
    assert "closed while a read waited" in str(ended[0]) and str(out) in str(ended[0])
    counters = read_manifest(out).counters
    assert read_manifest(out).complete and counters["frames_written"] == 2 and counters["writes_dropped"] == 0
    assert len(journal(out)) == 2  # the third frame, refused, is neither in the take nor counted


def test_a_frame_made_as_another_thread_closes_is_neither_handed_out_nor_queued(tmp_path, sim_cache, monkeypatch):
    # a read past its wait returned the frame of a source closed under it, and queued it for writers that had
    # stopped (never written, never counted)
    out = tmp_path / "take"
    source = open_rig(f"record+sim://?width=32&height=24&cache={sim_cache}&out={out}", clock=ManualClock())
    source.read(timeout_s=5.0)
    make = source.inner._read_frame

    def read_then_close(timeout_s):
        frame = make(timeout_s)
        source.close()  # as another thread's close would, once the inner source handed the frame
        return frame

    monkeypatch.setattr(source.inner, "_read_frame", read_then_close)
    frames_in = sum(source.stats.frames_in.values())
    with pytest.raises(RigOperationError) as raised:
        source.read(timeout_s=5.0)
    assert sum(source.stats.frames_in.values()) == frames_in  # not handed to the pairer
    assert source._writer._queue.empty()  # nor queued
    assert str(raised.value).startswith(f"record+ source closed while a read waited for its frame (recording to {out})")


@pytest.mark.parametrize("lossless", [False, True])
def test_a_submit_a_close_overtakes_is_refused_not_queued_behind_the_writers_stop(take, tmp_path, monkeypatch,
                                                                                 lossless):
    """A submit that looked before close began and queued its frame (it was copying the image) after the close
    had stopped the writers: the read handed the frame out, recorded by no one and counted nowhere
    (frames_written + writes_dropped fell one short of the frames handed out). It is refused now, as a read that a
    close lands in is."""
    from drivers.frames import Frame

    manifest = read_manifest(take[0])
    manifest.complete, manifest.counters = False, {}
    writer = record_module.RecordingWriter(tmp_path / "take", manifest, record_module.RecordOptions(
        out=tmp_path / "take", writers=1, lossless=lossless))
    writer.start()
    cam = manifest.rig.cameras[0]
    frames = [Frame(cam.name, np.zeros((cam.height, cam.width, 3), np.uint8), 1000 * i, i) for i in range(2)]
    writer.submit(frames[0])
    copying, closed, real_replace = threading.Event(), threading.Event(), record_module.replace

    def copied_once_the_close_is_done(*args, **kwargs):
        copying.set()
        assert closed.wait(30), "the close never came"
        return real_replace(*args, **kwargs)

    monkeypatch.setattr(record_module, "replace", copied_once_the_close_is_done)
    outcome: list = []

    def submit() -> None:
        try:
            writer.submit(frames[1])
            outcome.append("queued")
        except RigOperationError as e:
            outcome.append(e)

    submitting = threading.Thread(target=submit, daemon=True)
    submitting.start()
    try:
        assert copying.wait(30), "the submit never copied its frame"
        writer.close({})
    finally:
        closed.set()
        submitting.join(30)
    assert len(outcome) == 1 and isinstance(outcome[0], RigOperationError), outcome
    assert "closed while a read waited" in str(outcome[0])
    assert writer._queue.empty()  # nothing left behind the stop marks
    counters = read_manifest(tmp_path / "take").counters
    assert (counters["frames_written"], counters["writes_dropped"]) == (1, 0)


def test_a_close_from_another_thread_while_the_inner_sim_pre_renders_cancels_the_open(tmp_path):
    """record+sim: a close() while open() pre-rendered the inner loop did nothing (the base class closes only an open
    source, and the recorder did not pass it on): the loop rendered on, the take began, and the source came back
    open and closed, its inner source and writer threads never closed. The inner pre-render stops now, and the open
    raises, no take begun."""
    out = tmp_path / "take"
    source = create_rig_source(f"record+sim://?width=32&height=24&cache=off&workers=1&out={out}",
                               clock=ManualClock())
    rendering, closed, rendered = threading.Event(), threading.Event(), []
    render = source.inner._render

    def first_frame_held_until_the_close(camera, j, *, together=False):
        rendered.append((camera, j))
        rendering.set()
        assert closed.wait(30)
        return render(camera, j, together=together)

    source.inner._render = first_frame_held_until_the_close
    opener, failed = opened_in_a_thread(source)
    try:
        assert rendering.wait(30), "the open never rendered"
        source.close()
    finally:
        closed.set()
        opener.join(60)
    assert not opener.is_alive()
    assert len(failed) == 1 and isinstance(failed[0], RigInitializationError), failed
    assert "closed" in str(failed[0]), failed
    assert rendered == [(0, 0)], rendered  # the frame in progress, no other
    assert (source.is_open, source.inner.is_open, source.inner._loop, source._writer) == (False, False, None, None)
    assert not out.exists()  # no take begun


def test_a_close_as_the_inner_open_ends_begins_no_take_and_one_as_the_take_begins_closes_it(tmp_path, monkeypatch):
    """A close() landing once the inner source's open is done (nothing left there to cancel): the open raises
    before the take begins; one landing as the writer starts closes the take it began, its writer threads stopped."""
    out = tmp_path / "take"
    source = create_rig_source(f"record+sim://?width=32&height=24&cache=off&workers=1&out={out}",
                               clock=ManualClock())
    opened, closed = threading.Event(), threading.Event()
    inner_open = source.inner.open

    def opened_then_held_until_the_close():
        inner_open()
        opened.set()
        assert closed.wait(30)
        return source.inner

    monkeypatch.setattr(source.inner, "open", opened_then_held_until_the_close)
    opener, failed = opened_in_a_thread(source)
    try:
        assert opened.wait(60), "the inner source never opened"
        source.close()
    finally:
        closed.set()
        opener.join(60)
    assert len(failed) == 1 and isinstance(failed[0], RigInitializationError), failed
    assert str(failed[0]).startswith("record+ source closed while it opened (a close() from another thread)"), failed
    assert (source.is_open, source.inner.is_open, source._writer) == (False, False, None) and not out.exists()

    out = tmp_path / "take2"
    source = create_rig_source(f"record+sim://?width=32&height=24&cache=off&workers=1&out={out}",
                               clock=ManualClock())
    started, closed = threading.Event(), threading.Event()
    real_start = record_module.RecordingWriter.start

    def started_then_held_until_the_close(writer):
        real_start(writer)
        started.set()
        assert closed.wait(30)

    monkeypatch.setattr(record_module.RecordingWriter, "start", started_then_held_until_the_close)
    opener, failed = opened_in_a_thread(source)
    try:
        assert started.wait(60), "the take never began"
        source.close()
    finally:
        closed.set()
        opener.join(60)
    assert len(failed) == 1 and isinstance(failed[0], RigInitializationError), failed
    assert not source.is_open and not any(t.is_alive() for t in source._writer._threads)
    assert read_manifest(out).complete and read_manifest(out).counters["frames_written"] == 0
