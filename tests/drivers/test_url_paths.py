"""Relative file paths inside a rig URL written in a config file: read from the file's folder."""
from __future__ import annotations

import pytest

from drivers.registry import BACKENDS
from drivers.url import RigUrl
from drivers.url_paths import FILE_PARTS, rig_url_from_folder

#: A folder with every character that needs encoding in a URL path or query value.
ODD = "/srv/my cfg#1 %23+&=?x"


def test_every_backend_says_which_parts_of_its_url_are_files():
    # a new backend with a file option would otherwise read it from the daemon's current directory ('/')
    assert set(FILE_PARTS) == set(BACKENDS)


@pytest.mark.parametrize("url, target, options", [
    ("replay://takes/walk?loop=1", f"{ODD}/takes/walk", {"loop": "1"}),
    ("replay://take%2320/a%20b", f"{ODD}/take#20/a b", {}),  # the path's own %-escapes survive
    ("opencv://?first=take/left.mp4&second=0&rig=rigs/a+b.json&fps=30",
     "", {"first": f"{ODD}/take/left.mp4", "second": "0", "rig": f"{ODD}/rigs/a+b.json", "fps": "30"}),
    # an image sequence's %04d is a file; a stream URL and a GStreamer pipeline are not
    ("opencv://?first=seq/%2504d.png&second=rtsp%3A%2F%2Fcam%2Fs&rig=r.json",
     "", {"first": f"{ODD}/seq/%04d.png", "second": "rtsp://cam/s", "rig": f"{ODD}/r.json"}),
    ("opencv://?first=v4l2src%20!%20appsink&second=/dev/video2&rig=/etc/rig.json",
     "", {"first": "v4l2src ! appsink", "second": "/dev/video2", "rig": "/etc/rig.json"}),
    ("sim://?bvh=walk.bvh&cache=off&fps=30", "", {"bvh": f"{ODD}/walk.bvh", "cache": "off", "fps": "30"}),
    ("sim://?cache=cache", "", {"cache": f"{ODD}/cache"}),
    ("depthai://14442C10?rig=rig.json&fps=30", "14442C10", {"rig": f"{ODD}/rig.json", "fps": "30"}),
])
def test_relative_files_are_read_from_the_folder_and_survive_the_encoding(url, target, options):
    parsed = RigUrl.parse(rig_url_from_folder(url, ODD))
    assert (parsed.target, parsed.options) == (target, options)


@pytest.mark.parametrize("url", [
    "replay:///var/lib/ghnerf/take%231?loop=1",  # absolute: as written
    "sim://?fps=30&seed=0&motion=wave",  # no file in it
    "opencv://?first=/dev/video0&second=2&rig=/etc/ghnerf/rig.json",
    "record+sim://?out=takes/t1",  # refused by the daemon, with the URL as the user wrote it
    "foo://bar/baz",  # unknown scheme: the registry names it
    "replay://takes/walk#2",  # a fragment: RigUrl refuses it, naming it
    "no url",
])
def test_other_urls_are_kept_byte_for_byte(url):
    assert rig_url_from_folder(url, ODD) == url


def test_a_relative_path_with_a_byte_that_is_not_utf8_keeps_its_escape():
    """Made absolute it read back as U+FFFD (%EF%BF%BD), another name, which no check then refused."""
    assert rig_url_from_folder("replay://take%FF?loop=1", "/etc/g") == "replay:///etc/g/take%FF?loop=1"
    assert rig_url_from_folder("opencv://?first=a%FF.mp4&second=0", "/etc/g") == \
        "opencv://?first=/etc/g/a%FF.mp4&second=0"


def test_every_wrapper_says_which_of_its_options_are_files():
    # as for the backends: a wrapper's folder option left out would go unchecked (a NUL byte: a traceback)
    from drivers.wrappers import WRAPPER_FILE_OPTIONS, WRAPPERS

    assert set(WRAPPER_FILE_OPTIONS) == set(WRAPPERS)


def test_a_recorder_s_folder_is_checked_inside_another_wrapper(monkeypatch):
    """The check of a wrapped URL's files read ``record+`` off its start only: in ``spy+record+...`` neither the
    recorder's ``out=`` nor the inner backend's files were looked at, and a NUL byte in them reached the backend
    (a ValueError's traceback). Every wrapper of the registry's table is taken off now."""
    from drivers import wrappers
    from drivers.errors import RigConfigError
    from drivers.url_paths import check_url_paths

    monkeypatch.setitem(wrappers.WRAPPERS, "spy+", wrappers.WRAPPERS[wrappers.RECORD_PREFIX])
    with pytest.raises(RigConfigError, match="option out= 'a\\\\x00b'"):
        check_url_paths("spy+record+sim://?out=a%00b")
    with pytest.raises(RigConfigError, match="option bvh= 'w\\\\x00.bvh'"):
        check_url_paths("spy+record+sim://?out=take&bvh=w%00.bvh")
    check_url_paths("spy+record+sim://?out=take&bvh=walk.bvh")  # nothing wrong: nothing said
