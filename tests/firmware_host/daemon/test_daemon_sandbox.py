"""Paths the ghnerf unit's sandbox hides from the service (``firmware_host.daemon.sandbox``): ``--validate-config``
runs outside it and passed a model folder, rig file, recording, status file or file:// sink under /home (or in
/tmp), and the service then said only "no such folder" or "permission denied"."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from firmware_host.daemon import cli, sandbox
from firmware_host.daemon.sandbox import HOME_FOLDERS, PRIVATE_TMP_FOLDERS, rig_url_hint, sandbox_advice

REPO = Path(__file__).resolve().parents[3]


def _unit_settings() -> dict[str, str]:
    text = (REPO / "systemd" / "ghnerf.service").read_text()
    return dict(re.findall(r"^(\w+)=(.*)$", text, flags=re.MULTILINE))


def test_the_hidden_folders_are_the_installed_unit_s():
    """The folders are ProtectHome=yes's and PrivateTmp=yes's (systemd.exec(5)); a unit that changes either, or
    opens a path again (Bind*Paths=, ProtectHome=tmpfs), must bring the module along."""
    unit = _unit_settings()
    assert unit["ProtectHome"] == "yes" and HOME_FOLDERS == ("/home", "/root", "/run/user")
    assert unit["PrivateTmp"] == "yes" and PRIVATE_TMP_FOLDERS == ("/tmp", "/var/tmp")
    assert not {"BindPaths", "BindReadOnlyPaths", "ReadWritePaths", "ReadOnlyPaths"} & set(unit)


def test_the_advice_names_the_folder_the_setting_and_what_works_there():
    home = sandbox_advice("/home/me/models")
    assert home.startswith("under /home, which the ghnerf unit's ProtectHome=yes hides from the service: move it")
    # ReadWritePaths= cannot open a path below /home under ProtectHome=yes (nothing is mounted there to remount)
    assert "ProtectHome=tmpfs and BindReadOnlyPaths=/home/me/models" in home
    assert "BindPaths=/root/out.jsonl" in sandbox_advice("/root/out.jsonl", written=True)
    assert "(it does not see this one)" in sandbox_advice("/tmp/rig.json")
    assert "no one else sees" in sandbox_advice("/var/tmp/joints.jsonl", written=True)
    assert "ProtectHome" not in sandbox_advice("/tmp/rig.json")  # a bind would not help there: move it
    for seen in ("/opt/ghnerf/models", "/var/lib/ghnerf/take", "/etc/ghnerf/rig.json", "/homework/x", "/tmpfs/x"):
        assert sandbox_advice(seen) is None, seen


def test_a_link_into_a_home_folder_is_hidden_too(tmp_path, monkeypatch):
    home = tmp_path / "home"
    (home / "me" / "models").mkdir(parents=True)
    (tmp_path / "opt").mkdir()
    (tmp_path / "opt" / "models").symlink_to(home / "me" / "models")
    monkeypatch.setattr(sandbox, "HOME_FOLDERS", (str(home),))
    monkeypatch.setattr(sandbox, "PRIVATE_TMP_FOLDERS", ())  # tmp_path is under /tmp itself
    assert sandbox.hidden_by_sandbox(tmp_path / "opt" / "models") == str(home)
    assert sandbox.hidden_by_sandbox(tmp_path / "opt") is None


def _home_config(tmp_path: Path, monkeypatch) -> tuple[Path, Path]:
    """A config whose every path is under a stand-in home folder; the config file itself outside it."""
    home = tmp_path / "home"
    models = home / "me" / "models"
    models.mkdir(parents=True)
    (models / "encoder.onnx").write_bytes(b"only globbed by --validate-config --no-model")
    monkeypatch.setattr(sandbox, "HOME_FOLDERS", (str(home),))
    monkeypatch.setattr(sandbox, "PRIVATE_TMP_FOLDERS", ())  # tmp_path is under /tmp itself
    (tmp_path / "etc").mkdir()
    path = tmp_path / "etc" / "daemon.json"
    path.write_text(json.dumps({
        "rig": {"url": f"replay://{home / 'me' / 'take'}"},
        "sinks": ["udp://127.0.0.1:9870", f"file://{home / 'me' / 'joints.jsonl'}"],
        "estimator": {"session": {"model_dir": str(models)}},
        "health": {"status_file": str(home / "me" / "status.json")},
    }))
    return path, home


def test_validate_config_warns_of_every_path_the_service_could_not_see_and_passes(tmp_path, monkeypatch, capsys):
    path, home = _home_config(tmp_path, monkeypatch)
    assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 0
    err = capsys.readouterr().err
    me = home / "me"
    hides = f"is under {home}, which the ghnerf unit's ProtectHome=yes hides from the service"
    for key, where, bind in (("estimator.session.model_dir", me / "models", "BindReadOnlyPaths"),
                             ("health.status_file", me / "status.json", "BindPaths"),
                             ("rig.url", me / "take", "BindReadOnlyPaths"),
                             ("sinks[1]", me / "joints.jsonl", "BindPaths")):
        line = next((x for x in err.splitlines() if x.startswith(f"ghnerf-daemon: warning: {path}: {key}: ")), None)
        assert line is not None, (key, err)
        assert f"{key}: {where} {hides}" in line and f"{bind}={where} " in line, line
    assert err.splitlines()[-1].startswith(f"ghnerf-daemon: {path}: ok;")


def test_validate_config_says_nothing_of_paths_the_service_sees(tmp_path, monkeypatch, capsys):
    path, _ = _home_config(tmp_path, monkeypatch)
    monkeypatch.setattr(sandbox, "HOME_FOLDERS", (str(tmp_path / "elsewhere"),))
    assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_under_systemd_a_missing_model_folder_in_a_hidden_place_says_why(tmp_path, monkeypatch, capsys):
    """In the service a model folder under /home is not there (or not enterable): the error now says the sandbox
    hides it, and what to do; outside systemd a missing folder is just missing."""
    path, home = _home_config(tmp_path, monkeypatch)
    models = home / "me" / "models"
    (models / "encoder.onnx").unlink()
    models.rmdir()  # as the service sees it: no such folder
    assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 2
    plain = capsys.readouterr().err.strip()
    assert plain == f"ghnerf-daemon: error: {path}: estimator.session.model_dir: {models}: no such folder"
    monkeypatch.setenv("INVOCATION_ID", "0123456789abcdef")
    assert cli.main(["--config", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"{plain} (the path is under {home}, which the ghnerf unit's ProtectHome=yes hides")
    assert f"BindReadOnlyPaths={models} " in err


def test_under_systemd_a_rig_file_or_recording_in_a_hidden_place_says_why(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sandbox, "HOME_FOLDERS", (str(tmp_path / "home"),))
    monkeypatch.setattr(sandbox, "PRIVATE_TMP_FOLDERS", ())
    rig = tmp_path / "home" / "rig.json"
    url = f"depthai://?rig={rig}"
    assert rig_url_hint(url) == ""  # not under systemd: really missing
    monkeypatch.setenv("INVOCATION_ID", "0123456789abcdef")
    assert rig_url_hint(url).startswith(f" (the path is under {tmp_path / 'home'}, which the ghnerf unit's")
    assert rig_url_hint(f"replay://{tmp_path / 'home' / 'take'}?loop=1") != ""
    assert rig_url_hint(f"replay://{tmp_path / 'take'}") == rig_url_hint("sim://?fps=30") == ""
    # the start's check of a rig file names it with the hint (it said only "no such file")
    with pytest.raises(cli.DaemonConfigError, match=r"rig\.json.*\(the path is under .*BindReadOnlyPaths="):
        cli._check_rig_url(url, warn_of_rig=False)


def test_under_systemd_a_status_file_in_a_hidden_place_says_why(tmp_path, monkeypatch, caplog):
    """The status file's warning told to add the folder with ReadWritePaths=, which cannot open a path below
    /home under ProtectHome=yes; for such a path it now gives the sandbox's advice (BindPaths=, or move it)."""
    import logging

    from firmware_host.daemon import Daemon, daemon_config_from_dict

    home = tmp_path / "home"
    monkeypatch.setattr(sandbox, "HOME_FOLDERS", (str(home),))
    monkeypatch.setattr(sandbox, "PRIVATE_TMP_FOLDERS", ())
    status = home / "me" / "status.json"  # its folder missing, as in the service's empty /home
    config = daemon_config_from_dict({"rig": {"url": "sim://?fps=30"}, "sinks": ["memory://"],
                                      "health": {"status_file": str(status)}})
    monkeypatch.setenv("INVOCATION_ID", "0123456789abcdef")
    with caplog.at_level(logging.WARNING):
        Daemon(config)._tick(force=True, tell_systemd=False)
    said = [r.getMessage() for r in caplog.records if "status file" in r.getMessage()]
    assert len(said) == 1 and f"cannot write the status file {status}" in said[0], said
    assert f"(the path is under {home}, which the ghnerf unit's ProtectHome=yes" in said[0]
    assert f"BindPaths={status} " in said[0] and "add the folder with ReadWritePaths=" not in said[0]


def _status_warning(tmp_path, monkeypatch, caplog, error: OSError) -> str:
    """The daemon's warning for a status file whose write fails with ``error`` (outside systemd: no sandbox advice)."""
    import logging

    from firmware_host.daemon import Daemon, daemon_config_from_dict, service

    def refuse(path, report):
        raise error

    monkeypatch.setattr(service, "write_status_file", refuse)
    monkeypatch.delenv("INVOCATION_ID", raising=False)
    config = daemon_config_from_dict({"rig": {"url": "sim://?fps=30"}, "sinks": ["memory://"],
                                      "health": {"status_file": str(tmp_path / "status.json")}})
    with caplog.at_level(logging.WARNING):
        Daemon(config)._tick(force=True, tell_systemd=False)
    said = [r.getMessage() for r in caplog.records if "status file" in r.getMessage()]
    assert len(said) == 1, said
    return said[0]


def test_the_status_file_and_the_file_sink_give_one_read_only_hint(tmp_path, monkeypatch, caplog):
    """Review 52: the status file's ReadWritePaths= hint and the file sink's were two wordings of one advice, in two
    places (firmware_host/daemon/service.py, firmware_host/sinks/file_sink.py); firmware_host.service_unit owns it
    now. It is for EROFS (ProtectSystem=strict's read-only system), which ReadWritePaths= undoes; the status file gave
    it for EACCES too, a folder's owner or mode (or ProtectHome=), which that setting does not change."""
    import errno

    from firmware_host.service_unit import read_only_hint

    hint = read_only_hint(OSError(errno.EROFS, "Read-only file system"))
    assert hint == (" (read-only: the ghnerf unit writes only under /run/ghnerf and /var/lib/ghnerf; add the folder "
                    "with ReadWritePaths= in systemctl edit ghnerf)")
    said = _status_warning(tmp_path, monkeypatch, caplog, OSError(errno.EROFS, "Read-only file system"))
    assert said.endswith("Read-only file system" + hint), said
    caplog.clear()
    said = _status_warning(tmp_path, monkeypatch, caplog, PermissionError(errno.EACCES, "Permission denied"))
    assert said.endswith("Permission denied") and "ReadWritePaths" not in said, said
    assert read_only_hint(ValueError("not an OSError")) == ""


def test_the_folders_the_service_writes_are_the_installed_unit_s():
    from firmware_host.service_unit import WRITABLE_FOLDERS

    unit = _unit_settings()
    assert unit["ProtectSystem"] == "strict"  # else more than these folders are writable
    assert WRITABLE_FOLDERS == (f"/run/{unit['RuntimeDirectory']}", f"/var/lib/{unit['StateDirectory']}")
