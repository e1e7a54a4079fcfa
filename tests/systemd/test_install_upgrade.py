"""``install.sh`` for real (as root, building the environment), on a fake checkout and a fake interpreter.

The script writes to ``/etc`` and runs ``useradd``, ``runuser``, ``systemctl`` and ``udevadm``: it runs
here in a private mount namespace (``unshare``, a user namespace where not root) with a scratch folder
bound over ``/etc`` and stand-ins for those commands first on ``PATH``. Its ``--python`` is a script
that makes a fake virtual environment whose ``pip install`` of the runtime fails on demand. Skipped where ``unshare``
cannot make such a namespace. The real ``/etc`` and system are never touched.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

_STUBS = {
    # the system user and groups: there already, as far as the script can tell
    "getent": "exit 0\n",
    "groupadd": "exit 0\n",
    "useradd": 'echo "useradd $*" >> "$FAKE_LOG"\n',
    # runs the command as the caller
    "runuser": 'while [ $# -gt 0 ] && [ "$1" != -- ]; do shift; done; shift; exec "$@"\n',
    "systemctl": 'echo "systemctl $*" >> "$FAKE_LOG"\n',
    "udevadm": 'echo "udevadm $*" >> "$FAKE_LOG"\n',
    # --python: a system interpreter that makes a fake environment
    "fakepython": ('case "$1" in\n'
                   '  -c) echo /usr ;;\n'
                   '  -m) [ "$2" = venv ] || exit 3\n'
                   '      mkdir -p "$3/bin"; cp "$FAKE_BIN/venv-python" "$3/bin/python"\n'
                   '      cp "$FAKE_BIN/venv-daemon" "$3/bin/ghnerf-daemon" ;;\n'
                   '  *) exit 3 ;;\n'
                   'esac\n'),
    "venv-python": ('echo "python $*" >> "$FAKE_LOG"\n'
                    'case "$*" in *"pip install"*" -c "*) [ -z "${FAKE_PIP_FAIL:-}" ] || exit 1 ;; esac\n'),
    # --validate-config reads the model card in the folder the config names, as the real check loads the
    # model there: a model whose version is $FAKE_UNSERVED cannot serve the config (exit 2, as the daemon's)
    "venv-daemon": ('echo "ghnerf-daemon $*" >> "$FAKE_LOG"\n'
                    'case "$*" in *--validate-config*)\n'
                    '  dir=$(sed -n \'s/.*"model_dir": *"\\([^"]*\\)".*/\\1/p\' /etc/ghnerf/daemon.json)\n'
                    '  if [ -n "${FAKE_UNSERVED:-}" ] && grep -qF "\\"version\\": \\"$FAKE_UNSERVED\\"" "$dir/model_card.json"; then\n'
                    '    echo "daemon.json: estimator.session: model $FAKE_UNSERVED in $dir cannot serve it" >&2; exit 2\n'
                    '  fi ;;\n'
                    'esac\n'),
}


def _can_unshare() -> bool:
    if shutil.which("unshare") is None:
        return False
    try:
        proc = subprocess.run(["unshare", "-rm", "sh", "-c", "mount --bind /tmp /etc && test ! -e /etc/passwd"],
                              capture_output=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return False
    return proc.returncode == 0


pytestmark = pytest.mark.skipif(not _can_unshare(), reason="unshare cannot make a mount namespace here")


class Host:
    """A fake checkout (``repo``), a prefix, a scratch ``/etc`` and the stand-ins' log."""

    def __init__(self, tmp: Path) -> None:
        self.repo = tmp / "repo"
        (self.repo / "systemd").mkdir(parents=True)
        for name in ("install.sh", "ghnerf.service", "60-ghnerf.rules", "61-ghnerf-local.rules", "daemon.json"):
            shutil.copy(REPO / "systemd" / name, self.repo / "systemd" / name)
        (self.repo / "docs").mkdir()
        (self.repo / "docs/daemon.md").write_text("# daemon\n")
        (self.repo / "constraints.txt").write_text("")
        self.set_model("v1")
        self.prefix = tmp / "prefix"
        self.etc = tmp / "etc"
        self.etc.mkdir()
        self.bin = tmp / "bin"
        self.bin.mkdir()
        for name, body in _STUBS.items():
            (self.bin / name).write_text("#!/bin/bash\n" + body)
            (self.bin / name).chmod(0o755)
        self.log = tmp / "log"

    def set_model(self, version: str) -> None:
        models = self.repo / "models"
        shutil.rmtree(models, ignore_errors=True)
        models.mkdir()
        (models / "model_card.json").write_text(json.dumps({"version": version}))
        (models / f"graph-{version}.onnx").write_text(version)

    def model(self) -> str:
        return json.loads((self.prefix / "models/model_card.json").read_text())["version"]

    def old_install(self, *venvs: str, live: str, model: str) -> None:
        """A prefix as an earlier install.sh left it: these environments, ``venv`` linked to ``live``."""
        for name in venvs:
            (self.prefix / name / "bin").mkdir(parents=True)
        (self.prefix / "venv").symlink_to(live)
        (self.prefix / "models").mkdir()
        (self.prefix / "models/model_card.json").write_text(json.dumps({"version": model}))

    def install(self, *args: str, pip_fails: bool = False, unserved: str = "") -> subprocess.CompletedProcess:
        """``unserved``: the model version the config cannot be served by (the fake daemon's check fails on it)."""
        env = {**os.environ, "PATH": f"{self.bin}:{os.environ['PATH']}", "FAKE_LOG": str(self.log),
               "FAKE_BIN": str(self.bin)}
        env.pop("FAKE_PIP_FAIL", None)
        env.pop("FAKE_UNSERVED", None)
        if pip_fails:
            env["FAKE_PIP_FAIL"] = "1"
        if unserved:
            env["FAKE_UNSERVED"] = unserved
        self.log.write_text("")
        script = 'mount --bind "$1" /etc && shift && exec bash "$@"'
        return subprocess.run(["unshare", "-rm", "bash", "-c", script, "_", str(self.etc),
                               str(self.repo / "systemd/install.sh"), "--prefix", str(self.prefix),
                               "--python", str(self.bin / "fakepython"), *args],
                              capture_output=True, text=True, env=env, timeout=120)

    def calls(self, *commands: str) -> list[str]:
        return [line for line in self.log.read_text().splitlines() if line.split()[0] in commands]


@pytest.fixture
def host(tmp_path) -> Host:
    return Host(tmp_path)


def test_installs_switches_the_link_and_starts_as_it_says(host):
    proc = host.install()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    live = os.readlink(host.prefix / "venv")
    assert live.startswith("venv-2") and (host.prefix / live / "bin/ghnerf-daemon").is_file()
    assert host.model() == "v1" and not (host.prefix / "models.new").exists()
    assert (host.etc / "ghnerf/daemon.json").is_file() and (host.etc / "systemd/system/ghnerf.service").is_file()
    assert "ghnerf-daemon --config /etc/ghnerf/daemon.json --validate-config" in host.calls("ghnerf-daemon")
    started = host.calls("systemctl", "udevadm")[:-1]  # the last: systemctl status
    # --no-start prints the same commands for the device
    printed = host.install("--no-start")
    assert printed.returncode == 0, printed.stdout + printed.stderr
    assert f"not started; on the device: {' && '.join(started)}\n" in printed.stdout
    assert "systemctl restart ghnerf.service" in started and "udevadm control --reload-rules" in started
    assert host.calls("systemctl", "udevadm") == []


def test_a_failed_build_keeps_the_old_models_beside_the_old_environment(host):
    host.old_install("venv-20200101T000000", live="venv-20200101T000000", model="v1")
    host.set_model("v2")
    proc = host.install(pip_fails=True)
    assert proc.returncode == 2 and "pip could not install the runtime" in proc.stderr, proc.stdout + proc.stderr
    assert os.readlink(host.prefix / "venv") == "venv-20200101T000000"
    assert host.model() == "v1"  # not the new model beside the old code
    assert sorted(p.name for p in host.prefix.iterdir() if p.name.startswith("venv")) == \
        ["venv", "venv-20200101T000000"]
    assert not (host.prefix / "models.new").exists()
    # once the build works, the new model and the new environment go in together
    proc = host.install("--no-start")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert host.model() == "v2" and os.readlink(host.prefix / "venv") != "venv-20200101T000000"
    assert not (host.prefix / "models/graph-v1.onnx").exists() and (host.prefix / "models/graph-v2.onnx").exists()


def test_a_config_the_new_models_cannot_serve_leaves_the_previous_install_in_place(host):
    """Review 52: the check ran once the new environment and models were in place, so its failure (exit 2,
    "fix it and run again") left them there, and the running service's next restart exited 2 and stayed down.
    The check now runs the new pair where the config will see it and puts the previous one back on failure."""
    host.old_install("venv-20200101T000000", live="venv-20200101T000000", model="v1")
    (host.prefix / "models/graph-v1.onnx").write_text("v1")
    (host.prefix / "docs").mkdir()
    (host.prefix / "docs/daemon.md").write_text("# old daemon\n")
    host.set_model("v2")
    proc = host.install(unserved="v2")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    # the check ran the new environment on the new models at the config's path ...
    (check,) = host.calls("ghnerf-daemon")
    assert check == "ghnerf-daemon --config /etc/ghnerf/daemon.json --validate-config"
    # ... and they are gone again: the previous pair is back, and nothing was started or reloaded
    assert os.readlink(host.prefix / "venv") == "venv-20200101T000000"
    assert host.model() == "v1" and (host.prefix / "models/graph-v1.onnx").exists()
    assert not (host.prefix / "models/graph-v2.onnx").exists()
    assert sorted(p.name for p in host.prefix.iterdir() if p.name.startswith(("venv", "models"))) == \
        ["models", "venv", "venv-20200101T000000"]
    assert (host.prefix / "docs/daemon.md").read_text() == "# old daemon\n"
    assert host.calls("systemctl", "udevadm") == []
    assert (host.etc / "ghnerf/daemon.json").is_file()  # the config to fix, written for the check
    assert "model v2" in proc.stderr and "does not validate with the new environment and models" in proc.stderr
    assert "the previous environment and models are kept" in proc.stderr
    # a model that serves it goes in, the previous environment kept for a rollback
    proc = host.install("--no-start")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert host.model() == "v2" and not (host.prefix / "models.old").exists()
    assert os.readlink(host.prefix / "venv") != "venv-20200101T000000"
    assert (host.prefix / "venv-20200101T000000").is_dir()
    assert (host.prefix / "docs/daemon.md").read_text() == "# daemon\n"


def test_the_environment_the_link_points_to_survives_a_new_install(host):
    """After a rollback by relinking to an older environment, a new install keeps that one (the one it
    replaces) and removes the others, whatever their names sort to."""
    olds = ["venv-20200101T000000", "venv-20210101T000000", "venv-20220101T000000"]
    host.old_install(*olds, live="venv-20200101T000000", model="v1")
    proc = host.install("--no-start")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    new = os.readlink(host.prefix / "venv")
    assert new not in olds
    assert sorted(p.name for p in host.prefix.iterdir() if p.name.startswith("venv-")) == \
        sorted(["venv-20200101T000000", new])


def test_the_service_user_joins_a_group_an_earlier_install_left(host):
    # the stand-in getent finds every group, ghnerf's own among them: --user-group would fail on it
    proc = host.install("--no-start")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (useradd,) = host.calls("useradd")
    assert "--gid ghnerf" in useradd and "--user-group" not in useradd
    (host.bin / "getent").write_text('#!/bin/bash\n[ "$2" != ghnerf ]\n')  # no group ghnerf yet
    proc = host.install("--no-start")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (useradd,) = host.calls("useradd")
    assert "--user-group" in useradd and "--gid" not in useradd


def test_models_from_a_private_checkout_are_readable_by_the_service(host):
    # a checkout cloned under umask 077: cp -R kept its owner-only modes, and the service user could not
    # read the graphs (--validate-config only listed them then; it loads them now, but here the daemon is a stand-in)
    for path in (host.repo / "models").iterdir():
        path.chmod(0o600)
    (host.repo / "models").chmod(0o700)
    (host.repo / "docs/daemon.md").chmod(0o600)
    proc = host.install("--no-start")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (host.prefix / "models").stat().st_mode & 0o055 == 0o055
    assert all(p.stat().st_mode & 0o044 == 0o044 for p in (host.prefix / "models").iterdir())
    assert (host.prefix / "docs/daemon.md").stat().st_mode & 0o044 == 0o044
