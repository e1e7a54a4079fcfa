"""Edges of the sources a reviewer found: a pairing tolerance too large to count in nanoseconds, a close that
fails, a journal row of a camera outside the pair, a rig file of another size than a depthai stream, an
unreadable rig file (named alike by opencv:// and depthai://), a close from another thread while a sim (or
replay) read waits, a read timeout too long to count in nanoseconds, a recorder that cannot start."""
from __future__ import annotations

import json
import shutil

import pytest

from drivers import (
    ManualClock,
    PairingConfig,
    RigConfigError,
    RigDisconnectedError,
    RigInitializationError,
    RigOperationError,
    create_rig_source,
    open_rig,
)
from drivers.backends.recording_format import FRAMES, MANIFEST
from tests.drivers.contract import closed_while_reading
from tests.drivers.depthai_host import ScriptedLink


@pytest.fixture(scope="module")
def take(tmp_path_factory, sim_cache):
    out = tmp_path_factory.mktemp("edges") / "take"
    with open_rig(f"record+sim://?width=40&height=30&policy=all&seed=3&cache={sim_cache}&out={out}",
                  clock=ManualClock()) as source:
        for _ in range(6):
            source.read(timeout_s=5.0)
    return out


def test_a_tolerance_too_large_is_refused_by_name(take):
    # int(1e303 ms in ns) overflowed to a bare OverflowError, which took the daemon down
    with pytest.raises(RigConfigError, match=r"tolerance_ms.*1e\+?303"):
        create_rig_source(f"replay://{take}?tolerance_ms=1e303")
    with pytest.raises(RigConfigError, match=r"tolerance_ms must be a number in \(0, 10000\]"):
        PairingConfig(tolerance_ms=1e303)
    assert PairingConfig(tolerance_ms=10_000.0).tolerance_ms == 10_000.0


def test_a_row_of_a_camera_outside_the_pair_is_refused_at_open(take, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(take, copy)
    manifest = json.loads((copy / MANIFEST).read_text())
    extra = dict(manifest["rig"]["cameras"][0], name="extra")
    manifest["rig"]["cameras"].append(extra)  # a rig may list more cameras than the pair it records
    (copy / MANIFEST).write_text(json.dumps(manifest))
    lines = (copy / FRAMES).read_text().splitlines()
    row = json.loads(lines[3])
    row["camera"] = "extra"
    lines[3] = json.dumps(row)
    (copy / FRAMES).write_text("\n".join(lines) + "\n")
    with pytest.raises(RigInitializationError, match=r"frames\.jsonl, field 'camera': line 4: 'extra' is not a "
                                                     r"camera of the rig's pair"):
        create_rig_source(f"replay://{copy}")


class _FailingClose(ScriptedLink):
    def close(self) -> None:
        super().close()
        raise RuntimeError("X_LINK_ERROR while stopping")


def test_a_close_that_fails_still_closes_and_the_block_keeps_its_own_error():
    links: list[ScriptedLink] = []

    def factory():
        links.append(_FailingClose([(k, k) for k in range(3)], stops=True))
        return links[-1]

    source = create_rig_source("depthai://", link_factory=factory)
    with pytest.raises(RigDisconnectedError):  # was the close's RigOperationError
        with source:
            while True:
                source.read(timeout_s=0.5)
    assert not source.is_open
    with pytest.raises(RigOperationError):
        source.open()  # closed stays closed: no second device link
    assert len(links) == 1


def test_a_rig_file_of_another_size_names_the_url_and_the_file():
    url = "depthai://?rig=docs/examples/rig.json"
    with pytest.raises(RigConfigError, match=r"rig URL 'depthai://\?rig=docs/examples/rig\.json': option "
                                             r"rig=docs/examples/rig\.json: rig .* is \d+x\d+ but the stream is"):
        create_rig_source(url)


@pytest.mark.parametrize("scheme_and_cameras", ["opencv://?first=0&second=1&", "depthai://?"])
def test_an_unreadable_rig_file_names_the_url_and_the_option_alike_in_each_backend(tmp_path, scheme_and_cameras):
    # both backends read rig= through drivers.base.load_rig_option: one wording, the file's error kept as the cause
    from ghnerf_runtime.errors import RigFileError

    (tmp_path / "rig.json").write_text("not json")
    url = f"{scheme_and_cameras}rig={tmp_path / 'rig.json'}"
    with pytest.raises(RigConfigError) as raised:
        create_rig_source(url)
    assert str(raised.value).startswith(f"rig URL {url!r}: option rig={tmp_path / 'rig.json'}: file ")
    assert isinstance(raised.value.__cause__, RigFileError)


def test_naming_the_rig_option_converts_rig_errors_only():
    from drivers.base import naming_rig_option
    from drivers.url import RigUrl
    from ghnerf_runtime.errors import RigFileError

    url = RigUrl.parse("depthai://?rig=r.json")
    with pytest.raises(RigConfigError, match=r"^rig URL 'depthai://\?rig=r\.json': option rig=r\.json: too small$"):
        with naming_rig_option(url, "r.json"):
            raise RigConfigError("too small")
    with pytest.raises(RigConfigError, match=r"option rig=r\.json: file r\.json: gone"):
        with naming_rig_option(url, "r.json"):
            raise RigFileError("gone", path="r.json")
    with pytest.raises(KeyError):  # not a rig error: left as it is
        with naming_rig_option(url, "r.json"):
            raise KeyError("other")


# A read waits for the next frame's time (30 s timeout; the next frame 10 s or more away) or for its timeout (5 s),
# both seconds after the close; it slept until then (sim://, and replay:// which then returned the frame) before
# session 75. So 2 s, room for a loaded host, still tells the two apart.
@pytest.mark.parametrize("read_timeout_s", [30.0, 5.0])
@pytest.mark.parametrize("url", ["sim://?width=40&height=30&fps=0.1&cache={cache}",
                                 "record+sim://?width=40&height=30&fps=0.1&cache={cache}&out={out}",
                                 "replay://{take}?speed=0.002"])
def test_a_sim_read_waiting_when_another_thread_closes_says_so(sim_cache, take, tmp_path, url, read_timeout_s):
    source = open_rig(url.format(cache=sim_cache, out=tmp_path / "out", take=take))
    source.read(timeout_s=5.0)
    got, after_s = closed_while_reading(source, read_timeout_s)
    assert isinstance(got, RigOperationError) and "closed while a read waited" in str(got), got
    assert after_s < 2.0, f"the read returned {after_s:.2f} s after the close"


@pytest.mark.parametrize("timeout_s", [1e300, float("inf")])
def test_a_read_timeout_too_long_to_count_in_nanoseconds_is_refused_by_name(take, timeout_s):
    """read(timeout_s=1e300) passed the finite-number check, then int(1e300 * 1e9) raised a bare OverflowError."""
    with open_rig(f"replay://{take}?speed=recorded", clock=ManualClock()) as source:
        with pytest.raises(ValueError, match=r"read\(timeout_s="):
            source.read(timeout_s=timeout_s)
        assert source.read(timeout_s=1e12).sequence == 0  # long, yet countable: still a wait


def _full_disk_at_the_manifest(monkeypatch):
    from drivers.backends import recording_format
    from ghnerf_runtime.errors import RigFileError

    def no_space(path, text):
        raise RigFileError("No space left on device", path=str(path))

    monkeypatch.setattr(recording_format, "write_text_atomic", no_space)


@pytest.mark.parametrize("exists", [False, True])
def test_a_recording_that_cannot_start_leaves_its_folder_as_it_found_it(tmp_path, sim_cache, monkeypatch, exists):
    """A full disk at the manifest left frames.jsonl and the camera folders behind: no take, but a folder
    "not empty", so the retry after freeing space was refused; and the error was a RigOperationError."""
    out = tmp_path / "takes" / "take1"
    if exists:
        out.mkdir(parents=True)
    url = f"record+sim://?width=40&height=30&seed=3&cache={sim_cache}&out={out}"
    with monkeypatch.context() as patch:
        _full_disk_at_the_manifest(patch)
        with pytest.raises(RigInitializationError, match=f"cannot start recording in {out}.*No space left"):
            open_rig(url, clock=ManualClock())
    if exists:
        assert out.is_dir() and not any(out.iterdir())  # the folder given stays, empty
    else:
        assert not (tmp_path / "takes").exists()  # the folders the start made are gone
    with open_rig(url, clock=ManualClock()) as source:  # space freed: the same out= records
        source.read(timeout_s=5.0)
    assert (out / MANIFEST).is_file()


def test_a_read_or_an_iteration_after_close_says_the_source_was_closed(sim_cache):
    # it said "is not open; call open() or use open_rig()", and that open() refuses a closed source
    source = open_rig(f"sim://?width=64&height=48&cache={sim_cache}", clock=ManualClock())
    source.read(timeout_s=1.0)
    source.close()
    source.close()  # twice: nothing more to do
    for use in (lambda: source.read(timeout_s=0.1), lambda: next(iter(source)), source.open):
        with pytest.raises(RigOperationError, match=r"SimRigSource was closed; open a new source"):
            use()


class _ClosingClock(ManualClock):
    """A ManualClock that closes ``source`` at its first reading after a wait: a close from another thread landing
    just after a read's wait ended, before the frame is made (a race, here at a fixed point)."""

    source = None

    def __init__(self) -> None:
        super().__init__()
        self._armed = False

    def wait_until(self, deadline_ns, wake) -> bool:
        woken = super().wait_until(deadline_ns, wake)
        self._armed = not woken and self.source is not None
        return woken

    def now_ns(self) -> int:
        if self._armed:
            self._armed = False
            self.source.close()
        return super().now_ns()


def test_a_sim_close_landing_just_after_a_reads_wait_says_closed(sim_cache):
    # the read went on to make the frame from the loop the close had dropped: an AssertionError, not a DriverError
    clock = _ClosingClock()
    source = open_rig(f"sim://?width=40&height=30&cache={sim_cache}", clock=clock)
    source.read(timeout_s=1.0)
    clock.source = source
    with pytest.raises(RigOperationError, match="sim source closed while a read waited for its frame"):
        source.read(timeout_s=1.0)


def test_a_sim_close_between_a_pairs_two_frames_says_closed(sim_cache, monkeypatch):
    # the read's next frame found the source closed and said "sim rig is not open", of a source it had found open
    source = open_rig(f"sim://?width=40&height=30&cache={sim_cache}", clock=ManualClock())
    source.read(timeout_s=1.0)
    make = source._frame

    def make_then_close(capture):
        frame = make(capture)
        source.close()  # as another thread's close would, once the pair's first frame is made
        return frame

    monkeypatch.setattr(source, "_frame", make_then_close)
    with pytest.raises(RigOperationError, match="sim source closed while a read waited for its frame"):
        source.read(timeout_s=1.0)


@pytest.mark.parametrize("url, makes", [("sim://?width=40&height=30&cache={cache}", "_frame"),
                                        ("replay://{take}?speed=recorded", "_load")])
def test_a_frame_made_as_another_thread_closes_is_not_handed_out(sim_cache, take, monkeypatch, url, makes):
    # a read past its wait handed the pairer the frame it made while the close landed (a pair of a closed source)
    source = open_rig(url.format(cache=sim_cache, take=take), clock=ManualClock())
    source.read(timeout_s=1.0)
    make = getattr(source, makes)

    def make_then_close(*args):
        frame = make(*args)
        source.close()  # as another thread's close would, while the frame is made
        return frame

    monkeypatch.setattr(source, makes, make_then_close)
    frames_in = sum(source.stats.frames_in.values())
    with pytest.raises(RigOperationError, match="closed while a read waited for its frame"):
        source.read(timeout_s=1.0)
    assert sum(source.stats.frames_in.values()) == frames_in
