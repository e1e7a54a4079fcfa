"""``sim://`` beyond timing: options, the pre-rendered loop and its disk cache, ground truth."""
import logging
import threading

import numpy as np
import pytest

from drivers import ManualClock, RigConfigError, RigInitializationError, create_rig_source, open_rig
from drivers.backends.sim_loop import default_cache_root
from drivers.sim import SAMPLE_BVH, SceneConfig, SensorModel, SimScene
from tests.drivers.contract import opened_in_a_thread
from tests.drivers.reopens import open_sources_sharing_a_logged_set
from tests.framing_note import logged_edge_notes, logged_framing_notes

SMALL = "width=48&height=36"


def test_options_reach_the_rig_placement():
    source = create_rig_source("sim://?baseline=0.5&mount_height=1.6&distance=2.5&width=64&height=48&cache=off")
    rig = source.rig
    assert rig.baseline == pytest.approx(0.5)
    for cam in rig.pair:
        assert cam.center[1] == pytest.approx(-1.6)  # y is down: 1.6 m above the floor
        assert (cam.width, cam.height) == (64, 48)
    source.close()


def test_freestyle_follows_the_url_seed():
    from drivers.backends.sim import SimOptions
    from drivers.url import RigUrl

    a, b = (SimOptions.from_url(RigUrl.parse(f"sim://?motion=freestyle&seed={s}&cache=off")).scene for s in (3, 4))
    assert (a.motion, a.motion_params.seed, b.motion_params.seed) == ("freestyle", 3, 4)
    assert not np.allclose(SimScene(a).joints_3d(1.0), SimScene(b).joints_3d(1.0))


@pytest.mark.parametrize(
    ("url", "names"),
    [
        ("sim://?motion=moonwalk", ["motion", "moonwalk"]),
        ("sim://?motion=wave&bvh=x.bvh", ["motion=", "bvh="]),
        ("sim://?bvh=/no/such/file.bvh", ["bvh", "/no/such/file.bvh"]),
        ("sim://?drop=1.5", ["drop"]),
        ("sim://?fps=0", ["fps"]),
        ("sim://?width=8", ["width"]),
        ("sim://?baseline=9", ["baseline"]),
        ("sim://?policy=newest", ["policy"]),
        ("sim://?unplug_after_s=-1", ["unplug_after_s"]),
        ("sim://?unplug_after_s=1e300", ["unplug_after_s"]),
        ("sim://fps=60&width=320", ["no target", "'fps=60&width=320'", "after '?'"]),
        ("sim://?motion=walk&max_loop_mb=100", ["max_loop_mb", "99 frames"]),
    ],
)
def test_bad_options_are_config_errors_naming_the_option(url, names):
    with pytest.raises(RigConfigError) as info:
        create_rig_source(url)
    for name in names:
        assert name in str(info.value)


def test_first_open_renders_second_loads_the_disk_cache(tmp_path):
    url = f"sim://?{SMALL}&seed=4&cache={tmp_path}"
    with open_rig(url, clock=ManualClock()) as first:
        assert first.fill_report.source == "rendered"
        a = [first.read(timeout_s=1.0) for _ in range(5)]
    assert len(list(tmp_path.iterdir())) == 1  # one entry, named by the key
    with open_rig(url, clock=ManualClock()) as second:
        assert second.fill_report.source == "disk"
        b = [second.read(timeout_s=1.0) for _ in range(5)]
    for pa, pb in zip(a, b):
        for fa, fb in zip(pa.frames, pb.frames):
            assert np.array_equal(fa.image, fb.image)
            assert np.array_equal(fa.truth.depth, fb.truth.depth)
            assert np.array_equal(fa.joints_3d, fb.joints_3d)


def test_cache_key_changes_with_what_changes_the_pixels():
    def key(options):
        return create_rig_source(f"sim://?{SMALL}&cache=off&{options}").cache_key()

    base = key("seed=1")
    assert key("seed=1") == base
    for other in ("seed=2", "seed=1&noise=3", "seed=1&offset_ms=5", "seed=1&fps=25", "seed=1&baseline=0.8",
                  "seed=1&motion=squat"):
        assert key(other) != base, other
    assert key("seed=1&jitter_ms=3&drop=0.2") == base  # timing only: same pixels


@pytest.mark.parametrize("module", ["ghnerf_runtime/geometry/raycast.py", "ghnerf_runtime/geometry/camera.py",
                                    "ghnerf_runtime/body25.py", "drivers/backends/sim.py", "drivers/sim/render.py"])
def test_cache_key_changes_with_the_code_that_renders_and_times_the_frames(module, monkeypatch):
    """The ray casting and the lens model live in ghnerf_runtime.geometry (drivers.sim re-exports them),
    the joint order in body25, and which instant a loop frame shows in this backend: a change to any of
    them must not be served the old pixels and truth from the disk cache."""
    from pathlib import Path

    source = create_rig_source(f"sim://?{SMALL}&seed=1&cache=off")
    base = source.cache_key()
    read_bytes = Path.read_bytes

    def edited(path):
        data = read_bytes(path)
        return data + b"\n# edited\n" if path.as_posix().endswith(module) else data

    monkeypatch.setattr(Path, "read_bytes", edited)
    assert source.cache_key() != base


def test_corrupt_cache_entry_is_rendered_again(tmp_path, caplog):
    url = f"sim://?{SMALL}&seed=6&cache={tmp_path}"
    open_rig(url, clock=ManualClock()).close()
    entry = next(tmp_path.iterdir())
    (entry / "image.npy").write_bytes(b"not numpy")
    with caplog.at_level(logging.WARNING):
        with open_rig(url, clock=ManualClock()) as source:
            assert source.fill_report.source == "rendered"
            source.read(timeout_s=1.0)
    assert "unusable" in caplog.text
    assert "not stored" not in caplog.text  # the bad entry made way for the new render
    assert [p.name for p in tmp_path.iterdir()] == [entry.name]  # nothing left aside
    with open_rig(url, clock=ManualClock()) as third:
        assert third.fill_report.source == "disk"  # repaired once, not rendered at every open


def _zero_filled(path, keep_header):
    """What a power cut can leave of a file written without fsync: its size, zeros where the data was."""
    data = path.read_bytes()
    kept = data[: data.index(b"\n") + 1] if keep_header else b""  # the .npy header ends in a newline
    path.write_bytes(kept + b"\0" * (len(data) - len(kept)))


@pytest.mark.parametrize("keep_header", [True, False])
def test_a_cache_entry_a_power_cut_left_full_of_zeros_is_rendered_again(tmp_path, caplog, keep_header):
    """Renamed into place without fsync, an entry could reach the disk before its data: a file of the right
    size full of zeros, its header whole, loaded as black frames. The checksum in meta.json catches it."""
    url = f"sim://?{SMALL}&seed=7&cache={tmp_path}"
    with open_rig(url, clock=ManualClock()) as first:
        expected = first.read(timeout_s=1.0).images[0]
    assert expected.any()
    entry = next(tmp_path.iterdir())
    _zero_filled(entry / "image.npy", keep_header)
    with caplog.at_level(logging.WARNING):
        with open_rig(url, clock=ManualClock()) as source:
            assert source.fill_report.source == "rendered"
            assert np.array_equal(source.read(timeout_s=1.0).images[0], expected)
    assert "unusable" in caplog.text and "image.npy" in caplog.text
    with open_rig(url, clock=ManualClock()) as third:
        assert third.fill_report.source == "disk"  # the entry stored again is whole


def test_a_cache_entry_is_on_disk_before_it_is_named(tmp_path, monkeypatch):
    """Each file and the entry's folder are fsynced before the rename that names the entry, the root after."""
    import os

    if not os.path.isdir("/proc/self/fd"):
        pytest.skip("needs /proc to name fsynced files")
    from drivers.backends import sim_loop

    events = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: (events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}"))),
                                                 real_fsync(fd))[1])
    monkeypatch.setattr(os, "replace", lambda a, b: (events.append(("replace", str(a))), real_replace(a, b))[1])
    open_rig(f"sim://?{SMALL}&seed=9&cache={tmp_path}", clock=ManualClock()).close()
    root = os.path.realpath(tmp_path)
    (renamed,) = [i for i, (kind, _) in enumerate(events) if kind == "replace"]
    tmp = os.path.realpath(events[renamed][1])
    before = {path for kind, path in events[:renamed] if kind == "fsync"}
    names = [f"{name}.npy" for name in sim_loop._CAMERA_FIELDS] + ["meta.json"]
    assert {os.path.join(tmp, name) for name in names} | {tmp} <= before
    assert ("fsync", root) in events[renamed + 1:]


def test_cache_off_writes_nothing_and_the_default_honours_xdg(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert default_cache_root() == tmp_path / "ghnerf-sim"
    with open_rig(f"sim://?{SMALL}&cache=off", clock=ManualClock()) as source:
        source.read(timeout_s=1.0)
    assert list(tmp_path.iterdir()) == []
    with open_rig(f"sim://?{SMALL}", clock=ManualClock()) as source:
        source.read(timeout_s=1.0)
    assert len(list((tmp_path / "ghnerf-sim").iterdir())) == 1


def test_frames_show_their_scene_time_with_matching_truth(sim_cache):
    """Pre-rendered frames equal a fresh render of the scene at the frame's scene_time_s."""
    with open_rig(f"sim://?{SMALL}&seed=3&noise=2&offset_ms=7&cache={sim_cache}", clock=ManualClock()) as source:
        pairs = [source.read(timeout_s=1.0) for _ in range(source.loop_frames + 3)]
        scene = SimScene(SceneConfig(seed=3, sensor=SensorModel(read_noise=2.0)))
        period, n = source.period_s, source.loop_frames
        for pair in (pairs[1], pairs[n + 1]):  # the same loop frame on two passes
            for cam, frame in zip(source.rig.pair, pair.frames):
                j = frame.index % n
                expected_t = (j * period / n + (0.007 if cam.name == "right" else 0.0)) % period
                assert frame.scene_time_s == pytest.approx(expected_t)
                image, truth = scene.render(cam, frame.scene_time_s)
                assert np.array_equal(frame.image, image)
                assert np.array_equal(frame.truth.joints_2d, truth.joints_2d)
                assert np.array_equal(frame.truth.mask, truth.mask)
                assert np.allclose(frame.joints_3d, scene.joints_3d(frame.scene_time_s))
        # the pair's 3D truth is the first camera's instant
        assert np.array_equal(pairs[1].joints_3d, pairs[1].frames[0].joints_3d)


def test_images_are_private_copies_truth_is_read_only(sim_cache):
    with open_rig(f"sim://?{SMALL}&cache={sim_cache}", clock=ManualClock()) as source:
        first = source.read(timeout_s=1.0)
        first.frames[0].image[:] = 0  # a consumer drawing on its frame...
        for _ in range(source.loop_frames - 1):
            source.read(timeout_s=1.0)
        again = source.read(timeout_s=1.0)  # ...does not change the loop
        assert again.frames[0].index % source.loop_frames == 0
        assert again.frames[0].image.any()
        with pytest.raises(ValueError):
            again.frames[0].truth.depth[0, 0] = 1.0


def test_bvh_motion_loops_over_the_clip(sim_cache):
    with open_rig(f"sim://?{SMALL}&bvh={SAMPLE_BVH}&fps=10&cache={sim_cache}", clock=ManualClock()) as source:
        assert source.loop_frames == max(1, round(source.period_s * 10))
        pair = source.read(timeout_s=1.0)
        assert pair.joints_3d.shape == (25, 3)


@pytest.mark.parametrize("distance", [1.0, 1.2, 1.5, 2.0, 5.0, 8.0])
def test_the_subject_stands_at_the_distance_inside_the_working_volume(distance):
    """distance= moved the cameras' aim and the working volume but not the person, who stayed at 3 m
    (outside the volume at 1.5 or 8); and 1 <= distance < 1.5 was refused with an error about
    RigPlacement.volume_depth_m, a field the URL does not have."""
    source = create_rig_source(f"sim://?distance={distance}&width=64&height=48&cache=off")
    hips = source._scene.joints_3d(0.0)[8]  # MidHip
    assert (hips[0], hips[2]) == pytest.approx((0.0, distance))
    volume = source.rig.volume
    assert volume.contains(hips)
    assert volume.min_corner[2] >= 0.5 - 1e-9 and volume.max_corner[2] - volume.min_corner[2] <= 2.0 + 1e-9
    for cam in source.rig.pair:  # both cameras see the hips
        uv, depth = cam.project(hips)
        assert depth > 0 and 0 <= uv[0] < 64 and 0 <= uv[1] < 48
    source.close()


def test_a_placement_whose_cameras_miss_the_subject_is_refused_by_name():
    """convergence=120 turned each camera 60 degrees away from the subject: the left camera saw none
    of the 25 joints, and the rig filmed an empty room without a word."""
    with pytest.raises(RigConfigError) as info:
        create_rig_source("sim://?convergence=120&width=64&height=48&cache=off")
    for words in ("camera 'left'", "does not see the subject", "convergence=120", "distance=3", "baseline=1.2"):
        assert words in str(info.value)
    create_rig_source("sim://?convergence=60&width=64&height=48&cache=off").close()  # still in view: accepted


@pytest.mark.parametrize(("query", "fps"), [("fps=1", 1.0), ("fps=2", 2.0), ("fps=0.5", 0.5), ("fps=0.3&motion=walk", 0.3)])
def test_a_low_rate_loop_shows_the_instants_a_real_camera_would(query, fps):
    """At fps=1 the 1.2 s wave loop had one frame: every frame showed scene time 0, a frozen person.
    Loop frame k must show k / fps into the motion (modulo its period), off by at most 1 % of a period
    per frame (the loop then starts over, like any loop stretched to whole frames)."""
    source = create_rig_source(f"sim://?{query}&width=16&height=16&cache=off")
    period = source.period_s
    for k in range(max(source.loop_frames, 3)):  # at least three frames: a one-frame loop froze the person
        off = (source.scene_time(0, k % source.loop_frames) - k / fps) % period
        assert min(off, period - off) <= 0.01 * period * k + 1e-9, k
    source.close()


def test_a_slow_rig_delivers_a_moving_subject(sim_cache):
    with open_rig(f"sim://?fps=1&{SMALL}&cache={sim_cache}", clock=ManualClock()) as source:
        pairs = [source.read(timeout_s=2.0) for _ in range(6)]
    assert [p.frames[0].index for p in pairs] == list(range(6))
    assert [p.frames[0].scene_time_s for p in pairs] == pytest.approx([0.0, 1.0, 0.8, 0.6, 0.4, 0.2])  # k s into 1.2 s
    wrist = np.array([p.joints_3d[4] for p in pairs])  # RWrist: the waving hand moves
    assert np.ptp(wrist, axis=0).max() > 0.1


def test_loops_at_the_usual_rates_are_one_motion_period():
    for fps, frames in ((30, 36), (10, 12), (5, 6)):
        source = create_rig_source(f"sim://?fps={fps}&{SMALL}&cache=off")
        assert (source.loop_periods, source.loop_frames) == (1, frames)
        source.close()


@pytest.mark.parametrize("under", ["", "sub"])
def test_a_cache_that_is_a_file_is_a_config_error_naming_the_option(tmp_path, under):
    """A file named as the cache folder was a warning ('not stored') and every open rendered the loop again."""
    (tmp_path / "afile").write_text("")
    cache = tmp_path / "afile" / under if under else tmp_path / "afile"
    with pytest.raises(RigConfigError) as info:
        create_rig_source(f"sim://?{SMALL}&cache={cache}")
    said = str(info.value)
    assert f"option cache={str(cache)!r}" in said and "cache=off" in said
    assert ("is a file" if not under else f"is under {str(tmp_path / 'afile')!r}, a file") in said


def test_a_cache_folder_not_made_yet_is_taken(tmp_path):
    from drivers.backends.sim import SimOptions
    from drivers.url import RigUrl

    options = SimOptions.from_url(RigUrl.parse(f"sim://?{SMALL}&cache={tmp_path / 'new' / 'cache'}"))
    assert options.cache_root == tmp_path / "new" / "cache"


def test_a_rig_built_from_the_url_is_warned_of_at_open_as_a_rig_file_would_be(caplog):
    """``sim://?baseline=0.05`` puts the pair's rays 0.95 degrees apart at the subject: ``load_rig`` warns of such a
    rig file, and since session 65's second review the rig a backend builds in memory gets the same check, once, at
    open (drivers.base.RigSource.open); the default placement gets no word."""
    for url, warned in ((f"sim://?{SMALL}&cache=off&baseline=0.05", 1), (f"sim://?{SMALL}&cache=off", 0)):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="drivers.base"):
            source = create_rig_source(url, clock=ManualClock())
            assert not caplog.records  # at open, not when the URL is parsed
            with source.open():
                source.open()  # opening again: no second word
        narrow = [r.getMessage() for r in caplog.records if "MIN_PAIR_ANGLE_DEG" in r.getMessage()]
        assert len(narrow) == warned and len(caplog.records) == warned, caplog.text
        assert all(m.startswith("sim:// rig 'sim': cameras ") and "50 mm apart" in m for m in narrow), narrow


def test_a_rig_built_from_the_url_that_cuts_the_person_is_noted_at_info_once_over_shared_opens(caplog):
    """``sim://?distance=1`` shows 89 % of a standing person's height (``rig_file.rig_notes``): the rig a backend
    builds gets the note ``load_rig`` gives a rig file, at INFO and not as a warning, once over a daemon's reopens
    sharing a logged set (session 67); its volume's near edge, 0.5 m ahead (57 %), has a note of its own since
    session 69, once too."""
    url = f"sim://?{SMALL}&cache=off&distance=1"
    with caplog.at_level(logging.INFO, logger="drivers"):
        logged = open_sources_sharing_a_logged_set(lambda _: create_rig_source(url, clock=ManualClock()), 3)
    noted = logged_framing_notes(caplog.records)
    edge = logged_edge_notes(caplog.records)
    assert [r.levelname for r in noted + edge] == ["INFO", "INFO"] and len(logged) == 2, caplog.text
    assert noted[0].getMessage().startswith("sim:// rig 'sim': a 1.8 m person standing at the working volume's "
                                            "centre (x 0.00, z 1.00 m) is partly out of view: camera 'left' shows 89%")
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING], caplog.text


@pytest.mark.parametrize("prefix", ["", "record+"])
def test_sources_sharing_a_logged_set_warn_of_their_rig_once(caplog, tmp_path, prefix):
    """A daemon reopens its rig after each lost camera, through a new source each time: sources handed the same
    ``log_rig_warnings_once`` set warn once over all the opens (each open logged the narrow pair again, session 65's
    follow-up); a source without one, a one-shot tool's, still warns at its open. The recorder passes the set to the
    source it wraps, which builds the rig."""
    url = f"{prefix}sim://?{SMALL}&cache=off&baseline=0.05"
    with caplog.at_level(logging.WARNING, logger="drivers"):
        logged = open_sources_sharing_a_logged_set(lambda k: create_rig_source(
            url, clock=ManualClock(), **({"out": tmp_path / f"take{k}"} if prefix else {})), 3)
        shared = [r for r in caplog.records if "MIN_PAIR_ANGLE_DEG" in r.getMessage()]
        caplog.clear()
        with create_rig_source(url, clock=ManualClock(), **({"out": tmp_path / "one"} if prefix else {})).open():
            pass
        alone = [r for r in caplog.records if "MIN_PAIR_ANGLE_DEG" in r.getMessage()]
    assert len(shared) == 1 and len(logged) == 1, [r.getMessage() for r in shared]
    assert len(alone) == 1, caplog.text


@pytest.mark.parametrize("second", ["", "&second=1.0,3.4&second_after_s=1"])
def test_a_close_from_another_thread_cancels_the_pre_render_of_open(second):
    """A close() while open() pre-rendered the loop did nothing (the base class closes only an open source): the
    open rendered the whole loop on, then returned a closed source holding it. It stops at its next frame now, and
    raises, keeping no loop."""
    source = create_rig_source(f"sim://?{SMALL}&cache=off&workers=1{second}", clock=ManualClock())
    rendering, closed = threading.Event(), threading.Event()
    rendered = []
    render = source._render

    def first_frame_held_until_the_close(camera, j, *, together=False):
        rendered.append((camera, j))
        rendering.set()
        assert closed.wait(30)
        return render(camera, j, together=together)

    source._render = first_frame_held_until_the_close
    opener, failed = opened_in_a_thread(source)
    assert rendering.wait(30)
    source.close()
    closed.set()
    opener.join(timeout=60)
    assert not opener.is_alive()
    assert len(failed) == 1 and isinstance(failed[0], RigInitializationError), failed
    assert "closed" in str(failed[0]) and "pre-render" in str(failed[0]), failed
    assert rendered == [(0, 0)], rendered  # the frame in progress, no other
    assert (source._loop, source._loop_alone, source.is_open) == (None, None, False)
