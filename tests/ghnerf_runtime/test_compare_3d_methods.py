"""The 3D-method comparison script runs end to end on the oracle session (no model)."""
import json
import sys
from pathlib import Path

import pytest

pytest.importorskip("drivers.sim")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def test_reprojection_gates_add_triangulate_rows_and_a_tighter_gate_finds_no_more(tmp_path):
    from benchmarks import compare_3d_methods

    out = tmp_path / "cmp.json"
    assert compare_3d_methods.main(["--oracle", "--sequences", "1", "--frames", "3", "--methods", "triangulate",
                                    "--reprojection-gates", "1e-9,8", "--cache", str(tmp_path / "cache"),
                                    "--json", str(out)]) == 0
    rows = {r["method"]: r for r in json.loads(out.read_text())["rows"]}
    assert list(rows) == ["triangulate", "triangulate, gate 1e-09 px", "triangulate, gate 8 px"]
    # the oracle reprojects to float rounding: a 1e-9 px gate drops joints, the 8 px gate none
    assert rows["triangulate, gate 1e-09 px"]["found"] < rows["triangulate, gate 8 px"]["found"]
    assert rows["triangulate, gate 8 px"]["found"] == rows["triangulate"]["found"] > 0
    # split by the cameras that see each joint: the oracle draws a joint only where a camera sees it,
    # so joints no camera sees are never found, and the ones found sit at the truth
    by = rows["triangulate"]["by_visibility"]
    assert by["all_views"]["found"] > 0.9 and by["all_views"]["mpjpe_mm"] < 5.0
    assert by["no_view"]["found"] == 0.0
    with pytest.raises(SystemExit):
        compare_3d_methods.main(["--oracle", "--methods", "nope", "--cache", str(tmp_path / "cache")])
