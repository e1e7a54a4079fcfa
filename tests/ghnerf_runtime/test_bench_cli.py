"""``ghnerf-bench runtime``'s argument errors and Ctrl-C, without a model or a rendered sequence."""
from __future__ import annotations

import pytest

from ghnerf_runtime.cli import bench, simdata


@pytest.fixture
def no_render(monkeypatch):
    """Fails the test if the bench renders (or loads) its sequences: minutes on a cold cache."""
    def load_sequences(*args, **kwargs):
        raise AssertionError("the sequences were rendered before the error was found")

    monkeypatch.setattr(simdata, "load_sequences", load_sequences)


@pytest.mark.parametrize(("extra", "words"), [
    (["--model-dir", "NOWHERE"], "model folder does not exist"),
    (["--threads", "0"], "SessionConfig.threads: must be an integer in [1, 64], got 0"),
    # checked as its rows are built, after the model folder's graphs load (the shipped models/)
    (["--novel-interior-strides", "3"], "NovelViewConfig.interior_stride: must be one of"),
])
def test_a_model_or_config_error_is_said_before_the_sequences_are_rendered(tmp_path, capsys, no_render, extra,
                                                                            words):
    extra = [str(tmp_path / a) if a == "NOWHERE" else a for a in extra]
    rc = bench.main(["runtime", "--sequences", "1", "--frames", "2", "--warmup", "0", "--cache", "off",
                     "--precisions", "fp32", *extra])
    assert rc == 2
    assert words in capsys.readouterr().err


def test_ctrl_c_exits_130_without_a_traceback_or_a_report(tmp_path, capsys, monkeypatch):
    def interrupted(cfg):
        raise KeyboardInterrupt

    monkeypatch.setattr(bench, "load_session", interrupted)
    try:
        rc = bench.main(["runtime", "--sequences", "1", "--frames", "2", "--warmup", "0", "--cache", "off",
                         "--json", str(tmp_path / "r.json")])
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C escaped ghnerf-bench: the user saw a traceback")
    assert rc == 130 and "stopped (Ctrl-C)" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()


def test_a_cache_that_is_a_file_is_named_before_anything_runs(tmp_path, capsys, no_render, monkeypatch):
    monkeypatch.setattr(bench, "load_session", lambda cfg: pytest.fail("the model was loaded"))
    (tmp_path / "afile").write_text("")
    rc = bench.main(["runtime", "--sequences", "1", "--frames", "2", "--warmup", "0",
                     "--cache", str(tmp_path / "afile")])
    # was "[Errno 20] Not a directory: '<it>/seq-...'" after the model had loaded, naming no flag
    assert rc == 2 and f"--cache {tmp_path / 'afile'}: is a file; give a folder" in capsys.readouterr().err
