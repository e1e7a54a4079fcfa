"""Vendor telemetry off by default: depthai's and onnxruntime's switches, set before each library's first import.

Each check runs in a fresh interpreter whose environment lacks the switches (this suite's conftest sets them in
its own process) and whose HOME and XDG_CACHE_HOME are an empty folder, where the libraries keep their ids.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from ghnerf_runtime.vendor_telemetry import DEPTHAI_OFF, DEPTHAI_SWITCH, ONNXRUNTIME_OFF, ONNXRUNTIME_SWITCH

REPO = Path(__file__).resolve().parents[1]

# Records the switch's value at the moment ``depthai`` or ``onnxruntime`` is first looked for, then lets the
# import go on; prints {library: value at import, "after_<switch>": value after}.
_AT_IMPORT = """
import importlib.abc, json, os, sys
seen = {}
class Recorder(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name in ("depthai", "onnxruntime") and name not in seen:
            seen[name] = os.environ.get(%(switch)r)
        return None
sys.meta_path.insert(0, Recorder())
%(code)s
print(json.dumps({"at_import": seen.get(%(library)r), "after": os.environ.get(%(switch)r)}))
"""


def _run(code: str, home: Path, **switches: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in (DEPTHAI_SWITCH, ONNXRUNTIME_SWITCH)}
    env.update(HOME=str(home), XDG_CACHE_HOME=str(home / ".cache"), PYTHONPATH=str(REPO), **switches)
    # generous: importing depthai and onnxruntime takes seconds on a loaded host
    return subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=300, check=True)


def _switch_at_import(module: str, library: str, switch: str, home: Path, **switches: str) -> dict:
    code = _AT_IMPORT % {"switch": switch, "library": library, "code": f"import {module}\nimport {library}"}
    return json.loads(_run(code, home, **switches).stdout.splitlines()[-1])


def _files_under(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


def test_the_unit_file_switches_both_off():
    text = (REPO / "systemd" / "ghnerf.service").read_text()
    assignments = [a for line in re.findall(r"^Environment=(.*)$", text, flags=re.M) for a in line.split()]
    assert f"{DEPTHAI_SWITCH}={DEPTHAI_OFF}" in assignments
    assert f"{ONNXRUNTIME_SWITCH}={ONNXRUNTIME_OFF}" in assignments


def test_the_depthai_backend_switches_depthai_off_before_importing_it(tmp_path):
    pytest.importorskip("depthai")
    seen = _switch_at_import("drivers.backends.depthai", "depthai", DEPTHAI_SWITCH, tmp_path)
    assert seen == {"at_import": DEPTHAI_OFF, "after": DEPTHAI_OFF}


def test_the_depthai_backend_keeps_the_users_own_value(tmp_path):
    pytest.importorskip("depthai")
    seen = _switch_at_import("drivers.backends.depthai", "depthai", DEPTHAI_SWITCH, tmp_path,
                             **{DEPTHAI_SWITCH: "1"})
    assert seen == {"at_import": "1", "after": "1"}


def test_the_runtime_switches_onnxruntime_off_before_importing_it(tmp_path):
    seen = _switch_at_import("ghnerf_runtime.session", "onnxruntime", ONNXRUNTIME_SWITCH, tmp_path)
    assert seen == {"at_import": ONNXRUNTIME_OFF, "after": ONNXRUNTIME_OFF}


def test_the_runtime_keeps_the_users_own_onnxruntime_value(tmp_path):
    seen = _switch_at_import("ghnerf_runtime.session", "onnxruntime", ONNXRUNTIME_SWITCH, tmp_path,
                             **{ONNXRUNTIME_SWITCH: "0"})
    assert seen == {"at_import": "0", "after": "0"}


def test_no_depthai_telemetry_id_is_written(tmp_path):
    # depthai 3.12 writes .cache/depthai/telemetry/tmpIds.json on import with telemetry on (and tries to upload);
    # with it off it makes the empty folder only. A host-only pipeline: no device here.
    pytest.importorskip("depthai")
    _run("import drivers.backends.depthai, depthai\ndepthai.Pipeline(False).create(depthai.node.Sync)", tmp_path)
    assert _files_under(tmp_path) == []


def test_no_onnxruntime_device_id_is_written(tmp_path):
    # onnxruntime 1.31 writes .cache/Microsoft/DeveloperTools/.onnxruntime/deviceid and onnxruntime.db on import
    _run("import ghnerf_runtime.session, onnxruntime\nonnxruntime.get_available_providers()", tmp_path)
    assert _files_under(tmp_path) == []
