"""``benchmarks/measure_cold_tiles.py``: its command line runs and prints both configs and their ratios (the tiny test
export, random weights: the figures mean nothing)."""
from __future__ import annotations

from benchmarks.measure_cold_tiles import longest_run
from tests.benchmarks.test_bench_smoke import run_script, scratch_cache  # noqa: F401
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)


def test_the_command_line_runs(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    out = run_script("measure_cold_tiles", "--model-dir", str(tiny_model_dir), "--precision", "fp32",
                     "--sequences", "1", "--frames", "2", "--rooms", "1", "--pairs", "2",
                     "--rigs", "docs/examples/rig.json", capsys=capsys, monkeypatch=monkeypatch)
    rows = [line for line in out.splitlines() if line.startswith("| docs/examples/rig.json |")]
    assert [r.split("|")[2].strip() for r in rows] == [
        "tiles, rest every 4 (default)", "tiles, no rest", "no tiles",
        "ratio, tiles, rest every 4 / no tiles", "ratio, tiles, no rest / no tiles"], out
    # the example rig's cold crop draws a person at 0.40 of its side: every empty-room pair searches a tile (two pairs:
    # not yet a whole round of four tiles, so the default does not rest)
    assert rows[0].rstrip(" |").endswith("/ 2") and rows[1].rstrip(" |").endswith("/ 2"), out
    assert rows[2].rstrip(" |").endswith("0 / 0"), out
    assert all(" of 2 | " in r for r in rows[:3]), out


def test_a_person_walking_in_is_counted_from_their_first_pair(tiny_model_dir, scratch_cache, capsys,  # noqa: F811
                                                             monkeypatch):
    out = run_script("measure_cold_tiles", "--model-dir", str(tiny_model_dir), "--precision", "fp32",
                     "--sequences", "1", "--frames", "2", "--rooms", "1", "--pairs", "1", "--walk-in-after", "5",
                     "--rigs", "docs/examples/rig.json", capsys=capsys, monkeypatch=monkeypatch)
    rows = [line for line in out.splitlines() if line.startswith("| docs/examples/rig.json |")]
    assert "after 5 empty" in out, out
    # all seven pairs timed (cold here), the share with no joint and the pairs until found of the person's two only
    assert all(r.split("|")[3].strip() == "7" for r in rows[:3]), out
    assert all(float(r.split("|")[6]) in (0.0, 0.5, 1.0) for r in rows[:3]), out
    assert all(r.split("|")[7].split()[0] in ("0", "1", "2") for r in rows[:3]), out


def test_the_walk_in_sweep_meets_every_phase_of_the_rest(tiny_model_dir, scratch_cache, capsys,  # noqa: F811
                                                         monkeypatch):
    out = run_script("measure_cold_tiles", "--model-dir", str(tiny_model_dir), "--precision", "fp32",
                     "--sequences", "1", "--frames", "2", "--rest-every", "2", "--walk-in-sweep",
                     "--rigs", "docs/examples/rig.json", capsys=capsys, monkeypatch=monkeypatch)
    rows = [line.split("|")[1:-1] for line in out.splitlines() if line.startswith("| docs/examples/rig.json |")]
    assert [r[1].strip() for r in rows] == ["rest every 2, no wake-up", "rest every 2, wake-up at 6 levels",
                                            "no tiles"], out
    # a whole cycle of the rest: 2 pairs a tile pass x 4 tiles, the walk-in after 4 to 11 empty pairs
    assert all(r[2].strip() == "8" for r in rows), out
    assert all(r[10].split()[0].isdigit() for r in rows), out  # the false wakes (of the resting pairs)
    assert rows[2][10].strip() == "0 (0)" and rows[2][9].strip() == "1.00", out


def test_the_wake_margin_prints_empty_rooms_and_walk_ins(capsys, monkeypatch):
    """No model run: the statistic of the bench rooms' pairs and of their people's first pairs."""
    out = run_script("measure_cold_tiles", "--wake-margin", "--sequences", "2", "--pairs", "3",
                     "--rigs", "docs/examples/rig.json", capsys=capsys, monkeypatch=monkeypatch)
    rows = [line.split("|")[1:-1] for line in out.splitlines() if line.startswith("| docs/examples/rig.json |")]
    assert [r[1].strip() for r in rows] == ["empty rooms", "walk-ins"], out
    assert rows[0][2].strip() == "4" and rows[1][2].strip() == "2", out  # 2 rooms x 2 pairs after the first; 2 people
    assert rows[0][8].strip() == "0 of 4" and len(rows[1][9].split(",")) == 2, out  # noise wakes nothing


def test_the_moving_room_counts_wakes_after_the_first_round(tiny_model_dir, scratch_cache, capsys,  # noqa: F811
                                                          monkeypatch):
    out = run_script("measure_cold_tiles", "--model-dir", str(tiny_model_dir), "--precision", "fp32",
                     "--moving-room", "--sequences", "1", "--pairs", "6",
                     "--rigs", "docs/examples/rig.json", capsys=capsys, monkeypatch=monkeypatch)
    rows = [line.split("|")[1:-1] for line in out.splitlines() if line.startswith("| docs/examples/rig.json |")]
    assert [r[1].strip() for r in rows] == ["tiles, no rest", "rest every 4, no wake-up",
                                            "rest every 4, wake-up at 6 levels", "no tiles"], out
    assert all(r[2].strip() == "2" for r in rows), out  # 6 pairs, the first round of four tiles left out
    assert rows[0][4].strip() == "0" and rows[1][4].strip() == "0" and rows[3][4].strip() == "0", out
    assert rows[3][3].strip() == "0" and rows[3][7].strip() == "1.00", out
    assert all(len(r[5].split("/")) == 2 for r in rows), out  # seen in one view / a frame rejected
    assert all(0 <= int(r[9]) <= 6 for r in rows), out  # the most pairs in a row seen in one view, of 6


def test_the_longest_run_counts_true_values_in_a_row():
    assert longest_run([]) == 0 and longest_run([False, False]) == 0
    assert longest_run([True, False, True, True, False, True]) == 2
    assert longest_run([False, True, True, True]) == 3
