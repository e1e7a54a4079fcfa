"""``benchmarks/measure_import_common_view.py``: the command docs/rig-file.md names beside its common-view figures
keeps running, and its rows say what the docs say of them (the real rigs above the warning's share, the 0.6 m pair
on 80 mm squares read as metres below it)."""
from __future__ import annotations

import runpy

from tests.benchmarks.test_bench_smoke import BENCH, run_script


def _shares(out: str, row: str) -> list[float]:
    """The row's shares (the cells after its name and baseline; '-' where none)."""
    line = next(line for line in out.splitlines() if line.startswith(f"| {row} |"))
    return [float(cell) for cell in line.strip("| ").split(" | ")[2:] if cell != "-"]


def test_the_real_rigs_pass_and_the_squares_read_as_metres_do_not(capsys, monkeypatch):
    from calibration.common_view import MIN_COMMON_SHARE

    out = run_script("measure_import_common_view", "--placements", "5", capsys=capsys, monkeypatch=monkeypatch)
    for row in ("docs/examples/rig.json", "ghcal synth's rig", "ghcal synth's rig until session 68", "simulator default",
                "5 training placements (least)"):
        assert min(_shares(out, row)) > 2 * MIN_COMMON_SHARE, row
    for row in ("ghcal synth's rig, 80 mm", "ghcal synth's rig until session 68, 80 mm"):
        assert max(_shares(out, row)) < MIN_COMMON_SHARE, row
    assert "| simulator default, 80 mm | 15.00 | refused (over 10 m) |" in out


def test_ghcal_synth_s_row_is_the_rig_it_films(capsys, monkeypatch):
    """The row named "ghcal synth's rig" is calibration.render.synth_rig (since session 68), and example_rig, the one it
    filmed before, has a row of its own saying so."""
    from calibration.render import example_rig, synth_rig

    script = runpy.run_path(str(BENCH / "measure_import_common_view.py"))
    expected = [script["shares_line"]("ghcal synth's rig", synth_rig()),
                script["shares_line"]("ghcal synth's rig until session 68", example_rig())]
    out = run_script("measure_import_common_view", "--placements", "5", capsys=capsys, monkeypatch=monkeypatch)
    assert [line for line in expected if line not in out.splitlines()] == []
