"""ModelSession: loading, contract checks (refusing mismatched or corrupt models), warm-up, runs.

The model is the ``tiny`` preset exported once per test session by the real export CLI
(``python -m training.export``, random weights); the tests skip when torch is missing.
``tiny_model_dir`` is imported by the estimator and CLI tests too.
"""
from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ghnerf_runtime.config import SessionConfig
from ghnerf_runtime.contract import GRAPH_NAMES, ModelContract
from ghnerf_runtime.errors import ModelContractError, ModelError, ModelLoadError, ModelRunError, RuntimeErrorBase
from ghnerf_runtime.session import ModelSession, warmup_feeds

REPO = Path(__file__).resolve().parents[2]
_EXPORTED: dict[str, Path] = {}


def export_tiny(base: Path) -> Path:
    """Export the ``tiny`` preset (fp32, every graph) once per test session."""
    if "tiny" in _EXPORTED:
        return _EXPORTED["tiny"]
    if importlib.util.find_spec("torch") is None:
        pytest.skip("torch is not installed: the tiny test model cannot be exported")
    out = base / "tiny"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-m", "training.export", "--preset", "tiny", "--out", str(out)],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"export failed:\n{proc.stderr[-3000:]}"
    _EXPORTED["tiny"] = out
    return out


@pytest.fixture(scope="session")
def tiny_model_dir(tmp_path_factory) -> Path:
    return export_tiny(tmp_path_factory.mktemp("ghnerf-model"))


@pytest.fixture(scope="module")
def tiny_session(tiny_model_dir) -> ModelSession:
    return ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir)), GRAPH_NAMES)


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def _edit_metadata(path: Path, edit) -> None:
    """Rewrite a file's metadata_props through ``edit(dict) -> dict`` (onnx, a dev dependency)."""
    onnx = pytest.importorskip("onnx")
    model = onnx.load(str(path))
    props = edit({p.key: p.value for p in model.metadata_props})
    del model.metadata_props[:]
    onnx.helper.set_model_props(model, props)
    onnx.save(model, str(path))


def _load_encoder(folder: Path, **kw) -> ModelSession:
    return ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False, **kw), ("encoder",))


# --------------------------------------------------------------------------- loading
def test_load_checks_contract_and_warms_up(tiny_session):
    s = tiny_session
    assert s.graphs == GRAPH_NAMES
    assert (s.contract.height, s.contract.width) == (64, 64)
    assert set(s.warmup_ms) == set(GRAPH_NAMES) and all(v > 0 for v in s.warmup_ms.values())
    assert all(n == 0 for n in s.run_counts.values()), "warm-up runs must not count as work"
    d = s.describe()
    assert d["resolution"] == "64x64" and set(d["files"]) == set(GRAPH_NAMES)


def test_run_returns_contract_shapes_and_counts(tiny_session):
    feeds = warmup_feeds(tiny_session.contract)
    out = tiny_session.run("encoder", feeds)
    spec = tiny_session.contract.graph("encoder")
    assert list(out) == list(spec.output_names)
    for t in spec.outputs:
        assert out[t.name].shape == tuple(t.shape) and out[t.name].dtype == np.float32
    assert tiny_session.run_counts["encoder"] == 1
    tiny_session.reset_counts()


def test_run_both_side_by_side_answers_as_two_runs(tiny_model_dir):
    """open_lane / run_both: the two feeds run side by side, one thread each, and answer exactly what two runs
    in turn answer; with one thread per session there is nothing to run beside: in turn."""
    s = ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir), threads=2), ("human",))
    feeds = warmup_feeds(s.contract)
    mirrored = {"images": np.ascontiguousarray(feeds["images"][..., ::-1])}
    apart = s.run("human", feeds), s.run("human", mirrored)
    assert s.open_lane("human") and s.open_lane("human")  # idempotent
    s.reset_counts()
    both = s.run_both("human", feeds, mirrored)
    assert s.run_counts["human"] == 2
    for one, other in zip(apart, both):
        assert set(one) == set(other) and all(np.array_equal(one[k], other[k]) for k in one)
    with pytest.raises(ModelError, match="needs input 'images'"):
        s.run_both("human", feeds, {})
    # (the global pool, process-wide once installed, is not tried here: it would refuse every later session)
    alone = ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir), warmup=False, threads=1), ("human",))
    assert not alone.open_lane("human")
    in_turn = alone.run_both("human", feeds, mirrored)
    assert all(np.array_equal(in_turn[i][k], apart[i][k]) for i in (0, 1) for k in apart[i])
    assert not s.open_lane("encoder")  # not loaded


def test_novel_view_graphs_run_on_lanes_with_the_same_numbers(tiny_model_dir):
    """open_lane / run_on_lane for the novel view's graphs (the estimator's worker renders on them beside the
    keypoint stages): a lane opens for ``volume`` and ``render_rgb`` (their first run reads the encoder's and the
    volume's outputs at one target) and answers what the two-thread sessions answer, to float rounding (this
    fp32 model's sums may split differently over one thread or two; the shipped model's answers are the same
    bits: test_estimator_accuracy); a graph without a lane runs on its session; the runs are counted, and the
    lanes' warm-up runs are not."""
    s = ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir), threads=2),
                          ("encoder", "volume", "render_rgb"))
    feeds = warmup_feeds(s.contract, targets=1, ray_stride=2)
    feeds.update(s.run("encoder", feeds))
    volume = s.run("volume", feeds)
    rgb = s.run("render_rgb", {**feeds, **volume})
    assert s.open_lane("volume") and s.open_lane("render_rgb")
    assert s.run_counts == {"encoder": 1, "volume": 1, "render_rgb": 1}
    lanes = s.on_lanes()
    assert lanes.contract is s.contract and lanes.has("volume") and not lanes.has("render")
    on_lane = lanes.run("volume", feeds)
    assert set(on_lane) == set(volume)
    for k in volume:
        np.testing.assert_allclose(on_lane[k], volume[k], rtol=1e-5, atol=1e-6 * np.abs(volume[k]).max())
    on_lane = lanes.run("render_rgb", {**feeds, **volume})
    assert set(on_lane) == set(rgb)
    for k in rgb:
        np.testing.assert_allclose(on_lane[k], rgb[k], rtol=1e-5, atol=1e-6)
    no_lane, own = lanes.run("encoder", feeds), s.run("encoder", feeds)  # no lane: the session itself
    assert all(np.array_equal(no_lane[k], v) for k, v in own.items())
    assert s.run_counts == {"encoder": 3, "volume": 2, "render_rgb": 2}
    with pytest.raises(ModelError, match="needs input 'ray_uv'"):
        lanes.run("render_rgb", {k: v for k, v in {**feeds, **volume}.items() if k != "ray_uv"})


def test_run_unknown_graph_and_missing_input(tiny_model_dir):
    s = _load_encoder(tiny_model_dir)
    with pytest.raises(ModelError, match="not loaded"):
        s.run("volume", {})
    with pytest.raises(ModelError, match="needs input 'images'"):
        s.run("encoder", {})


def test_a_graph_failing_inside_says_why_once_without_onnxruntime_s_own_log(tiny_model_dir, capfd):
    """A node failing mid-run (one target's volume for two targets' rays) also put onnxruntime's own line on
    stderr, ANSI-coloured with its C++ source location, beside the ModelRunError; the error kept the source
    location and the template signature before the reason."""
    graphs = ("encoder", "volume", "render_heat")
    s = ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir), warmup=False), graphs)
    feeds = warmup_feeds(s.contract)
    feeds.update(s.run("encoder", feeds))
    feeds.update(s.run("volume", feeds))
    feeds["volume"] = feeds["volume"][:1]
    capfd.readouterr()
    with pytest.raises(ModelRunError) as e:
        s.run("render_heat", feeds)
    assert e.value.path == str(tiny_model_dir / "render_heat.onnx") and "graph 'render_heat' failed" in str(e.value)
    assert "batch size" in str(e.value)  # onnxruntime's reason, at the end of its message
    assert ".cc:" not in str(e.value) and "[with T" not in str(e.value) and "::" not in str(e.value)
    assert "onnxruntime" not in capfd.readouterr().err


def test_loads_only_requested_graphs_and_int8_falls_back_to_fp32(tiny_model_dir):
    s = ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir), precision="int8", warmup=False),
                          ("encoder", "volume"))
    assert s.graphs == ("encoder", "volume")
    assert s.files["encoder"].path.name == "encoder.onnx"  # the tiny export has no int8 files


def test_int8_asked_for_by_name_and_run_in_fp32_is_said(tiny_model_dir, caplog):
    """`ghnerf-run --precision int8` on a folder without int8 files ran fp32 without a word (INFO only), and its
    timings were taken for int8's. ``auto`` takes what the folder has: no warning."""
    import logging

    with caplog.at_level(logging.WARNING, logger="ghnerf_runtime.session"):
        ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir), precision="int8", warmup=False),
                          ("encoder", "volume"))
    assert "int8 was asked for" in caplog.text and "running the fp32 encoder.onnx, volume.onnx" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="ghnerf_runtime.session"):
        ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir), precision="auto", warmup=False),
                          ("encoder", "volume"))
    assert "int8 was asked for" not in caplog.text


def test_int8_file_is_preferred_when_present(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    shutil.copy(folder / "encoder.onnx", folder / "encoder.int8.onnx")
    assert _load_encoder(folder, precision="int8").files["encoder"].path.name == "encoder.int8.onnx"
    assert _load_encoder(folder, precision="fp32").files["encoder"].path.name == "encoder.onnx"
    assert _load_encoder(folder, precision="fp32", precision_overrides={"encoder": "int8"}).files[
        "encoder"].path.name == "encoder.int8.onnx"


def _int8_twin(folder: Path, graph: str, weights_id: str | None, age_s: float) -> Path:
    """``graph``'s fp32 file copied as its int8 file with ``weights_id`` (``""``: none; None: none in either file),
    ``age_s`` seconds older than the fp32 file (negative: newer)."""
    fp32, int8 = folder / f"{graph}.onnx", folder / f"{graph}.int8.onnx"
    if weights_id is None:
        _edit_metadata(fp32, lambda p: {k: v for k, v in p.items() if k != "ghnerf.weights_id"})
    shutil.copy(fp32, int8)
    _edit_metadata(int8, lambda p: {**{k: v for k, v in p.items() if k != "ghnerf.weights_id"}, "ghnerf.precision":
                                    "int8", **({"ghnerf.weights_id": weights_id} if weights_id else {})})
    now = fp32.stat().st_mtime
    os.utime(int8, (now - age_s, now - age_s))
    return int8


def _stale_warnings(caplog) -> list[str]:
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    return [m for m in said if "not quantized from" in m]


@pytest.mark.parametrize("precision", ["auto", "int8"])
def test_an_int8_file_of_other_weights_than_the_fp32_beside_it_is_not_run(tiny_model_dir, tmp_path, caplog,
                                                                          precision):
    """A folder exported before session 73 keeps the int8 file of a graph an export replaced, and the runtime ran it
    (the stale weights, or a load refused for two weights ids): its weights id, which the quantizer copies from the
    fp32 file, differs from the fp32 file's. The fp32 file runs, said once naming both and the fix; the times do
    not count where the ids say (the stale file here is the newer)."""
    import logging

    folder = _copy(tiny_model_dir, tmp_path / "m")
    own = ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False), ("encoder",)).weights_id
    assert own is not None  # the export stamps one
    _int8_twin(folder, "encoder", "f" * 64, age_s=-3600.0)
    with caplog.at_level(logging.WARNING):
        s = _load_encoder(folder, precision=precision)
    assert s.files["encoder"].path.name == "encoder.onnx" and s.files["encoder"].precision == "fp32"
    [said] = _stale_warnings(caplog)
    assert "encoder.int8.onnx is not quantized from encoder.onnx (its weights id differs" in said
    assert f"python -m training.export --checkpoint CHECKPOINT.pt --out {folder} --int8" in said
    assert "int8 was asked for" not in caplog.text  # the stale file is the reason, said once
    caplog.clear()
    _int8_twin(folder, "encoder", "", age_s=-3600.0)  # no id beside an fp32 file with one: quantized before ids
    with caplog.at_level(logging.WARNING):
        assert _load_encoder(folder, precision=precision).files["encoder"].path.name == "encoder.onnx"
    assert "(its weights id differs from encoder.onnx's)" in _stale_warnings(caplog)[0]
    caplog.clear()
    _int8_twin(folder, "encoder", own, age_s=30 * 86400.0)  # its own weights, however old its time
    with caplog.at_level(logging.WARNING):
        assert _load_encoder(folder, precision=precision).files["encoder"].path.name == "encoder.int8.onnx"
    assert not _stale_warnings(caplog)


def test_a_stale_int8_file_is_judged_before_onnxruntime_opens_it(tiny_model_dir, tmp_path, monkeypatch):
    """The stale-int8 check reads both files' metadata, so onnxruntime opens only the file that runs: it opened the
    int8 file too, for its weights id, and threw the session away (an encoder's load, counted in ``load_ms``)."""
    import ghnerf_runtime.session as session_module

    folder = _copy(tiny_model_dir, tmp_path / "m")
    _int8_twin(folder, "encoder", "f" * 64, age_s=-3600.0)
    opened, real_open = [], session_module._open
    monkeypatch.setattr(session_module, "_open", lambda path, config: opened.append(path.name) or real_open(path,
                                                                                                           config))
    assert _load_encoder(folder).files["encoder"].path.name == "encoder.onnx"
    assert opened == ["encoder.onnx"]


def test_onnx_metadata_reads_what_onnxruntime_reads_and_names_a_cut_file(tiny_model_dir, tmp_path):
    """The stale-int8 check reads the fp32 file's metadata from its protobuf fields, not through an onnxruntime
    session (milliseconds, not a second of a daemon's start for the two encoders): the same keys and values."""
    import onnxruntime as ort

    from ghnerf_runtime.onnx_file import onnx_metadata

    files = sorted(tiny_model_dir.glob("*.onnx")) + sorted((REPO / "models" / "ghnerf").glob("*.onnx"))[:4]
    for path in files:
        want = dict(ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).get_modelmeta()
                    .custom_metadata_map)
        assert want and onnx_metadata(path, "graph") == want, path
    cut = tmp_path / "cut.onnx"
    cut.write_bytes(files[0].read_bytes()[:-7])
    with pytest.raises(ModelLoadError, match=r"cut\.onnx: the graph file is no ONNX model \(truncated"):
        onnx_metadata(cut, "graph")
    with pytest.raises(ModelLoadError, match=r"none\.onnx: cannot read the graph file: No such file"):
        onnx_metadata(tmp_path / "none.onnx", "graph")
    text = tmp_path / "text.onnx"
    text.write_text("not a model at all\n")
    with pytest.raises(ModelLoadError, match=r"text\.onnx: the graph file is no ONNX model \(truncated"):
        onnx_metadata(text, "graph")
    bad_key = tmp_path / "bad_key.onnx"  # field 14, an entry whose key (1) is the bytes ff fe: no UTF-8 string
    bad_key.write_bytes(bytes([14 << 3 | 2, 6, 1 << 3 | 2, 2, 0xFF, 0xFE, 2 << 3 | 2, 0]))
    with pytest.raises(ModelLoadError, match=r"bad_key\.onnx: the graph file is no ONNX model \(truncated"):
        onnx_metadata(bad_key, "graph")


def test_an_int8_file_without_a_weights_id_is_judged_by_its_time(tiny_model_dir, tmp_path, caplog):
    """Files exported before weights ids: an int8 file older than the fp32 one by more than STALE_INT8_AGE_S was
    quantized from an earlier one; older by the seconds a copy or a git checkout puts between them, it is taken."""
    import logging

    folder = _copy(tiny_model_dir, tmp_path / "m")
    _int8_twin(folder, "encoder", None, age_s=2 * 86400.0)  # an export two days before the fp32 file's
    with caplog.at_level(logging.WARNING):
        assert _load_encoder(folder).files["encoder"].path.name == "encoder.onnx"
    [said] = _stale_warnings(caplog)
    assert "encoder.int8.onnx is not quantized from encoder.onnx (it records no link to encoder.onnx and is 48.0 h " \
           "older)" in said
    caplog.clear()
    _int8_twin(folder, "encoder", None, age_s=5.0)
    with caplog.at_level(logging.WARNING):
        assert _load_encoder(folder).files["encoder"].path.name == "encoder.int8.onnx"
    assert not _stale_warnings(caplog)


def _record_fp32_sha256(int8: Path, digest: str) -> None:
    """``int8`` with ``digest`` as the fp32 file's sha256 the quantizer records, its time kept."""
    times = (int8.stat().st_atime, int8.stat().st_mtime)
    _edit_metadata(int8, lambda p: {**p, "ghnerf.fp32_sha256": digest})
    os.utime(int8, times)


def _sha256(path: Path) -> str:
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_the_fp32_files_sha256_an_int8_file_records_decides_before_ids_and_times(tiny_model_dir, tmp_path, caplog):
    """The quantizer records the sha256 of the fp32 file it quantized (``ghnerf.fp32_sha256``): the same bytes
    beside it take the int8 file however much older its time (the shipped files record no weights id, and a pull
    that rewrote only a ``<graph>.onnx`` was judged by times a checkout sets); other bytes give the fp32 file, said
    naming both, where the weights ids agree and the int8 file is the newer."""
    import logging

    folder = _copy(tiny_model_dir, tmp_path / "m")
    int8 = _int8_twin(folder, "encoder", None, age_s=2 * 86400.0)  # the times alone say stale
    _record_fp32_sha256(int8, _sha256(folder / "encoder.onnx"))
    with caplog.at_level(logging.WARNING):
        assert _load_encoder(folder).files["encoder"].path.name == "encoder.int8.onnx"
    assert not _stale_warnings(caplog)

    folder = _copy(tiny_model_dir, tmp_path / "m2")
    own = ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False), ("encoder",)).weights_id
    int8 = _int8_twin(folder, "encoder", own, age_s=-3600.0)  # the ids and the times say fresh
    quantized_from = _sha256(folder / "encoder.onnx")
    _record_fp32_sha256(int8, quantized_from)
    now = (folder / "encoder.onnx").stat().st_mtime
    _edit_metadata(folder / "encoder.onnx", lambda p: {**p, "doc": "rewritten"})  # a later commit's fp32 file
    os.utime(folder / "encoder.onnx", (now, now))
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        assert _load_encoder(folder, precision="int8").files["encoder"].path.name == "encoder.onnx"
    [said] = _stale_warnings(caplog)
    assert (f"encoder.int8.onnx is not quantized from encoder.onnx (it was quantized from a file of sha256 "
            f"{quantized_from[:12]}..., and encoder.onnx has sha256 {_sha256(folder / 'encoder.onnx')[:12]}...)"
            ) in said


@pytest.mark.skipif(not (REPO / "models" / "model_card.json").is_file(), reason="no shipped model")
@pytest.mark.parametrize("variant", ["ghnerf", "baseline"])
def test_the_shipped_int8_files_record_their_fp32_twins_sha256(variant, tmp_path):
    """Every shipped ``<graph>.int8.onnx`` but the ghnerf ``human.int8.onnx`` records the sha256 of the
    ``<graph>.onnx`` beside it (stamped after the export, docs/model.md "Precision"), so its time does not count:
    copied with the int8 files two days older, each is still taken. ``human.int8.onnx`` is left as exported: the
    skeleton prior records that file's own sha256 and refuses any other bytes."""
    from ghnerf_runtime.novel_painter import NovelPainter
    from ghnerf_runtime.onnx_file import onnx_metadata

    shipped = REPO / "models" / variant
    folder = tmp_path / variant
    shutil.copytree(shipped, folder)
    unstamped = {"human.int8.onnx"} if variant == "ghnerf" else set()
    for int8 in sorted(folder.glob("*.int8.onnx")):
        fp32 = int8.with_name(int8.name.replace(".int8", ""))
        recorded = onnx_metadata(int8, "graph").get("ghnerf.fp32_sha256" if fp32.name != "novel_painter.onnx"
                                                    else "ghnerf_painter.fp32_sha256")
        assert recorded == (None if int8.name in unstamped else _sha256(fp32)), int8.name
        old = fp32.stat().st_mtime - 2 * 86400.0
        os.utime(int8, (old, old))
        if fp32.name == "novel_painter.onnx":
            assert NovelPainter.choose(folder) == int8
        elif int8.name not in unstamped:
            assert ModelSession._stale_int8(folder, fp32.stem, int8) is None, int8.name


def test_the_session_loads_the_fp32_painter_beside_a_stale_int8_one(tiny_model_dir, tmp_path):
    """``ModelSession.load(novel_painter=True)`` takes the painter ``NovelPainter.choose`` gives: the fp32 file where
    the int8 one records another training (tests/ghnerf_runtime/test_novel_painter.py has the rule)."""
    painters = pytest.importorskip("tests.ghnerf_runtime.test_novel_painter")
    folder = _copy(tiny_model_dir, tmp_path / "m")
    fp32 = painters._recorded(painters.blend_painter(folder / "novel_painter.onnx"), steps="2")
    painters._recorded(painters.blend_painter(folder / "novel_painter.int8.onnx"), steps="1", precision="int8")
    s = ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False), ("encoder",), novel_painter=True)
    assert s.novel_painter.path == fp32


def test_files_found_by_metadata_when_renamed(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    (folder / "encoder.onnx").rename(folder / "ghnerf-enc-v1.onnx")
    assert _load_encoder(folder).files["encoder"].path.name == "ghnerf-enc-v1.onnx"


def test_the_files_say_what_the_model_was_trained_on_past_the_frame(tiny_model_dir, tmp_path):
    """``ghnerf.frame_padding`` reaches the session's contract (the estimator's default ``roi.pad_fill`` follows
    it) and its summary; a folder exported before contract 1.3.0, without the key, reads as "none"."""
    assert _load_encoder(tiny_model_dir).contract.frame_padding == "none"  # random weights: trained on nothing
    folder = _copy(tiny_model_dir, tmp_path / "m")
    _edit_metadata(folder / "encoder.onnx", lambda p: {**p, "ghnerf.frame_padding": "black"})
    black = _load_encoder(folder)
    assert black.contract.frame_padding == "black" and black.describe()["frame_padding"] == "black"
    _edit_metadata(folder / "encoder.onnx", lambda p: {k: v for k, v in p.items() if k != "ghnerf.frame_padding"})
    assert _load_encoder(folder).contract.frame_padding == "none"
    _edit_metadata(folder / "encoder.onnx", lambda p: {**p, "ghnerf.frame_padding": "grey"})
    with pytest.raises(ModelContractError) as e:
        _load_encoder(folder)
    assert e.value.key == "ghnerf.frame_padding" and "'grey'" in str(e.value) and "encoder.onnx" in str(e.value)


# --------------------------------------------------------------------------- refusals
def test_wrong_contract_version_refused(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    _edit_metadata(folder / "encoder.onnx", lambda p: {**p, "ghnerf.contract_version": "2.0.0"})
    with pytest.raises(ModelContractError) as e:
        _load_encoder(folder)
    msg = str(e.value)
    assert str(folder / "encoder.onnx") in msg and "ghnerf.contract_version" in msg and "2.0.0" in msg
    assert e.value.key == "ghnerf.contract_version" and e.value.path == str(folder / "encoder.onnx")
    assert isinstance(e.value, (ModelError, RuntimeErrorBase, ValueError))


def test_resolution_other_than_configured_refused(tiny_model_dir):
    with pytest.raises(ModelContractError) as e:
        _load_encoder(tiny_model_dir, expected_resolution=128)
    assert "ghnerf.resolution" in str(e.value) and "64x64" in str(e.value) and "128x128" in str(e.value)
    assert "encoder.onnx" in str(e.value)


def test_metadata_resolution_disagreeing_with_the_graph_refused(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    tiny = _load_encoder(folder).contract
    big = ModelContract.build(height=128, width=128, variant=tiny.variant, levels=tiny.levels,
                              channels=tiny.channels, strides=tiny.strides, render_feature=tiny.render_feature,
                              heatmap_stride=tiny.heatmap_stride)
    _edit_metadata(folder / "encoder.onnx", lambda p: {**p, **big.to_metadata(graph="encoder")})
    with pytest.raises(ModelContractError) as e:
        _load_encoder(folder)
    assert e.value.key == "images" and "[2, 3, 64, 64]" in str(e.value) and "encoder.onnx" in str(e.value)


@pytest.mark.parametrize(("key", "edit"), [
    # a key of strides, but no image feature: next() over the features raised a bare StopIteration
    ("ghnerf.render_feature", lambda v: "human_feat"),
    # int(inf) raised OverflowError, which no handler took
    ("ghnerf.channels", lambda v: json.dumps({**json.loads(v), "feat_s1": 1e400}).replace("Infinity", "1e400")),
    # int() truncated 8.5 to 8 and read true as 1: a contract nobody wrote
    ("ghnerf.channels", lambda v: json.dumps({**json.loads(v), "feat_s1": json.loads(v)["feat_s1"] + 0.5})),
    ("ghnerf.strides", lambda v: json.dumps({**json.loads(v), "feat_s1": True})),
    ("ghnerf.levels", lambda v: json.dumps([{**lv, "planes": lv["planes"] + 0.5} for lv in json.loads(v)])),
    # bool("false") is True: the host would skip the mean/std the graph does not apply
    ("ghnerf.normalisation", lambda v: json.dumps({**json.loads(v), "mean_std_in_graph": "false"})),
    ("ghnerf.levels", lambda v: "[" * 100_000 + "]" * 100_000),  # a bare RecursionError
])
def test_impossible_metadata_values_are_refused_by_key(tiny_model_dir, tmp_path, key, edit):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    _edit_metadata(folder / "encoder.onnx", lambda p: {**p, key: edit(p[key])})
    with pytest.raises(ModelContractError) as e:
        _load_encoder(folder)
    assert e.value.key == key and "encoder.onnx" in str(e.value)


def test_a_model_of_more_joints_than_body_25_is_refused_at_load_naming_the_count(tiny_model_dir, tmp_path):
    # 65 joints: more than a joint-stream packet carries (64); refused here, before any frame is made
    folder = _copy(tiny_model_dir, tmp_path / "m")
    names = json.dumps([f"joint{k}" for k in range(65)])
    _edit_metadata(folder / "encoder.onnx", lambda p: {**p, "ghnerf.joint_names": names})
    with pytest.raises(ModelContractError) as e:
        _load_encoder(folder)
    assert e.value.key == "ghnerf.joint_names" and "encoder.onnx" in str(e.value)
    assert "BODY_25's 25 joints" in str(e.value) and "this model has 65:" in str(e.value)


def test_missing_metadata_key_refused(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    _edit_metadata(folder / "encoder.onnx", lambda p: {k: v for k, v in p.items() if k != "ghnerf.levels"})
    with pytest.raises(ModelContractError) as e:
        _load_encoder(folder)
    assert e.value.key == "ghnerf.levels" and "missing" in str(e.value) and "encoder.onnx" in str(e.value)


@pytest.mark.parametrize("keep", [5, -1])  # cut in the contract's keys; cut before the last, ghnerf.graph
def test_a_file_cut_short_in_its_metadata_says_so(tiny_model_dir, tmp_path, keep):
    """A copy that stopped at an entry's end parses: it was called "not a GHNeRF export, or too old"."""
    onnx = pytest.importorskip("onnx")
    folder = _copy(tiny_model_dir, tmp_path / "m")
    path = folder / "encoder.onnx"
    whole = path.read_bytes()
    model = onnx.load(str(path))
    del model.metadata_props[keep:]
    cut = model.SerializeToString()
    assert whole.startswith(cut) and len(cut) < len(whole)  # exactly the file's first bytes
    path.write_bytes(cut)
    with pytest.raises(ModelContractError) as e:
        _load_encoder(folder)
    assert e.value.path == str(path) and "cut short" in str(e.value) and "too old" not in str(e.value)


def test_file_without_any_contract_refused(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    _edit_metadata(folder / "encoder.onnx", lambda p: {})
    with pytest.raises(ModelContractError, match="no ghnerf.* metadata"):
        _load_encoder(folder)


@pytest.mark.parametrize("damage", ["truncated", "garbage", "empty"])
def test_corrupt_file_refused(tiny_model_dir, tmp_path, damage):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    path = folder / "encoder.onnx"
    data = path.read_bytes()
    path.write_bytes({"truncated": data[: len(data) // 2], "garbage": os.urandom(4096), "empty": b""}[damage])
    with pytest.raises(ModelLoadError) as e:
        _load_encoder(folder)
    assert str(path) in str(e.value) and "truncated or corrupt" in str(e.value)
    assert isinstance(e.value, OSError)


def test_a_file_onnxruntime_parses_but_refuses_says_why(tiny_model_dir, tmp_path):
    """An IR version too new: onnxruntime's reason, not its C++ signature, and no "corrupt?" for a file that parsed."""
    onnx = pytest.importorskip("onnx")
    folder = _copy(tiny_model_dir, tmp_path / "m")
    model = onnx.load(str(folder / "encoder.onnx"))
    model.ir_version = 99
    onnx.save(model, str(folder / "encoder.onnx"))
    with pytest.raises(ModelLoadError) as e:
        _load_encoder(folder)
    assert "IR version: 99" in str(e.value) and "corrupt" not in str(e.value) and "::" not in str(e.value)


def test_fp32_asked_for_never_loads_int8_weights(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    _edit_metadata(folder / "encoder.onnx", lambda p: {**p, "ghnerf.precision": "int8"})  # int8 under the fp32 name
    with pytest.raises(ModelContractError) as e:
        _load_encoder(folder, precision="fp32")
    assert e.value.key == "ghnerf.precision" and "int8" in str(e.value) and "encoder.onnx" in str(e.value)
    with pytest.raises(ModelContractError, match="ghnerf.precision"):
        _load_encoder(folder, precision="int8", precision_overrides={"encoder": "fp32"})
    assert _load_encoder(folder).files["encoder"].precision == "int8"  # auto takes what the folder has
    (folder / "encoder.onnx").rename(folder / "enc-q.onnx")  # found by metadata: int8 is no fp32 either
    with pytest.raises(ModelLoadError, match="no file for graph 'encoder'"):
        _load_encoder(folder, precision="fp32")
    assert _load_encoder(folder, precision="int8").files["encoder"].path.name == "enc-q.onnx"


def test_missing_file_and_folder_refused(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    (folder / "volume.onnx").unlink()
    with pytest.raises(ModelLoadError, match="no file for graph 'volume'"):
        ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False), ("encoder", "volume"))
    with pytest.raises(ModelLoadError, match="model folder does not exist"):
        _load_encoder(tmp_path / "nowhere")


@pytest.mark.parametrize(("kind", "said"), [("folder", "a folder"), ("dangling", "a symbolic link that leads nowhere")])
def test_a_graph_name_that_is_no_file_is_named_as_what_it_is(tmp_path, kind, said):
    """A folder (an unpacked archive) or a link to nowhere under encoder.onnx said "no file for graph 'encoder'"
    of the folder, sending the user looking for the file that ls shows."""
    path = tmp_path / "encoder.onnx"
    if kind == "folder":
        path.mkdir()
    else:
        path.symlink_to(tmp_path / "gone.onnx")
    for precision in ("fp32", "auto"):  # (auto looks for encoder.int8.onnx first)
        with pytest.raises(ModelLoadError) as e:
            _load_encoder(tmp_path, precision=precision)
        assert e.value.path == str(path) and f"is not a graph file but {said}" in str(e.value)
        assert str(path) in str(e.value) and "'encoder'" in str(e.value)


def test_more_threads_than_cores_loads_and_warns_naming_both(tiny_model_dir, monkeypatch, caplog):
    """session.threads past the cores this process may use (a config written for a larger machine) was taken
    without a word; it still loads (the config may be moved back), and the log says so."""
    import ghnerf_runtime.session as session_module

    monkeypatch.setattr(session_module, "usable_cores", lambda: 2)
    for threads, warned in ((3, True), (2, False)):
        caplog.clear()
        with caplog.at_level("WARNING", logger="ghnerf_runtime.session"):
            assert _load_encoder(tiny_model_dir, threads=threads).has("encoder")
        said = [r.getMessage() for r in caplog.records if "session.threads" in r.getMessage()]
        assert said == (["session.threads is 3, more than the 2 core(s) this process may run on: onnxruntime's "
                         "threads only share those (docs/runtime.md, \"Threads\")"] if warned else [])
    assert 1 <= session_module.usable_cores() <= (os.cpu_count() or 1)


def test_a_relative_model_dir_that_is_not_there_names_the_folder_it_was_read_from(tmp_path, monkeypatch):
    # `ghnerf-run` outside the repository said only "models: model folder does not exist"
    monkeypatch.chdir(tmp_path)
    where = f"model folder does not exist (read from the current directory {tmp_path})"
    with pytest.raises(ModelLoadError, match=re.escape(where)):
        _load_encoder("models")


def test_a_model_dir_that_is_a_file_or_no_graphs_is_named(tiny_model_dir):
    with pytest.raises(ModelLoadError, match="is not a folder") as e:  # said "model folder does not exist"
        _load_encoder(tiny_model_dir / "encoder.onnx")
    assert str(tiny_model_dir / "encoder.onnx") in str(e.value)
    with pytest.raises(ModelError, match="no graphs to load") as e:  # was a bare AssertionError
        ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir), warmup=False), ())
    assert str(tiny_model_dir) in str(e.value)


def test_a_model_dir_that_is_a_link_to_nowhere_says_so(tmp_path):
    (tmp_path / "loop").symlink_to("loop")  # said "model folder does not exist" of a path ls shows
    (tmp_path / "dangling").symlink_to(tmp_path / "gone")
    for name in ("loop", "dangling"):
        with pytest.raises(ModelLoadError, match="symbolic link that leads to no folder") as e:
            _load_encoder(tmp_path / name)
        assert e.value.path == str(tmp_path / name)


_LOAD_AS_THE_SERVICE = """
import sys
from ghnerf_runtime.config import EstimatorConfig, SessionConfig
from ghnerf_runtime.estimator import load_session
from ghnerf_runtime.session import ModelSession
session = SessionConfig(model_dir=sys.argv[1], warmup=False)
try:
    if sys.argv[2] == "estimator":
        load_session(EstimatorConfig(session=session))
    else:
        ModelSession.load(session, ("encoder",))
except Exception as e:
    print(f"{type(e).__name__}|{e}")
"""


@pytest.mark.parametrize(("locked", "mode"), [
    ("folder", 0o000), ("folder", 0o111), ("folder", 0o444),  # neither; enter but not list; list but not enter
    ("parent", 0o000),  # a folder above it (ProtectHome=yes makes /home so for the service)
    ("ghnerf", 0o000),  # the shipped layout's subfolder: was "no file for graph" in the folder above it
])
def test_a_model_folder_this_user_may_not_read_is_a_load_error_naming_it(tmp_path, locked, mode):
    """Was a bare PermissionError from a stat in resolve_model_dir (the daemon: a traceback and exit 1)."""
    from tests.unprivileged import run_unprivileged

    top = tmp_path / "models"
    folder = top / "ghnerf" if locked == "ghnerf" else top / "m" if locked == "parent" else top
    folder.mkdir(parents=True)
    (folder / "encoder.onnx").write_bytes(b"\x08\x07not read")
    lock = {"folder": top, "parent": top, "ghnerf": folder}[locked]
    lock.chmod(mode)
    try:
        model_dir = top / "m" if locked == "parent" else top
        proc = run_unprivileged([sys.executable, "-c", _LOAD_AS_THE_SERVICE, str(model_dir), "estimator"],
                                cwd=REPO, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})
    finally:
        lock.chmod(0o755)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    kind, message = proc.stdout.strip().split("|", 1)
    assert kind == "ModelLoadError", proc.stdout
    assert message.startswith(f"{folder if locked == 'ghnerf' else model_dir}: cannot read the model folder")
    assert "ermission denied" in message


def test_a_graph_file_this_user_may_not_read_says_so(tmp_path):
    """onnxruntime says "system error number 13"; the message now says what that is."""
    from tests.unprivileged import run_unprivileged

    (tmp_path / "encoder.onnx").write_bytes(b"\x08\x07not read")
    (tmp_path / "encoder.onnx").chmod(0)
    proc = run_unprivileged([sys.executable, "-c", _LOAD_AS_THE_SERVICE, str(tmp_path), "session"],
                            cwd=REPO, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == 0, proc.stderr[-2000:]
    kind, message = proc.stdout.strip().split("|", 1)
    assert kind == "ModelLoadError" and message.startswith(str(tmp_path / "encoder.onnx"))
    assert "Permission denied (system error number 13)" in message and "corrupt" not in message


def _slice_output(path: Path, output: str, axis: int, keep: int) -> None:
    """Rewrite ``path`` so that ``output`` keeps the first ``keep`` entries of ``axis``; its declared shape (and
    so the file's I/O as the load reads it) stays as it was."""
    onnx = pytest.importorskip("onnx")
    model = onnx.load(str(path))
    node = next(n for n in model.graph.node if output in n.output)
    node.output[list(node.output).index(output)] = output + "_full"
    for name, value in (("starts", 0), ("ends", keep), ("axes", axis)):
        model.graph.initializer.append(onnx.numpy_helper.from_array(np.array([value], np.int64), f"cut_{name}"))
    model.graph.node.append(onnx.helper.make_node("Slice", [output + "_full", "cut_starts", "cut_ends", "cut_axes"],
                                                  [output]))
    onnx.save(model, str(path))


@pytest.mark.parametrize(("axis", "keep", "said"), [
    (2, 24, "[2, 256, 24]"),  # 24 joints: the estimator sent 24 "BODY_25" joints on the wire
    (0, 1, "[1, 256, 25]"),  # one target's heatmaps for two: an IndexError in the estimator stopped the daemon
])
def test_a_graph_whose_outputs_break_the_contract_is_refused_at_warm_up(tiny_model_dir, tmp_path, axis, keep, said):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    _slice_output(folder / "render_heat.onnx", "heatmaps", axis, keep)
    graphs = ("encoder", "volume", "render_heat")
    session = ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False), graphs)  # the I/O read fine
    feeds = warmup_feeds(session.contract)
    feeds.update(session.run("encoder", feeds))
    feeds.update(session.run("volume", feeds))
    with pytest.raises(ModelRunError) as e:
        session.run("render_heat", feeds)
    assert e.value.path == str(folder / "render_heat.onnx") and "'heatmaps'" in str(e.value)
    assert said in str(e.value) and "['B', 'R', 25]" in str(e.value)
    with pytest.raises(ModelRunError, match="render_heat.onnx") as e:  # the warm-up runs it: refused at load
        ModelSession.load(SessionConfig(model_dir=str(folder)), graphs)
    assert "'heatmaps'" in str(e.value)


@pytest.mark.parametrize("graph", ["encoder", "render_heat"])
def test_a_graph_whose_weights_hold_nan_is_refused_at_warm_up(tiny_model_dir, tmp_path, graph):
    """A graph exported from a diverged run's weights answers NaN to every input: it loaded and warmed up without
    a word, and the estimator found no one, frame after frame."""
    onnx = pytest.importorskip("onnx")
    folder = _copy(tiny_model_dir, tmp_path / "m")
    model = onnx.load(str(folder / f"{graph}.onnx"))
    weights = max(model.graph.initializer, key=lambda t: int(np.prod(t.dims)))
    values = onnx.numpy_helper.to_array(weights).copy()
    values.flat[0] = np.nan
    weights.CopyFrom(onnx.numpy_helper.from_array(values, weights.name))
    onnx.save(model, str(folder / f"{graph}.onnx"))
    graphs = ("encoder", "volume", "render_heat")
    with pytest.raises(ModelRunError) as e:
        ModelSession.load(SessionConfig(model_dir=str(folder)), graphs)
    assert e.value.path == str(folder / f"{graph}.onnx")
    assert f"graph {graph!r} returned" in str(e.value) and "NaN or infinite value(s)" in str(e.value)
    ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir)), graphs)  # the export it was made from loads


@pytest.mark.parametrize("precision", ["fp16", ""])
def test_a_precision_the_runtime_does_not_know_is_refused(tiny_model_dir, tmp_path, precision):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    _edit_metadata(folder / "encoder.onnx", lambda p: {**p, "ghnerf.precision": precision})
    with pytest.raises(ModelContractError) as e:  # was loaded and reported as an "fp16" graph
        _load_encoder(folder, precision="int8")
    assert e.value.key == "ghnerf.precision" and repr(precision) in str(e.value) and "encoder.onnx" in str(e.value)


def test_graph_files_from_different_models_refused(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    _edit_metadata(folder / "volume.onnx", lambda p: {**p, "ghnerf.model_version": "9.9.9"})
    with pytest.raises(ModelContractError) as e:
        ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False), ("encoder", "volume"))
    assert "different models" in str(e.value) and e.value.key == "ghnerf.model_version"
    assert "volume.onnx" in str(e.value)


def test_file_holding_another_graph_refused(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    shutil.copy(folder / "encoder.onnx", folder / "volume.onnx")
    with pytest.raises(ModelContractError, match="holds graph 'encoder', loaded as 'volume'"):
        ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False), ("encoder", "volume"))


def test_shipped_layout_resolves_to_the_ghnerf_subfolder(tiny_model_dir, tmp_path):
    models = tmp_path / "models"
    _copy(tiny_model_dir, models / "ghnerf")
    _copy(tiny_model_dir, models / "baseline")
    (models / "model_card.json").write_text('{"name": "shipped"}')
    s = _load_encoder(models)
    assert s.files["encoder"].path == models / "ghnerf" / "encoder.onnx" and s.card == {"name": "shipped"}
    assert _load_encoder(models / "baseline").files["encoder"].path.parent == models / "baseline"


def test_model_card_is_read_when_present(tiny_model_dir, tmp_path):
    folder = _copy(tiny_model_dir, tmp_path / "m")
    (folder / "model_card.json").write_text('{"name": "tiny-test", "pck": 0.5}')
    assert _load_encoder(folder).card == {"name": "tiny-test", "pck": 0.5}
    (folder / "model_card.json").write_text("{not json")
    assert _load_encoder(folder).card == {}  # an unreadable card is not fatal
    for text in ("[" * 100_000, '{"n": ' + "1" * 5000 + "}"):  # were a bare RecursionError, ValueError
        (folder / "model_card.json").write_text(text)
        assert _load_encoder(folder).card == {}
    (folder / "model_card.json").write_bytes(b"\xef\xbb\xbf" + b'{"name": "bom"}')  # was ignored as bad JSON
    assert _load_encoder(folder).card == {"name": "bom"}


@pytest.mark.skipif(not (REPO / "models" / "model_card.json").is_file(), reason="no trained model in models/")
def test_the_global_thread_pool_loads_the_shipped_model_with_its_prior_and_painter():
    """onnxruntime's global pool is process-wide: once installed, every session must use it, the skeleton
    prior's and the painter's too (they failed to load, blamed on a corrupt file). In a child process, so
    this test's pool does not reach the others'."""
    script = (
        "from ghnerf_runtime.config import EstimatorConfig, SessionConfig, NovelViewConfig\n"
        "from ghnerf_runtime.estimator import load_session\n"
        "cfg = EstimatorConfig(session=SessionConfig(model_dir='models', thread_pool='global', warmup=False),\n"
        "                      novel_view=NovelViewConfig(enabled=True, painter='on'))\n"
        "s = load_session(cfg)\n"
        "assert s.skeleton_prior is not None and s.novel_painter is not None\n"
        "print('loaded')\n"
    )
    proc = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == 0 and "loaded" in proc.stdout, proc.stderr[-2000:]
