"""The parity checks cannot pass vacuously: a report that compared nothing, or a NaN / infinite int8 output that
no bound of its own covers, is refused naming the graph and output."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("torch")

from training.export.parity import ParityError, _stats, check_fp32_parity, check_int8_parity  # noqa: E402

OK = {"max_abs": 0.0, "mean_abs": 0.0, "ref_max": 1.0}


@pytest.mark.parametrize("check, report, what", [
    (check_fp32_parity, {}, r"^m/fp32 parity: no graph was compared"),
    (check_fp32_parity, {"encoder": {"feat_s1": OK}, "volume": {}}, r"^m/fp32 parity: no output of volume"),
    (check_int8_parity, {}, r"^m/int8 parity: no graph was compared"),
    (check_int8_parity, {"graphs": {}, "pipeline": {}}, r"^m/int8 parity: no graph was compared"),
    (check_int8_parity, {"graphs": {"human": {}}}, r"^m/int8 parity: no output of human"),
])
def test_a_check_that_compared_nothing_fails(check, report, what):
    """Each used to pass: every bound is a test of the figures present."""
    with pytest.raises(ParityError, match=what):
        check(report, "m/")


@pytest.mark.parametrize("graph, output", [
    ("encoder", "feat_s1"), ("volume", "volume"), ("render_heat", "acc"), ("render", "acc"), ("query", "joint_heat"),
])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_nan_or_infinite_int8_output_fails_whatever_its_bound(graph, output, bad):
    """NaN compares False with every bound, so ``not max_abs <= bound`` catches it only where a bound exists: an
    int8 encoder whose features were all NaN (with no pipeline in the report) passed."""
    shape = (2, 4, 8)
    report = {"graphs": {graph: {output: _stats(np.full(shape, bad, np.float32), np.zeros(shape, np.float32)),
                                 "other": OK}}}
    with pytest.raises(ParityError, match=rf"^m/{graph}\.int8\.onnx: its '{output}' differs from fp32 by (nan|inf)"):
        check_int8_parity(report, "m/")
    check_int8_parity({"graphs": {graph: {output: OK}}})  # a finite one within bounds passes
