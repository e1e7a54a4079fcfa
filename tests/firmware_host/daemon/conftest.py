"""The daemon's tests keep their files under pytest's tmp folder (in /tmp) and read the checkout's models
(which may lie under /home: a CI runner's checkout): to ``firmware_host.daemon.sandbox`` all of that is hidden
from the installed service, so ``--validate-config`` would warn of it and, under systemd (a CI runner's service
sets ``INVOCATION_ID``), the errors would carry its advice. Only ``test_daemon_sandbox.py`` wants those; every
other test sees a daemon that hides nothing and runs outside systemd."""
from __future__ import annotations

import pytest

from firmware_host.daemon import sandbox


@pytest.fixture(autouse=True)
def _no_sandbox_hints_unless_asked(request, monkeypatch):
    monkeypatch.delenv("INVOCATION_ID", raising=False)
    if request.module.__name__.rsplit(".", 1)[-1] != "test_daemon_sandbox":
        monkeypatch.setattr(sandbox, "HOME_FOLDERS", ())
        monkeypatch.setattr(sandbox, "PRIVATE_TMP_FOLDERS", ())
