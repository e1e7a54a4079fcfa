"""systemd/: the install script (staged into a folder, no root), the unit file, the udev rules, the config.

``systemd-analyze verify`` checks the installed unit where systemd's tools exist (skipped elsewhere);
the rest checks that the unit, the default config and the daemon agree with each other.
"""
from __future__ import annotations

import configparser
import fnmatch
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from firmware_host.daemon.config import load_daemon_config

REPO = Path(__file__).resolve().parents[2]
INSTALL = REPO / "systemd" / "install.sh"
UNIT = REPO / "systemd" / "ghnerf.service"


def _install(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(INSTALL), *args], capture_output=True, text=True, timeout=300)


def _unit(path: Path) -> configparser.ConfigParser:
    parser = configparser.ConfigParser(strict=False, interpolation=None, delimiters=("=",))
    parser.optionxform = str  # systemd keys are case-sensitive
    parser.read_string(path.read_text())
    return parser


@pytest.fixture(scope="module")
def staged(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("stage")
    prefix = tmp_path_factory.mktemp("prefix")  # absolute, and where verify finds the executable
    proc = _install("--destdir", str(root), "--prefix", str(prefix))
    assert proc.returncode == 0, proc.stderr
    return root, prefix


def test_stages_every_file(staged):
    root, prefix = staged
    unit = root / "etc/systemd/system/ghnerf.service"
    assert unit.is_file() and (root / "etc/udev/rules.d/60-ghnerf.rules").is_file()
    staged_prefix = root / str(prefix).lstrip("/")
    assert (staged_prefix / "models/model_card.json").read_bytes() == (REPO / "models/model_card.json").read_bytes()
    assert (staged_prefix / "docs/daemon.md").is_file()
    service = _unit(unit)["Service"]
    assert service["ExecStart"] == f"{prefix}/venv/bin/ghnerf-daemon --config /etc/ghnerf/daemon.json"
    assert "/opt/ghnerf" not in unit.read_text()
    config = load_daemon_config(root / "etc/ghnerf/daemon.json")
    assert config.estimator.session.model_dir == f"{prefix}/models"
    assert config.rig.url == "depthai://"


def _install_section() -> str:
    text = (REPO / "docs/daemon.md").read_text()
    start = text.index("## Installing on the device")
    return text[start:text.index("\n## ", start + 1)]


def test_the_docs_name_every_path_it_installs(staged):
    """docs/daemon.md's table names each path install.sh writes (what --destdir stages: the files; the prefix's
    own folders by name) and what it makes that staging cannot (the environment the unit runs, the user)."""
    root, prefix = staged
    staged_prefix = root / str(prefix).lstrip("/")
    installed = set()
    for path in root.rglob("*"):
        if path.is_dir():
            continue
        if staged_prefix in path.parents:  # under the prefix: its top-level entry, as the docs write it
            top = path.relative_to(staged_prefix).parts[0]
            installed.add(f"PREFIX/{top}/" if (staged_prefix / top).is_dir() else f"PREFIX/{top}")
        else:
            installed.add("/" + str(path.relative_to(root)))
    assert {"/etc/systemd/system/ghnerf.service", "/etc/ghnerf/daemon.json", "PREFIX/models/"} <= installed
    exec_start = _unit(root / "etc/systemd/system/ghnerf.service")["Service"]["ExecStart"].split()[0]
    section = _install_section()
    for path in sorted(installed) + [exec_start.replace(str(prefix), "PREFIX"), "PREFIX/venv"]:
        assert f"`{path}`" in section, f"docs/daemon.md, Installing on the device, does not name {path}"
    assert "| user `ghnerf` |" in section


def test_staging_says_what_the_service_still_lacks(staged):
    """Staged, the unit names PREFIX/venv and the user ghnerf, neither of which --destdir makes; the output said
    only "not started; on the device: systemctl ... restart", which started a service that failed at once."""
    root, prefix = staged
    proc = _install("--destdir", str(root), "--prefix", str(prefix))
    assert proc.returncode == 0, proc.stderr
    assert (f"staged only: no environment {prefix}/venv (the unit runs {prefix}/venv/bin/ghnerf-daemon) and no user "
            "ghnerf") in proc.stdout
    assert f"sudo systemd/install.sh --prefix {prefix} --no-start" in proc.stdout


def test_an_existing_config_is_kept(staged):
    root, prefix = staged
    config = root / "etc/ghnerf/daemon.json"
    edited = json.loads(config.read_text())
    edited["sinks"] = ["serial:///dev/ttyACM0?baud=921600"]
    config.write_text(json.dumps(edited))
    proc = _install("--destdir", str(root), "--prefix", str(prefix))
    assert proc.returncode == 0, proc.stderr
    assert "kept the existing" in proc.stdout
    assert json.loads(config.read_text())["sinks"] == ["serial:///dev/ttyACM0?baud=921600"]


@pytest.mark.parametrize("args, message", [
    (["--prefix", "relative/path", "--destdir", "/tmp/x"], "--prefix must be an absolute path"),
    (["--prefix", "/opt/a b", "--destdir", "/tmp/x"], "--prefix may hold only"),
    (["--frobnicate"], "unknown option --frobnicate"),
    (["--prefix"], "--prefix needs a folder"),
])
def test_bad_options_exit_2(args, message):
    proc = _install(*args)
    assert proc.returncode == 2 and message in proc.stderr


@pytest.mark.parametrize("prefix", ["/home/pi/ghnerf", "/root/ghnerf", "/run/user/1000/ghnerf", "/home",
                                    "/opt/../home/pi/ghnerf"])
def test_a_prefix_the_sandbox_hides_is_refused(tmp_path, prefix):
    """ProtectHome=yes hides /home, /root and /run/user from the service: it could not chdir to the prefix
    (status 200/CHDIR) and would restart until its start limit. Refused before anything is written."""
    stage = tmp_path / "stage"
    proc = _install("--destdir", str(stage), "--prefix", prefix)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert f"--prefix {prefix} is under a home folder" in proc.stderr
    assert "ProtectHome" in proc.stderr and "--prefix /opt/ghnerf" in proc.stderr
    assert not stage.exists()


def test_no_start_prints_the_commands_a_start_runs(staged):
    root, prefix = staged
    proc = _install("--destdir", str(root), "--prefix", str(prefix))
    assert proc.returncode == 0, proc.stderr
    # restart, not enable --now: an upgrade of a running service must restart it; udev for a plugged OAK
    assert ("not started; on the device: systemctl daemon-reload && udevadm control --reload-rules && "
            "udevadm trigger --subsystem-match=usb && systemctl enable ghnerf.service && "
            "systemctl restart ghnerf.service") in proc.stdout


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed")
def test_systemd_accepts_the_installed_unit(staged):
    root, prefix = staged
    exe = prefix / "venv/bin/ghnerf-daemon"
    exe.parent.mkdir(parents=True, exist_ok=True)
    if not exe.exists():
        exe.symlink_to(Path(sys.executable).parent / "ghnerf-daemon")
    proc = subprocess.run(["systemd-analyze", "verify", str(root / "etc/systemd/system/ghnerf.service")],
                          capture_output=True, text=True, timeout=120)
    complaints = [line for line in (proc.stdout + proc.stderr).splitlines() if "ghnerf" in line]
    assert proc.returncode == 0 and not complaints, proc.stdout + proc.stderr


def test_unit_and_daemon_agree():
    unit = _unit(UNIT)
    service = unit["Service"]
    assert service["Type"] == "notify"  # the daemon sends READY=1 (firmware_host.daemon.service)
    assert service["RestartPreventExitStatus"] == "2"  # the CLI's exit status for what a restart cannot fix
    assert service["Restart"] == "on-failure"
    # on-failure counts a death by SIGHUP as clean; SIGHUP is the reload signal, never a wanted end
    assert "SIGHUP" in service["RestartForceExitStatus"].split()
    # systemctl reload: the signal the CLI reloads the config on, sent to the daemon itself.
    assert service["ExecReload"].split()[1:] == ["-HUP", "$MAINPID"]
    default = load_daemon_config(REPO / "systemd/daemon.json")
    # The status file lives in the folder systemd creates for the service.
    assert Path(default.health.status_file).parent == Path("/run") / service["RuntimeDirectory"]
    # The pings stop once the loop has not beaten for health.loop_allowance_s; systemd then restarts
    # the service within WatchdogSec. A watchdog shorter than the opening allowance would kill a
    # daemon still booting an OAK, which beats only around the open.
    watchdog_s = float(service["WatchdogSec"])
    assert default.health.open_allowance_s >= watchdog_s
    assert watchdog_s >= 2 * default.health.status_every_s  # pinged every WatchdogSec / 2 at least
    assert float(service["TimeoutStartSec"]) > 10
    assert service["RuntimeDirectoryPreserve"] == "yes"  # the last status outlives a crash
    groups = service["SupplementaryGroups"].split()
    rules = (REPO / "systemd/60-ghnerf.rules").read_text()
    assert 'GROUP="plugdev"' in rules and {"plugdev", "dialout", "video"} <= set(groups)  # OAK, serial, webcams


def test_the_start_does_not_wait_for_the_network():
    """Ordered after network-online.target (and pulling it in), the service waited at every boot without a link
    for the wait-online service to give up (systemd-networkd's: 2 minutes), a serial- or USB-only rig too, though
    nothing of the daemon needs the network at start (a UDP sink whose host does not resolve yet does not hold it
    up: tests/firmware_host/daemon/test_daemon_service.py). network.target stays, for the order of the stop."""
    unit = _unit(UNIT)["Unit"]
    deps = {key: unit.get(key, "").split() for key in ("After", "Wants", "Requires", "BindsTo", "Requisite")}
    assert not any("network-online.target" in names for names in deps.values()), deps
    assert "network.target" in deps["After"]


_RULE_KEY = re.compile(r'^(?P<key>SUBSYSTEM|ATTRS\{\w+\}|ATTR\{\w+\}|KERNEL|ENV\{\w+\}|MODE|GROUP|SYMLINK|TAG)'
                       r'(?P<op>==|!=|\+=|=)"(?P<value>[^"]*)"$')


def _active_rules(path: Path) -> list[str]:
    return [line.strip() for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]


def test_udev_rules_parse():
    lines = [line.strip() for name in ("60-ghnerf.rules", "61-ghnerf-local.rules")
             for line in (REPO / "systemd" / name).read_text().splitlines()]
    rules = [line for line in lines if line and not line.startswith("#")]
    assert rules, "no active rule"
    assert not _active_rules(REPO / "systemd/61-ghnerf-local.rules")  # templates only: the user's ids go there
    commented = [line.lstrip("# ") for line in lines if line.startswith("# SUBSYSTEM")]
    assert len(commented) == 2  # a USB receiver, a serial receiver's stable name
    for rule in rules + commented:  # the templates must be valid once uncommented too
        for pair in (p.strip() for p in rule.split(",")):
            assert _RULE_KEY.match(pair), f"bad udev pair {pair!r} in {rule!r}"
    assert any('ATTRS{idVendor}=="03e7"' in rule for rule in rules)  # Luxonis / Movidius


def _udev_apply(rule: str, device: dict[str, str]) -> dict[str, str] | None:
    """What ``rule`` assigns to ``device`` (its ``SUBSYSTEM`` and sysfs attributes, ``ATTRS{idVendor}`` ...), or
    None when a match key fails. udev's own comparison: a shell glob, ``|`` between alternatives. The device's
    attributes stand for the whole parent chain ``ATTRS`` searches (a USB device node has them itself)."""
    assigned = {}
    for pair in (p.strip() for p in rule.split(",")):
        m = _RULE_KEY.match(pair)
        assert m, f"bad udev pair {pair!r} in {rule!r}"
        key, op, value = m["key"], m["op"], m["value"]
        if op in ("==", "!="):
            hit = key in device and any(fnmatch.fnmatchcase(device[key], alt) for alt in value.split("|"))
            if hit != (op == "=="):
                return None
        else:
            assigned[key] = value
    return assigned


def _oak(product: str) -> dict[str, str]:
    return {"SUBSYSTEM": "usb", "ATTRS{idVendor}": "03e7", "ATTRS{idProduct}": product}


#: The OAK's product ids (Luxonis XLink): unbooted (USB boot ROM), booted (depthai's firmware running), its flash
#: bootloader and booted from flash. depthai boots it, so the device node changes id, and group, under the service.
OAK_PRODUCTS = ("2485", "f63b", "f63c", "f63d")


@pytest.mark.parametrize("product", OAK_PRODUCTS)
def test_every_state_of_an_oak_goes_to_the_services_group(product):
    """An OAK re-enumerates under another product id once depthai has booted it: a rule covering only the id
    seen in lsusb before the boot lost the camera to EACCES right after its first open."""
    groups = _unit(UNIT)["Service"]["SupplementaryGroups"].split()
    rules = _active_rules(REPO / "systemd/60-ghnerf.rules")
    assigned = [a for a in (_udev_apply(rule, _oak(product)) for rule in rules) if a is not None]
    assert assigned, f"no rule of 60-ghnerf.rules matches the OAK as 03e7:{product}"
    final = {k: v for a in assigned for k, v in a.items()}  # the last assignment wins, as in udev
    assert final["GROUP"] in groups and final["MODE"] == "0660", final


def test_the_oak_rule_leaves_other_devices_alone():
    hub = {"SUBSYSTEM": "usb", "ATTRS{idVendor}": "1d6b", "ATTRS{idProduct}": "0002"}  # a Linux root hub
    oak_interface = {**_oak("f63b"), "SUBSYSTEM": "tty"}  # not the usb subsystem
    for rule in _active_rules(REPO / "systemd/60-ghnerf.rules"):
        assert _udev_apply(rule, hub) is None and _udev_apply(rule, oak_interface) is None, rule


def _group_names(text: str) -> set[str]:
    return set(re.findall(r'GROUP="([^"]*)"', text))


def test_every_group_the_rules_give_is_one_the_service_and_its_user_have():
    """A rule (or a template, once uncommented) giving a device to a group the service is not in leaves it
    EACCES to the daemon; install.sh makes the user and the groups, the unit adds them to the process."""
    groups = set(_unit(UNIT)["Service"]["SupplementaryGroups"].split())
    named = set()
    for name in ("60-ghnerf.rules", "61-ghnerf-local.rules"):
        named |= _group_names((REPO / "systemd" / name).read_text())
    assert named and named <= groups, named - groups
    script = INSTALL.read_text()
    useradd = re.search(r"--groups (\S+) ghnerf", script)
    assert useradd and set(useradd[1].split(",")) == groups
    for group in groups:  # created where the distribution has no such group (useradd --groups would fail)
        assert f"getent group {group} >/dev/null || groupadd --system {group}" in script


def test_the_usb_receiver_template_is_the_documented_example_in_the_form_udev_compares():
    """The template's ids were a made-up cafe:4011 beside docs/protocol.md's usb://1209:0001 example and its
    rule; and udev compares the sysfs text (four lower-case hex digits), which the sink's URL need not be."""
    from firmware_host.sinks.usb_sink import UsbSink

    template = next(line.lstrip("# ") for line in (REPO / "systemd/61-ghnerf-local.rules").read_text().splitlines()
                    if line.startswith('# SUBSYSTEM=="usb"'))
    assert template in (REPO / "docs/protocol.md").read_text()  # the rule the usb:// section shows
    ids = dict(re.findall(r'ATTRS\{(idVendor|idProduct)\}=="([^"]*)"', template))
    sink = UsbSink.from_url("usb://0x1209:1?ep=0x01", cameras=("left", "right"))  # the example, written loosely
    assert (ids["idVendor"], ids["idProduct"]) == (f"{sink.vid:04x}", f"{sink.pid:04x}")
    assert _udev_apply(template, {"SUBSYSTEM": "usb", "ATTRS{idVendor}": ids["idVendor"],
                                  "ATTRS{idProduct}": ids["idProduct"]}) == {"MODE": "0660", "GROUP": "plugdev"}


def test_a_reinstall_keeps_the_udev_rules_a_user_added(tmp_path):
    """The rules' templates said to uncomment them in the installed file, which every install replaced: after an
    upgrade a usb:// receiver could no longer be claimed (EACCES, retried for ever) and a serial receiver's
    /dev/ghnerf-robot was gone. Now rules of one's own live in 61-ghnerf-local.rules, written only when absent,
    and a rule found added to an installed 60-ghnerf.rules is moved there before that file is replaced."""
    root, prefix = tmp_path / "stage", tmp_path / "prefix"
    rules_d = root / "etc/udev/rules.d"
    assert _install("--destdir", str(root), "--prefix", str(prefix)).returncode == 0
    receiver = 'SUBSYSTEM=="usb", ATTRS{idVendor}=="cafe", ATTRS{idProduct}=="4011", MODE="0660", GROUP="plugdev"'
    robot = 'SUBSYSTEM=="tty", ATTRS{idVendor}=="2e8a", ATTRS{idProduct}=="000a", SYMLINK+="ghnerf-robot"'
    with open(rules_d / "60-ghnerf.rules", "a") as fh:  # as an earlier layout's comment told the user
        fh.write(receiver + "\n")
    with open(rules_d / "61-ghnerf-local.rules", "a") as fh:
        fh.write(robot + "\n")

    proc = _install("--destdir", str(root), "--prefix", str(prefix))
    assert proc.returncode == 0, proc.stderr
    assert "moved 1 rule(s) of yours" in proc.stdout
    assert (rules_d / "60-ghnerf.rules").read_text() == (REPO / "systemd/60-ghnerf.rules").read_text()
    active = [rule for path in sorted(rules_d.glob("*.rules")) for rule in _active_rules(path)]
    assert receiver in active and robot in active
    assert active.count(receiver) == 1
    local = (rules_d / "61-ghnerf-local.rules").read_text()

    proc = _install("--destdir", str(root), "--prefix", str(prefix))  # idempotent: nothing moves twice
    assert proc.returncode == 0 and "moved" not in proc.stdout
    assert (rules_d / "61-ghnerf-local.rules").read_text() == local


def test_help_is_the_header_comment_only():
    # it printed the header's lines by number, and with them the script's "set -euo pipefail"
    proc = _install("--help")
    assert proc.returncode == 0
    assert proc.stdout.startswith("Install the ghnerf daemon") and "docs/daemon.md has the details." in proc.stdout
    assert "set -euo" not in proc.stdout and "#" not in proc.stdout.splitlines()[0]
