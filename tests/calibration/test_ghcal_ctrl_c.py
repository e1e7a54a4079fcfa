"""``ghcal``: a Ctrl-C in a command that runs a while (synth, solve) exits 130 with a line, not a traceback."""
from __future__ import annotations

import pytest

from calibration import cli


def test_ctrl_c_in_synth_exits_130_without_a_traceback(tmp_path, capsys, monkeypatch):
    def views(*a, **k):  # the render: about half a minute for the default views
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "calibration_views", views)
    try:
        rc = cli.main(["synth", "--out", str(tmp_path / "synth")])
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C escaped ghcal: the user saw a traceback")
    assert rc == 130 and "ghcal: stopped (Ctrl-C); the synth did not finish" in capsys.readouterr().err
    assert not (tmp_path / "synth").exists()
