"""Paths no file can have, given to each console script, in the daemon's config file and inside rig and sink URLs,
end in one usage line naming the option or key and the value (``repr`` for odd bytes), exit status 2.

Before session 63's review: a NUL byte in ``health.status_file`` raised ``ValueError: embedded null byte`` from
``os.path.realpath`` (a traceback, for ``--validate-config`` and the start alike); a name past 255 bytes in a
``replay://`` or ``sim://?cache=`` URL raised ``ENAMETOOLONG``; a path that is not UTF-8 (``sys.argv`` keeps such
bytes as surrogates) crashed OpenCV with a segmentation fault; a ``~`` in a config file was read as a folder named
``~`` beside it; and an output folder through a file or a link to nothing was OSError's bare "File exists".
"""
from __future__ import annotations

import importlib
import json
import os
from pathlib import Path

import pytest

from ghnerf_runtime.path_check import path_problem, shown

ROOT = Path(__file__).resolve().parents[1]

NUL = "a\x00b"
NOT_UTF8 = os.fsdecode(b"take-\xff\xfe.png")  # as sys.argv holds a Latin-1 file name on a UTF-8 system
LONG_NAME = "x" * 300
LONG_PATH = "/tmp/" + "/".join(["y" * 200] * 25)
TILDE = "~/ghnerf/x"

#: (kind, value, what the message says): each odd value the checks refuse.
ODD = [
    ("nul", NUL, "holds a NUL byte"),
    ("not_utf8", NOT_UTF8, "is not UTF-8"),
    ("long_name", LONG_NAME, "a file or folder name has at most 255"),
    ("long_path", LONG_PATH, "a path has at most 4095"),
    ("tilde", TILDE, "which is not expanded here"),
]


@pytest.mark.parametrize("kind, value, said", ODD, ids=[k for k, _, _ in ODD])
def test_path_problem_names_each_kind(kind, value, said):
    assert said in path_problem(value)


def test_ordinary_paths_pass():
    for value in ("models", "/etc/ghnerf/daemon.json", "./~", "a~b", "café/rig.json", "x" * 255, "-",
                  "my takes/take 1.json", "~take", "../rig.json"):
        assert path_problem(value) is None


def test_a_user_s_home_folder_is_refused_as_the_own_one_is():
    """``~root/models`` (``~pi/models`` on a Raspberry Pi) names a user's home folder to a shell; unexpanded, it was
    read as a folder called ``~root`` beside the config file. A ``~name`` of no user stays a name."""
    import pwd

    user = pwd.getpwuid(0).pw_name
    assert "which is not expanded here" in path_problem(f"~{user}/models")
    assert path_problem("~no-such-user-here/models") is None


def test_a_long_name_passes_where_its_file_system_takes_it(tmp_path, monkeypatch):
    """A FAT, exFAT, NTFS or SMB folder counts 255 UTF-16 units (pathconf: 1530 bytes): 100 CJK characters (300
    bytes) name a file there, which the fixed 255-byte limit refused. Where the file system says 255, refused."""
    name = "\u5f71" * 100  # 300 bytes in UTF-8
    limits = {"PC_NAME_MAX": 1530}
    monkeypatch.setattr(os, "pathconf", lambda path, what: limits[what])
    assert path_problem(str(tmp_path / name)) is None
    assert path_problem(str(tmp_path / "new" / name / "x.json")) is None
    limits["PC_NAME_MAX"] = 255
    assert "a file or folder name has at most 255" in path_problem(str(tmp_path / name))


def test_odd_bytes_are_shown_as_repr():
    assert shown(NUL) == repr(NUL) and shown(NOT_UTF8) == repr(NOT_UTF8) and shown("models") == "models"


#: (module of the console script, its arguments with P where the odd path goes, the option named)
SCRIPTS = [
    ("drivers.sim.demo", ["--out", "P"], "--out"),
    ("drivers.sim.demo", ["--motion", "P"], "--motion"),
    ("firmware_host.demo", ["--out", "P", "--truth-only"], "--out"),
    ("firmware_host.demo", ["--config", "P"], "--config"),
    ("firmware_host.demo", ["--model-dir", "P"], "--model-dir"),
    ("firmware_host.daemon.cli", ["--config", "P", "--validate-config"], "--config"),
    ("calibration.cli", ["board", "--out", "P"], "--out"),
    ("calibration.cli", ["solve", "--images", "P", "--out", "r.json"], "--images"),
    ("calibration.cli", ["check", "--rig", "P", "--images", "i"], "--rig"),
    ("calibration.cli", ["import", "P", "--out", "r.json"], "file"),
    ("training.cli.train", ["--config", "P", "--out", "o", "--validate-config"], "--config"),
    ("training.cli.evaluate", ["--data", "P", "--model", "a=b"], "--data"),
    ("training.cli.evaluate", ["--model", "P"], "--model"),
    ("ghnerf_runtime.cli.run", ["--rig", "P", "--images", "a.png", "b.png"], "--rig"),
    ("ghnerf_runtime.cli.run", ["--rig", "r.json", "--videos", "P", "b.mp4"], "--videos"),
    ("ghnerf_runtime.cli.run", ["--rig", "r.json", "--images", "a.png", "b.png", "--overlay", "P"], "--overlay"),
    ("ghnerf_runtime.cli.run", ["--config", "P", "--validate-config"], "--config"),
    ("ghnerf_runtime.cli.bench", ["runtime", "--model-dir", "P"], "--model-dir"),
    ("ghnerf_runtime.cli.bench", ["runtime", "--json", "P"], "--json"),
    ("ghnerf_runtime.cli.bench", ["sim-pair", "--out", "P"], "--out"),
]


#: (module CLI run as ``python -m``, its arguments with P where the odd path goes, the option named): not console
#: scripts, so the table above does not list them; their path options took any value (a NUL raised from ``mkdir``).
MODULE_CLIS = [
    ("training.data.generate", ["--out", "P", "--val", "1"], "--out"),
    ("training.data.convert_zju", ["P", "--out", "o"], "subject"),
    ("training.data.convert_zju", ["subject", "--out", "P"], "--out"),
]


@pytest.mark.parametrize("kind, value, said", [ODD[0], ODD[1], ODD[2], ODD[4]], ids=["nul", "not_utf8", "long_name",
                                                                                   "tilde"])
@pytest.mark.parametrize("module, argv, option", SCRIPTS + MODULE_CLIS,
                         ids=[f"{m.split('.')[-2]}.{m.split('.')[-1]} {o}" for m, _, o in SCRIPTS + MODULE_CLIS])
def test_each_console_script_refuses_an_odd_path_as_a_usage_error(capsys, module, argv, option, kind, value, said):
    """In process, as argparse parses: nothing is opened, rendered, loaded or made (a folder, a subject read) before
    the refusal (a path that is not UTF-8 reaching OpenCV killed the process: a crash here would end the test run).
    The ``python -m`` module CLIs too."""
    if module.startswith("training.cli"):  # (the module CLIs under training.data need no torch)
        pytest.importorskip("torch")
    main = importlib.import_module(module).main
    with pytest.raises(SystemExit) as e:
        main([value if a == "P" else a for a in argv])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}: {shown(value)}: " in err and said in err and "Traceback" not in err


#: Options where an empty value was read as the option left out (the run went on without a word): checked besides
#: the tables above.
EMPTY_ALSO = [
    ("ghnerf_runtime.cli.run", ["--rig", "r.json", "--images", "a.png", "b.png", "--novel-view", "P"], "--novel-view"),
    ("ghnerf_runtime.cli.run", ["--rig", "r.json", "--images", "a.png", "b.png", "--out", "P"], "--out"),
    ("ghnerf_runtime.cli.run", ["--rig", "r.json", "--images", "P", "b.png"], "--images"),
]


@pytest.mark.parametrize("module, argv, option", SCRIPTS + MODULE_CLIS + EMPTY_ALSO,
                         ids=[f"{m.split('.')[-2]}.{m.split('.')[-1]} {o}"
                              for m, _, o in SCRIPTS + MODULE_CLIS + EMPTY_ALSO])
def test_each_console_script_refuses_an_empty_path_as_a_usage_error(capsys, module, argv, option):
    """An empty path (a ``"$UNSET"`` in a script) names no file. Before session 64's review it was read as the option
    left out or as the current folder: ``ghnerf-run --novel-view ''`` rendered nothing and exited 0, ``--config ''``
    ran on the defaults, ``ghnerf-demo --out ''`` wrote its files into the current folder and ``--model-dir ''``
    ended in a ConfigError traceback."""
    if module.startswith("training.cli"):
        pytest.importorskip("torch")
    main = importlib.import_module(module).main
    with pytest.raises(SystemExit) as e:
        main(["" if a == "P" else a for a in argv])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}: is empty: give a path" in err and "Traceback" not in err


def test_the_scripts_table_covers_every_console_script():
    text = (ROOT / "pyproject.toml").read_text()
    scripts = text.split("[project.scripts]")[1].split("\n[")[0]
    modules = {line.split("=")[1].strip().strip('"').split(":")[0] for line in scripts.splitlines() if "=" in line}
    listened = {"firmware_host.listen"}  # takes a udp:// URL only: no file
    assert modules - listened == {m for m, _, _ in SCRIPTS}




# ------------------------------------------------------------------ the daemon's config file
def _daemon_config(tmp_path: Path, **changes) -> Path:
    data = {"rig": {"url": "sim://?fps=30"}, "sinks": ["udp://127.0.0.1:9870"],
            "estimator": {"session": {"model_dir": str(ROOT / "models")}},
            "health": {"status_file": str(tmp_path / "status.json")}}
    for key, value in changes.items():
        section, name = key.split("__")
        data[section] = value if name == "" else {**data[section], name: value}
    path = tmp_path / "daemon.json"
    path.write_text(json.dumps(data))
    return path


def _quoted(value: str) -> str:
    from urllib.parse import quote

    return quote(value, safe="/")


#: (config change, the key named): every path key of docs/daemon.md, and the files of rig URLs.
DAEMON_PATHS = [
    (lambda v: {"health__status_file": v}, "health.status_file"),
    (lambda v: {"estimator__session": {"model_dir": v}}, "estimator.session.model_dir"),
    (lambda v: {"rig__url": "replay://" + _quoted(v)}, "rig.url"),
    (lambda v: {"rig__url": "sim://?bvh=" + _quoted(v)}, "rig.url"),
    (lambda v: {"rig__url": "sim://?cache=" + _quoted(v)}, "rig.url"),
    (lambda v: {"rig__url": f"opencv://?first={_quoted(v)}&second=1&rig=/r.json"}, "rig.url"),
    (lambda v: {"rig__url": f"opencv://?first=0&second=1&rig={_quoted(v)}"}, "rig.url"),
]


@pytest.mark.parametrize("kind, value, said", [ODD[0], ODD[2], ODD[3], ODD[4]], ids=["nul", "long_name",
                                                                                   "long_path", "tilde"])
@pytest.mark.parametrize("change, key", DAEMON_PATHS, ids=["status_file", "model_dir", "replay", "sim bvh",
                                                           "sim cache", "opencv first", "opencv rig"])
def test_the_daemon_refuses_an_odd_path_in_its_config_naming_the_key(tmp_path, capsys, change, key, kind, value,
                                                                     said):
    from firmware_host.daemon.cli import main

    config = _daemon_config(tmp_path, **change(value))
    assert main(["--config", str(config), "--validate-config", "--no-model"]) == 2
    err = capsys.readouterr().err
    assert f"{config}: {key}: " in err and shown(value) in err and said in err and "Traceback" not in err


def test_the_daemon_start_refuses_a_nul_in_the_status_file_as_validation_does(tmp_path, capsys):
    """The reviewer's case: the start (not only --validate-config) ended in ``ValueError: embedded null byte``."""
    from firmware_host.daemon.cli import main

    config = _daemon_config(tmp_path, health__status_file=NUL)
    assert main(["--config", str(config), "--max-seconds", "1"]) == 2
    err = capsys.readouterr().err
    assert f"health.status_file: {NUL!r}: holds a NUL byte" in err


def test_a_file_sink_url_with_an_odd_path_is_refused_naming_it():
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks.file_sink import FileSink

    for path, said in (("/tmp/a%00b", "holds a NUL byte"), ("/tmp/" + LONG_NAME, "at most 255")):
        with pytest.raises(SinkConfigError, match=said):
            FileSink.from_url("file://" + path)


# ------------------------------------------------------------------ rig URLs on a command line
@pytest.mark.parametrize("url, part", [
    ("replay://a%00b", "the path after ://"), ("sim://?cache=a%00b", "option cache="),
    ("opencv://?first=a%00b&second=1&rig=/r.json", "option first="), ("record+sim://?out=a%00b", "option out="),
    (f"replay:///tmp/{LONG_NAME}", "the path after ://"), ("sim://?cache=~/cache", "option cache="),
])
def test_a_rig_url_naming_an_odd_path_is_refused_before_its_backend_opens_it(url, part):
    from drivers.errors import RigConfigError
    from drivers.registry import create_rig_source

    with pytest.raises(RigConfigError, match=f"{part} "):
        create_rig_source(url)


# ------------------------------------------------------------------ folders that cannot be made
@pytest.mark.parametrize("make", ["through_a_file", "dangling_link"])
@pytest.mark.parametrize("module, argv", [
    ("firmware_host.demo", ["--truth-only", "--seconds", "0.1", "--out", "P"]),
    ("ghnerf_runtime.cli.bench", ["sim-pair", "--out", "P"]),
    ("calibration.cli", ["board", "--out", "P"]),
], ids=["ghnerf-demo", "ghnerf-bench sim-pair", "ghcal board"])
def test_an_output_folder_that_cannot_be_made_is_said_with_the_flag(tmp_path, capsys, module, argv, make):
    (tmp_path / "plain").write_text("")
    os.symlink(tmp_path / "gone", tmp_path / "link")
    bad = tmp_path / "plain" / "x" if make == "through_a_file" else tmp_path / "link"
    main = importlib.import_module(module).main
    try:
        code = main([str(bad) if a == "P" else a for a in argv])
    except SystemExit as e:
        code = e.code
    assert code == 2
    err = capsys.readouterr().err
    why = "is a file" if make == "through_a_file" else "is a symbolic link to"
    assert f"--out {bad}: " in err and why in err and "Errno" not in err


# ------------------------------------------------------------------ OpenCV never sees a name it crashes on
def test_an_image_whose_name_is_not_utf8_is_read_not_crashed_on(tmp_path):
    import cv2
    import numpy as np

    from ghnerf_runtime.image_files import read_image_or_none

    cv2.imwrite(str(tmp_path / "plain.png"), np.full((3, 4, 3), 7, np.uint8))
    os.rename(tmp_path / "plain.png", os.fsencode(tmp_path) + b"/\xff.png")
    (listed,) = os.listdir(tmp_path)  # as a folder of views is listed: the byte kept as a surrogate
    assert read_image_or_none(tmp_path / listed, cv2.IMREAD_COLOR).shape == (3, 4, 3)


def test_an_image_path_with_a_nul_byte_is_not_read_up_to_it(tmp_path, monkeypatch):
    """``cv2.imread("a\\x00b")`` reads the file ``a``."""
    import cv2
    import numpy as np

    from ghnerf_runtime.image_files import read_image_or_none

    monkeypatch.chdir(tmp_path)
    cv2.imwrite("a.png", np.zeros((3, 4, 3), np.uint8))
    assert read_image_or_none("a.png\x00b", cv2.IMREAD_COLOR) is None


@pytest.mark.parametrize("data, said", [
    ({"sinks": ["udp://127.0.0.1:9870"], "health": {"status_file": NUL}}, f"health.status_file: {NUL!r}: holds a NUL"),
    ({"sinks": ["file:///tmp/a%00b"]}, "sinks[0]: '/tmp/a\\x00b': holds a NUL byte"),
], ids=["status_file", "file sink"])
def test_a_config_built_from_data_refuses_a_nul_before_the_outputs_apart_check(data, said):
    """Not only a config file: ``daemon_config_from_dict`` (a reload's, a test's) reached ``os.path.realpath``."""
    from firmware_host.daemon.config import DaemonConfigError, daemon_config_from_dict

    with pytest.raises(DaemonConfigError) as e:
        daemon_config_from_dict(data)
    assert said in str(e.value)


def test_the_daemon_refuses_a_nul_in_a_file_sink_of_its_config_file(tmp_path, capsys):
    from firmware_host.daemon.cli import main

    config = _daemon_config(tmp_path, sinks__=["file:///tmp/a%00b"])
    assert main(["--config", str(config), "--validate-config", "--no-model"]) == 2
    assert f"{config}: sinks[0]: '/tmp/a\\x00b': holds a NUL byte" in capsys.readouterr().err


def test_a_rig_url_refused_for_its_path_shows_no_password():
    """The refusal wrote the whole URL as given: a stream's password beside the odd file path reached the log,
    where every other rig URL error redacts it (drivers.url.redact_url)."""
    from drivers.errors import RigConfigError
    from drivers.url_paths import check_url_paths

    with pytest.raises(RigConfigError) as refused:
        check_url_paths("opencv://?first=/v/a%00b.mp4&second=rtsp%3A%2F%2Fuser%3Asecret%40cam%2Fs&rig=/r.json")
    assert "holds a NUL byte" in str(refused.value) and "secret" not in str(refused.value)
