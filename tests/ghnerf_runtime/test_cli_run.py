"""``ghnerf-run`` end to end on a simulated pair (and a short clip), with the tiny exported model."""
from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_NAMES
from ghnerf_runtime.cli import run as cli_run
from ghnerf_runtime.config import NOVEL_PATHS, EstimatorConfig, config_to_dict
from ghnerf_runtime.contract import GRAPH_NAMES
from ghnerf_runtime.errors import ModelRunError
from ghnerf_runtime.rig_file import load_rig
from tests.exif_images import jpeg_turned
from tests.framing_note import framing_notes
from tests.rotated_videos import phone_take
from tests.odd_images import bmp_beyond_opencv_s_limits, tiff_laid_out
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)

simdata = pytest.importorskip("ghnerf_runtime.cli.simdata")
pytest.importorskip("drivers.sim")


@pytest.fixture(scope="module")
def sim_pair(tmp_path_factory):
    return simdata.write_sim_example(tmp_path_factory.mktemp("sim-pair"))


def _check_frame(obj: dict, cameras: tuple[str, ...], width: int, height: int) -> None:
    """The documented per-frame schema (docs/runtime.md)."""
    assert obj["joint_names"] == list(JOINT_NAMES)
    assert len(obj["joints_3d"]) == 25 and all(len(j) == 4 for j in obj["joints_3d"])
    assert set(obj["joints_2d"]) == set(cameras)
    for rows in obj["joints_2d"].values():
        assert len(rows) == 25 and all(len(j) == 3 for j in rows)
    assert len(obj["missing"]) == 25 and all(isinstance(m, bool) for m in obj["missing"])
    stages = {"preprocess", "encoder", "decode_2d", "joints_3d", "total"}  # default: encoder heatmaps
    assert stages <= set(obj["timing_ms"])
    numbers = [v for j in obj["joints_3d"] for v in j] + [v for rows in obj["joints_2d"].values() for j in rows
                                                         for v in j] + list(obj["timing_ms"].values())
    assert all(isinstance(v, (int, float)) and math.isfinite(v) for v in numbers)
    for (x, y, z, c), missing in zip(obj["joints_3d"], obj["missing"]):
        assert 0.0 <= c <= 1.0
        if missing:
            assert (x, y, z, c) == (0.0, 0.0, 0.0, 0.0)
    for name, rows in obj["joints_2d"].items():
        assert len(obj["missing_2d"][name]) == 25 and all(isinstance(m, bool) for m in obj["missing_2d"][name])
        for (u, v, c), missing in zip(rows, obj["missing_2d"][name]):
            assert 0.0 <= c <= 1.0 and missing == (c == 0)  # the flag and confidence 0 say the same
            if c > 0:
                assert -width <= u <= 2 * width and -height <= v <= 2 * height
            else:  # a missing 2D joint is zeros (docs/runtime.md)
                assert (u, v) == (0.0, 0.0)
    assert list(obj["joints_2d"]) == list(cameras) == list(obj["frame_ok"]) == list(obj["missing_2d"])  # rig order
    assert all(isinstance(v, float) for v in numbers) and isinstance(obj["sequence"], int)  # floats, never 0


def test_run_on_a_sim_pair_writes_the_documented_json(sim_pair, tiny_model_dir, tmp_path):  # noqa: F811
    out = tmp_path / "joints.json"
    novel = tmp_path / "novel.png"
    overlay = tmp_path / "overlay.png"
    # the random weights find nobody, and a pair with nobody has no novel view: the presence gate off views it
    config = tmp_path / "everyone.json"
    config.write_text(json.dumps({"presence": {"enabled": False}}))
    rc = cli_run.main(["--rig", sim_pair["rig"], "--images", sim_pair["left"], sim_pair["right"],
                       "--model-dir", str(tiny_model_dir), "--out", str(out), "--novel-view", str(novel),
                       "--novel-overlay", "skeleton", "--overlay", str(overlay), "--config", str(config)])
    assert rc == 0
    frames = json.loads(out.read_text())
    rig = load_rig(sim_pair["rig"])
    assert isinstance(frames, list) and len(frames) == 1
    assert frames[0]["time_s"] is None  # a still pair was filmed at no time the run knows
    _check_frame(frames[0], rig.names[:2], *rig.pair[0].size)
    assert "novel_volume" in frames[0]["timing_ms"]
    img = cv2.imread(str(novel))
    assert img is not None and img.shape == (64, 64, 3)  # the tiny model renders 64x64
    ov = cv2.imread(str(overlay))
    assert ov is not None and ov.shape == (480, 1280, 3)


def test_a_novel_view_of_a_pair_that_shows_nobody_is_said_to_be_black(sim_pair, tiny_model_dir, tmp_path,  # noqa: F811
                                                                     caplog):
    """The random weights find nobody, so the pair has no novel view and --novel-view gets black: it was written
    with exit status 0 and no word, which looked like a broken render."""
    novel = tmp_path / "novel.png"
    rc = cli_run.main(["--rig", sim_pair["rig"], "--images", sim_pair["left"], sim_pair["right"],
                       "--model-dir", str(tiny_model_dir), "--out", str(tmp_path / "j.json"),
                       "--novel-view", str(novel)])
    assert rc == 0 and not cv2.imread(str(novel)).any()
    assert f"--novel-view {novel}: black: no novel view for a pair that shows nobody" in caplog.text


def test_run_on_two_videos_writes_one_object_per_line(tiny_model_dir, tmp_path, capsys):  # noqa: F811
    clip = simdata.write_sim_example(tmp_path / "clip", frames=3, width=320, height=240)
    rc = cli_run.main(["--rig", clip["rig"], "--videos", clip["left"], clip["right"],
                       "--model-dir", str(tiny_model_dir), "--method", "depth_centroid"])
    assert rc == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip()]
    assert len(lines) == 3
    rig = load_rig(clip["rig"])
    for i, line in enumerate(lines):
        obj = json.loads(line)
        assert obj["sequence"] == i and obj["method"] == "depth_centroid"
        _check_frame(obj, rig.names[:2], 320, 240)


def test_a_video_run_with_a_novel_view_writes_every_pair_in_order(tiny_model_dir, tmp_path, capsys):  # noqa: F811
    """ghnerf-run finishes each pair's novel view while the next pair is estimated (NovelViewPipeline): every
    pair still comes out, in order, with its view and its overlay, as one by one."""
    clip = simdata.write_sim_example(tmp_path / "clip", frames=4, width=320, height=240)
    outputs = {}
    for name in ("piped", "again"):
        out, novel = tmp_path / f"{name}.jsonl", tmp_path / f"{name}.mp4"
        assert cli_run.main(["--rig", clip["rig"], "--videos", clip["left"], clip["right"], "--model-dir",
                             str(tiny_model_dir), "--out", str(out), "--novel-view", str(novel),
                             "--overlay", str(tmp_path / f"{name}-overlay.mp4")]) == 0
        frames = [json.loads(line) for line in out.read_text().splitlines()]
        assert [f["sequence"] for f in frames] == [0, 1, 2, 3]
        for path in (novel, tmp_path / f"{name}-overlay.mp4"):
            cap = cv2.VideoCapture(str(path))
            assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 4, path
            cap.release()
        outputs[name] = [(f["joints_3d"], f["joints_2d"]) for f in frames]
    assert outputs["piped"] == outputs["again"]  # deterministic: nothing of one pair leaks into the next


def test_an_image_tagged_to_be_turned_is_read_as_stored(tmp_path):
    # OpenCV turned it by its EXIF orientation (6: a quarter), a 40x30 frame read as 30x40 against the rig's cameras
    image = np.random.default_rng(0).integers(0, 256, (30, 40, 3), np.uint8)
    ok, jpeg = cv2.imencode(".jpg", image)
    assert ok
    path = tmp_path / "turned.jpg"
    path.write_bytes(jpeg_turned(jpeg.tobytes(), 6))
    assert cli_run._read_image(str(path)).shape == (30, 40, 3)


def test_a_video_turned_by_its_metadata_is_read_as_stored(tmp_path):
    # a phone's upright video: OpenCV turned its 64x48 frames by the container's rotation (48x64), like an image by
    # its EXIF orientation, a quarter turn against the rig's cameras
    turned, plain, stored = phone_take(tmp_path)
    args = cli_run.build_parser().parse_args(["--rig", "r.json", "--videos", str(turned), str(plain)])
    pairs = list(cli_run._pairs(args))
    assert len(pairs) == len(stored)
    for (first, second), frame in zip(pairs, stored):
        assert np.array_equal(first, frame) and np.array_equal(second, frame)


def test_an_image_whose_header_is_beyond_opencv_s_size_limits_is_named_as_unreadable(tmp_path):
    # cv2.imread raises for it rather than failing: ghnerf-run stopped with a cv2.error traceback
    path = tmp_path / "huge.bmp"
    path.write_bytes(bmp_beyond_opencv_s_limits())
    with pytest.raises(cli_run.UsageError, match=f"{re.escape(str(path))}: cannot read the image"):
        cli_run._read_image(str(path))


def _refused_without_opencv_s_words(path: str, said: str, capfd, opencv_s: str) -> None:
    """``_read_image(path)`` refused, its error containing ``said``, and nothing of OpenCV's own log (``opencv_s``,
    a word of its line) printed beside it."""
    with pytest.raises(cli_run.UsageError, match=re.escape(said)):
        cli_run._read_image(path)
    captured = capfd.readouterr()
    assert opencv_s not in captured.err + captured.out


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int32])
def test_an_image_of_samples_that_do_not_decode_to_8_bits_is_named_by_its_sample_type(tmp_path, capfd, dtype):
    # a float TIFF (NaN and values outside 0-1 in it) was "not a format OpenCV reads", which it is, under libtiff's
    # "[ WARN:0@0.2] ... Sorry, can not handle images with 32-bit samples": the error now names its sample type
    image = np.full((6, 8, 3), 0.5).astype(dtype)
    if np.issubdtype(dtype, np.floating):
        image[0, 0], image[1, 1], image[2, 2] = np.nan, np.inf, -3.0
    path = tmp_path / "float.tiff"
    assert cv2.imwrite(str(path), image)
    said = f"{path}: cannot take the image: it has {np.dtype(dtype).name} samples (8x6, 3 channels): only 8- or 16-bit"
    _refused_without_opencv_s_words(str(path), said, capfd, "Sorry")


def test_a_tiff_of_a_compression_opencv_does_not_decode_is_named_not_estimated_as_a_black_image(tmp_path, capfd):
    # a JPEG 2000 TIFF (Compression 34712) was read as an image of zeros, libtiff's error only logged, and its
    # joints estimated from it
    data = cv2.imencode(".tiff", np.full((6, 8, 3), 200, np.uint8), [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1]
    path = tmp_path / "left.tiff"
    path.write_bytes(tiff_laid_out(data.tobytes(), changed={259: (3, (34712,))}))
    said = f"{path}: cannot take the image: it is a TIFF of Compression 34712 (JPEG 2000), which OpenCV"
    _refused_without_opencv_s_words(str(path), said, capfd, "TIFF")


def _jpeg_cut_to_a_third() -> bytes:
    """A real encoded JPEG (noise: its scan is most of the file) cut to a third of its length."""
    image = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    data = cv2.imencode(".jpg", image)[1].tobytes()
    return data[:len(data) // 3]


def test_a_jpeg_cut_short_is_refused_naming_the_file_not_estimated_on_grey(tmp_path):
    # OpenCV's file reader filled the missing two thirds with grey, and the joints were estimated from it (exit 0)
    path = tmp_path / "left.jpg"
    path.write_bytes(_jpeg_cut_to_a_third())
    said = f"{path}: cannot take the image: it is a JPEG cut short ({path.stat().st_size} bytes, not ending at"
    with pytest.raises(cli_run.UsageError, match=re.escape(said)):
        cli_run._read_image(str(path))


def test_a_missing_or_unreadable_image_is_named_without_opencv_s_warning(tmp_path, capfd):
    """A mistyped image path gave OpenCV's own "[ WARN:0@0.5] global loadsave.cpp ... findDecoder imread_" line
    above ghnerf-run's error, and the error said "missing file or unknown format" without saying which: a missing
    file, a folder and a file that is no image are each named, with nothing from OpenCV."""
    not_image = tmp_path / "notes.png"
    not_image.write_text("not a picture")
    cases = {str(tmp_path / "absent.png"): "absent.png: no such file",
             str(tmp_path): f"{tmp_path}: a folder, not an image",
             str(not_image): "notes.png: cannot read the image (not a format OpenCV reads"}
    for path, said in cases.items():
        with pytest.raises(cli_run.UsageError, match=re.escape(said)):
            cli_run._read_image(path)
    captured = capfd.readouterr()
    assert "findDecoder" not in captured.err + captured.out


def test_a_still_of_another_size_than_the_rig_s_is_refused_from_its_header_without_decoding_it(
        sim_pair, tiny_model_dir, tmp_path, capsys, monkeypatch):  # noqa: F811
    """An 8000x6000 still was decoded whole (about 400 MB) before the estimator refused its size: the header's
    size is compared with the rig file's first, the decoder never called for it."""
    big = tmp_path / "big.png"
    assert cv2.imwrite(str(big), np.zeros((60, 80, 3), np.uint8))

    def no_decode(path, flags):
        raise AssertionError(f"{path} decoded")

    monkeypatch.setattr(cli_run, "read_image_or_none", no_decode)
    args = ["--rig", sim_pair["rig"], "--model-dir", str(tiny_model_dir), "--images", str(big), sim_pair["right"]]
    assert cli_run.main(args) == 2
    err = capsys.readouterr().err
    first = load_rig(sim_pair["rig"]).names[0]
    assert (f"{big}: camera {first!r}: expected a (480, 640, 3) uint8 BGR image (the rig file's 640x480), its header "
            "gives 80x60 (not decoded)") in err


def test_errors_exit_2_and_name_the_problem(sim_pair, tiny_model_dir, tmp_path, capsys):  # noqa: F811
    args = ["--rig", sim_pair["rig"], "--model-dir", str(tiny_model_dir)]
    assert cli_run.main(args + ["--images", sim_pair["left"], str(tmp_path / "absent.png")]) == 2
    assert "absent.png: no such file" in capsys.readouterr().err
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((10, 10, 3), np.uint8))
    assert cli_run.main(args + ["--images", sim_pair["left"], str(small)]) == 2
    assert "expected a (480, 640, 3)" in capsys.readouterr().err
    cfg = tmp_path / "cfg.json"
    cfg.write_text('{"joints3d": {"metod": "volumetric"}}')
    assert cli_run.main(args + ["--images", sim_pair["left"], sim_pair["right"], "--config", str(cfg)]) == 2
    assert "joints3d.metod: unknown key" in capsys.readouterr().err
    assert cli_run.main(["--rig", sim_pair["rig"], "--images", sim_pair["left"], sim_pair["right"],
                         "--model-dir", str(tmp_path / "nomodel")]) == 2
    assert "model folder does not exist" in capsys.readouterr().err


def test_the_default_model_folder_missing_names_the_option_that_gives_one(sim_pair, tmp_path, monkeypatch, capsys):
    """Run from outside the repository (the README's commands, from another folder), ``./models`` is not there: the
    error said where it looked, not how to name the folder."""
    monkeypatch.chdir(tmp_path)
    assert cli_run.main(["--rig", sim_pair["rig"], "--images", sim_pair["left"], sim_pair["right"]]) == 2
    err = capsys.readouterr().err
    assert f"model folder does not exist (read from the current directory {tmp_path})" in err
    assert err.rstrip().endswith("; pass --model-dir (the repository's models/ holds the shipped model)")


def test_the_default_model_folder_missing_under_a_config_naming_none_names_the_option_too(sim_pair, tmp_path,
                                                                                          monkeypatch, capsys):
    """``--config FILE`` without ``session.model_dir`` reads the default ``./models`` as no config does: the hint to
    pass ``--model-dir`` was left out for any ``--config``. A config that names a folder is at fault itself: no hint."""
    monkeypatch.chdir(tmp_path)
    cfg = tmp_path / "cfg.json"
    cfg.write_text('{"joints3d": {"method": "volumetric"}}')
    pair = ["--rig", sim_pair["rig"], "--images", sim_pair["left"], sim_pair["right"], "--config", str(cfg)]
    assert cli_run.main(pair) == 2
    err = capsys.readouterr().err
    assert f"model folder does not exist (read from the current directory {tmp_path})" in err
    assert err.rstrip().endswith(f"; pass --model-dir or session.model_dir in {cfg} (the repository's models/ holds "
                                 f"the shipped model)")
    cfg.write_text('{"session": {"model_dir": "elsewhere"}}')
    assert cli_run.main(pair) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "elsewhere") in err and "model folder does not exist" in err and "--model-dir" not in err


def _graph_named_folder(folder: Path) -> Path:
    """A folder with a file under each graph's name: what ``--validate-config`` looks for (it loads none)."""
    folder.mkdir()
    for graph in GRAPH_NAMES:
        (folder / f"{graph}.onnx").write_bytes(b"")
    return folder


def test_validate_config_prints_the_resolved_tree(tmp_path, capsys):
    cfg = tmp_path / "cfg.json"
    cfg.write_text('{"joints3d": {"method": "volumetric"}}')
    model = str(_graph_named_folder(tmp_path / "m"))
    assert cli_run.main(["--rig", "unused.json", "--images", "a", "b", "--config", str(cfg), "--validate-config",
                         "--model-dir", model]) == 0
    tree = json.loads(capsys.readouterr().out)
    assert tree["joints3d"]["method"] == "volumetric" and tree["session"]["model_dir"] == model
    assert tree["heatmaps"] == {"source": "encoder", "flip_test": True, "flip_test_skip_below": 0.1,
                                "flip_test_side_by_side": True}  # the documented defaults
    assert cli_run.main(["--rig", "unused.json", "--images", "a", "b", "--validate-config", "--no-flip-test"]) == 0
    assert json.loads(capsys.readouterr().out)["heatmaps"]["flip_test"] is False
    cfg.write_text('{"heatmaps": {"flip_test": false}}')  # the flag overrides the config, both ways
    assert cli_run.main(["--rig", "unused.json", "--images", "a", "b", "--config", str(cfg), "--validate-config",
                         "--flip-test"]) == 0
    assert json.loads(capsys.readouterr().out)["heatmaps"]["flip_test"] is True
    assert tree["smoothing"]["enabled"] is True  # on by default
    assert cli_run.main(["--rig", "unused.json", "--images", "a", "b", "--validate-config", "--no-smoothing"]) == 0
    assert json.loads(capsys.readouterr().out)["smoothing"]["enabled"] is False


def test_the_defaults_in_the_docs_are_the_configs():
    text = (Path(__file__).resolve().parents[2] / "docs" / "runtime.md").read_text()
    block = text.split("prints the resolved tree. Defaults:\n\n```json\n", 1)[1].split("```", 1)[0]
    assert json.loads(block) == config_to_dict(EstimatorConfig())


def test_validate_config_needs_no_rig_or_images(tmp_path, capsys):
    cfg = tmp_path / "cfg.json"
    cfg.write_text('{"joints3d": {"method": "volumetric"}}')
    assert cli_run.main(["--config", str(cfg), "--validate-config"]) == 0  # as docs/runtime.md writes it
    assert json.loads(capsys.readouterr().out)["joints3d"]["method"] == "volumetric"
    cfg.write_bytes('{"session": {"model_dir": "mod\xe9ls"}}'.encode("latin-1"))
    assert cli_run.main(["--config", str(cfg), "--validate-config"]) == 2
    assert "not UTF-8" in capsys.readouterr().err


NO_MODEL_FOLDERS = [  # how to make a path that is no model folder, and what the error says of it
    (lambda p: p.write_text("{}"), "is not a folder"),
    (lambda p: None, "model folder does not exist"),
    (lambda p: p.symlink_to(p.parent / "gone"), "is a symbolic link that leads to no folder"),
    (lambda p: p.mkdir(), "no file for graph 'encoder'"),
]


@pytest.mark.parametrize(("make", "said"), NO_MODEL_FOLDERS)
def test_validate_config_refuses_a_model_dir_that_is_no_model_folder(tmp_path, capsys, make, said):
    """It exited 0 and printed the tree; the run then stopped on the folder (docs/runtime.md, "The model folder")."""
    folder = tmp_path / "models"
    make(folder)
    assert cli_run.main(["--model-dir", str(folder), "--validate-config"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and f"error: --model-dir {folder}: {said}" in captured.err, captured.err
    cfg = tmp_path / "cfg.json"  # named by the config instead: its key and the file
    cfg.write_text(json.dumps({"session": {"model_dir": str(folder)}}))
    assert cli_run.main(["--config", str(cfg), "--validate-config"]) == 2
    assert f"error: session.model_dir in {cfg} ({folder}): {said}" in capsys.readouterr().err


@pytest.mark.parametrize(("make", "said"), NO_MODEL_FOLDERS)
def test_a_run_names_the_option_or_key_that_gave_a_model_dir_that_is_no_model_folder(sim_pair, tmp_path, capsys,
                                                                                     make, said):
    """As --validate-config says it: the run said "m.json: is not a folder (session.model_dir names ...)" of a
    file given as --model-dir, naming a key the user never typed."""
    folder = tmp_path / "models"
    make(folder)
    pair = ["--rig", sim_pair["rig"], "--images", sim_pair["left"], sim_pair["right"]]
    assert cli_run.main(pair + ["--model-dir", str(folder)]) == 2
    assert f"error: --model-dir {folder}: {said}" in capsys.readouterr().err
    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps({"session": {"model_dir": str(folder)}}))
    assert cli_run.main(pair + ["--config", str(cfg)]) == 2
    assert f"error: session.model_dir in {cfg} ({folder}): {said}" in capsys.readouterr().err


def test_validate_config_names_a_file_the_settings_turn_on_that_the_folder_lacks(tmp_path, capsys):
    folder = _graph_named_folder(tmp_path / "m")
    assert cli_run.main(["--model-dir", str(folder), "--validate-config"]) == 0
    capsys.readouterr()
    assert cli_run.main(["--model-dir", str(folder), "--validate-config", "--skeleton-prior", "on"]) == 2
    assert f"--model-dir {folder}: joints3d.skeleton_prior = 'on' but the folder has no skeleton_prior.onnx" in \
        capsys.readouterr().err
    (folder / "render_rgb.onnx").unlink()  # novel views run it
    assert cli_run.main(["--model-dir", str(folder), "--validate-config", "--rig", "r.json", "--images", "a", "b",
                         "--novel-view", "n.png"]) == 2
    assert "no file for graph 'render_rgb'" in capsys.readouterr().err


def test_a_corrupt_graph_the_config_does_not_run_is_not_loaded_nor_checked(sim_pair, tiny_model_dir, tmp_path,  # noqa: F811
                                                                           capsys):
    """The runtime loads only the graphs the configuration runs ("Compute only what the scene requires"): with
    ``heatmaps.source`` "rendered" the ``human`` graph is not run, so a damaged ``human`` file is not read and the
    run goes on; the default source runs it and is refused, naming the file. ``--validate-config`` checks the
    config alone and loads no graph (docs/runtime.md, "The model folder; switching models": decided in session 60)."""
    import shutil

    folder = shutil.copytree(tiny_model_dir, tmp_path / "model")
    damaged = sorted(folder.glob("human*.onnx"))
    assert damaged, "the tiny model has a human graph"
    for path in damaged:
        path.write_bytes(path.read_bytes()[:1000])  # cut short: onnxruntime cannot load it
    args = ["--rig", sim_pair["rig"], "--images", sim_pair["left"], sim_pair["right"], "--model-dir", str(folder)]
    out = tmp_path / "joints.json"
    assert cli_run.main([*args, "--heatmap-source", "rendered", "--out", str(out)]) == 0
    assert len(json.loads(out.read_text())) == 1
    capsys.readouterr()
    assert cli_run.main([*args, "--out", str(tmp_path / "refused.json")]) == 2  # the default runs the human graph
    err = capsys.readouterr().err
    assert f"{folder / 'human'}" in err and "onnxruntime cannot load the graph file" in err, err
    assert cli_run.main(["--model-dir", str(folder), "--validate-config"]) == 0


@pytest.mark.parametrize(("extra", "words"), [
    ([], ["--rig"]),
    (["--rig", "r.json"], ["--images", "--videos"]),
    (["--rig", "r.json", "--images", "a", "b", "--novel-stride", "2"], ["--novel-stride", "without --novel-view"]),
    (["--rig", "r.json", "--images", "a", "b", "--novel-alpha", "0.3", "--novel-overlay", "skeleton"],
     ["--novel-alpha, --novel-overlay"]),
    (["--rig", "r.json", "--images", "a", "b", "--novel-path", "orbit"], ["--novel-path", "without --novel-view"]),
    (["--rig", "r.json", "--images", "a", "b", "--novel-view", "n.png", "--novel-path", "arc"], ["--novel-path",
                                                                                                "invalid choice"]),
    (["--rig", "r.json", "--images", "a", "b", "--max-frames", "3"], ["--max-frames applies to --videos"]),
    # refused before the rig and the model are read, by the flag's name: it was NovelViewRequest.alpha at the first pair
    (["--rig", "r.json", "--images", "a", "b", "--novel-view", "n.png", "--novel-alpha", "3"],
     ["--novel-alpha 3.0: ", "in [-1, 2]"]),
    (["--rig", "r.json", "--images", "a", "b", "--novel-view", "n.png", "--novel-alpha", "nan"],
     ["--novel-alpha nan: ", "in [-1, 2]"]),
    (["--rig", "r.json", "--videos", "a", "b", "--max-frames", "0"], ["at least 1"]),
    # a still pair has nothing to smooth: it ran, exit 0 (session 64)
    (["--rig", "r.json", "--images", "a", "b", "--no-smoothing"], ["--no-smoothing applies to --videos"]),
])
def test_flags_that_would_be_ignored_are_refused(extra, words, capsys):
    with pytest.raises(SystemExit) as e:
        cli_run.main(extra)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert all(w in err for w in words), err


@pytest.mark.parametrize("extra, said", [
    (["--skeleton-prior", "off", "--max-prior-error", "0.1"],
     "--max-prior-error with joints3d.skeleton_prior 'off': no skeleton prior runs"),
    (["--method", "depth_centroid", "--max-prior-error", "0.1"],
     "--max-prior-error with joints3d.method 'depth_centroid'"),
    (["--heatmap-source", "rendered", "--flip-test"],
     "--flip-test with heatmaps.source 'rendered': the flip test runs on the encoder's heatmaps only"),
])
def test_a_flag_the_other_settings_turn_off_is_refused_before_anything_is_read(extra, said, capsys):
    """Each ran with the flag without effect, exit 0 (session 64's review): said before the rig or model is read."""
    assert cli_run.main(["--rig", "nowhere.json", "--images", "a.png", "b.png", *extra]) == 2
    err = capsys.readouterr().err
    assert said in err and "nowhere.json" not in err


@pytest.mark.parametrize(("extra", "said"), [
    # each ran and replaced the file: the calibration by the joints, a captured image by its overlay
    (["--images", "a.png", "b.png", "--out", "r.json"], "--out r.json is the file --rig reads"),
    (["--images", "a.png", "b.png", "--overlay", "./sub/../a.png"],
     "--overlay ./sub/../a.png is the file --images (first) reads"),
    (["--videos", "a.mp4", "b.mp4", "--novel-view", "b.mp4"], "--novel-view b.mp4 is the file --videos (second) reads"),
    (["--images", "a.png", "b.png", "--config", "c.json", "--out", "c.json"], "--out c.json is the file --config reads"),
    # the later writer replaced the earlier one's file
    (["--images", "a.png", "b.png", "--overlay", "v.png", "--novel-view", "v.png"],
     "--novel-view v.png is where --overlay writes too"),
])
def test_an_output_that_is_an_input_or_another_output_is_refused(tmp_path, monkeypatch, capsys, extra, said):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "r.json").write_text("{}")
    with pytest.raises(SystemExit) as e:
        cli_run.main(["--rig", "r.json", *extra])
    assert e.value.code == 2 and f"error: {said}: " in capsys.readouterr().err
    assert (tmp_path / "r.json").read_text() == "{}" and not (tmp_path / "v.png").exists()


@pytest.mark.parametrize("flag", ["--images", "--videos"])
def test_one_file_for_both_cameras_is_refused(tmp_path, monkeypatch, capsys, flag):
    """Each camera's view in one picture: the run went on and reported joints, wrong."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:
        cli_run.main(["--rig", "r.json", flag, "a", "./a", "--out", "o.json"])
    assert e.value.code == 2 and f"error: {flag}: a and ./a are one file; give each camera's own" in \
        capsys.readouterr().err


@pytest.mark.parametrize(("make", "said"), [
    (lambda p: None, "no such file"),
    (lambda p: p.mkdir(), "a folder, not a video"),
    (lambda p: p.write_bytes(b"not a video"), "cannot open the video (not a format OpenCV reads, or unreadable)"),
])
def test_a_video_that_cannot_be_opened_says_why(tmp_path, monkeypatch, capsys, make, said):
    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _StubEstimator())
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    make(tmp_path / "a.mp4")
    (tmp_path / "b.mp4").write_bytes(b"")
    assert cli_run.main(["--rig", "r.json", "--videos", str(tmp_path / "a.mp4"), str(tmp_path / "b.mp4"),
                         "--out", str(tmp_path / "o.json")]) == 2
    assert f"{tmp_path / 'a.mp4'}: {said}" in capsys.readouterr().err  # was "cannot open the video", whatever why


@pytest.mark.parametrize("path", ["line", "orbit", "auto"])
def test_novel_path_sets_the_configs_path(path, capsys):
    args = ["--rig", "unused.json", "--images", "a", "b", "--novel-view", "n.png", "--validate-config"]
    assert cli_run.main(args + ["--novel-path", path]) == 0
    assert json.loads(capsys.readouterr().out)["novel_view"]["path"] == path


def test_threads_zero_is_refused_by_the_config_check(capsys):
    assert cli_run.main(["--validate-config", "--threads", "0"]) == 2
    assert "threads" in capsys.readouterr().err


def test_an_output_image_of_unknown_kind_is_refused_before_the_run(sim_pair, tiny_model_dir, tmp_path, capsys):  # noqa: F811
    args = ["--rig", sim_pair["rig"], "--model-dir", str(tiny_model_dir), "--images", sim_pair["left"],
            sim_pair["right"], "--out", str(tmp_path / "j.json")]
    assert cli_run.main(args + ["--overlay", str(tmp_path / "overlay.txt")]) == 2
    assert "overlay.txt: cannot write an image of this kind" in capsys.readouterr().err
    assert not (tmp_path / "j.json").exists() or (tmp_path / "j.json").read_text() == ""
    (tmp_path / "pics").mkdir()  # a folder where the image goes: said before the run, not when the file is closed
    assert cli_run.main(args + ["--novel-view", str(tmp_path / "pics")]) == 2
    assert f"--novel-view {tmp_path / 'pics'}: is a folder" in capsys.readouterr().err
    # a missing folder is made, and the image is written at the end of the run
    assert cli_run.main(args + ["--overlay", str(tmp_path / "new" / "overlay.png")]) == 0
    assert (tmp_path / "new" / "overlay.png").is_file()


def test_bench_runtime_interleaves_every_row_over_every_sequence(tiny_model_dir, tmp_path):  # noqa: F811
    """``ghnerf-bench runtime`` smoke run: every row counts the same pairs (warm-up excluded)."""
    from ghnerf_runtime.cli import bench

    report_path = tmp_path / "bench.json"
    # the random weights find nobody, and a pair with nobody has no novel view: the presence gate off views them
    code = bench.main(["runtime", "--model-dir", str(tiny_model_dir), "--sequences", "2", "--frames", "3",
                       "--precisions", "fp32,int8", "--heatmap-sources", "encoder", "--warmup", "2",
                       "--presence-gates", "off",
                       "--cache", str(tmp_path / "cache"), "--json", str(report_path)])
    assert code == 0
    report = json.loads(report_path.read_text())
    assert report["interleaved"] and len(report["runs"]) == 4  # 2 precisions x (keypoints, + novel view)
    assert all(r["presence"] is False and r["presence_label"] for r in report["runs"])
    for row in report["runs"]:
        assert row["pairs"] == 2 * 3 - 2
        assert row["pairs_per_s"] > 0 and math.isfinite(row["total"]["median"])
    novel = [r for r in report["runs"] if r["mode"] == "keypoints+novel"]
    assert all(r["novel view"]["median"] > 0 for r in novel)
    assert all(r["novel_interior_stride"] == 0 for r in novel)  # the config's default
    for row in report["runs"]:  # the MPJPE split by the cameras that see each joint covers every joint once
        by = row["accuracy"]["mpjpe_by_visibility"]
        assert set(by) == {"all_views", "some_views", "no_view"}
        assert sum(c["share"] for c in by.values()) == pytest.approx(1.0)
        assert sum(c["joints"] for c in by.values()) == row["accuracy"]["mpjpe_evaluated"]
        swaps = row["accuracy"]["left_right_swaps"]
        assert len(swaps["by_view"]) == 2 and len(swaps["by_view_evaluated"]) == 2
        for f, n in zip(swaps["by_view"], swaps["by_view_evaluated"]):  # null (nan) only for a view of no pairs
            assert (f is None) if n == 0 else 0.0 <= f <= 1.0
        assert "jitter_mm" in row["accuracy"] and row["smoothing"] is True  # the config's default


def test_bench_runtime_rows_with_the_turn_search_on_and_off(tiny_model_dir, tmp_path, capsys):  # noqa: F811
    """``--turn-searches on,off``: one keypoint row each, labelled, the search set in each row's config (the bench
    took no such row: roi.turn_search could not be benched on the whole sequences)."""
    from ghnerf_runtime.cli import bench

    report_path = tmp_path / "bench.json"
    code = bench.main(["runtime", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "2",
                       "--precisions", "fp32", "--heatmap-sources", "encoder", "--modes", "keypoints", "--warmup",
                       "0", "--turn-searches", "on,off", "--cache", str(tmp_path / "cache"), "--json",
                       str(report_path)])
    assert code == 0
    runs = json.loads(report_path.read_text())["runs"]
    assert [(r["turn_search"], r["turn_search_label"]) for r in runs] == [(True, True), (False, True)]
    out = capsys.readouterr().out
    assert " turn-search " in out and " no-turn-search " in out


def test_bench_runtime_rows_with_the_cold_start_refinement_on_and_off(tiny_model_dir, tmp_path, capsys):  # noqa: F811
    """``--refine-cold-starts on,off``: one keypoint row each, labelled, tracking.refine_cold_start set in each
    row's config, and each row scores its sequences' first pairs (the cold starts the refinement acts on) apart:
    the bench had no row for the knob that runs a cold first pair twice (its p99 over every pair)."""
    from ghnerf_runtime.cli import bench

    report_path = tmp_path / "bench.json"
    code = bench.main(["runtime", "--model-dir", str(tiny_model_dir), "--sequences", "2", "--frames", "2",
                       "--precisions", "fp32", "--heatmap-sources", "encoder", "--modes", "keypoints", "--warmup",
                       "1", "--refine-cold-starts", "on,off", "--cache", str(tmp_path / "cache"), "--json",
                       str(report_path)])
    assert code == 0
    runs = json.loads(report_path.read_text())["runs"]
    assert [(r["refine_cold_start"], r["refine_label"]) for r in runs] == [(True, True), (False, True)]
    # every sequence's first pair, the warm-up's too (the warm-up is a matter of timing)
    assert [r["accuracy_first_pair"]["pairs"] for r in runs] == [2, 2]
    assert all("jitter_mm" not in r["accuracy_first_pair"] for r in runs)
    out = capsys.readouterr().out
    assert " refine-cold " in out and " no-refine-cold " in out
    assert out.count("each sequence's first pair (2 pairs): PCK@0.2 ") == 2


@pytest.mark.skipif(not (Path(__file__).resolve().parents[2] / "models" / "baseline").is_dir(),
                    reason="no models/baseline")
def test_bench_runs_a_model_without_encoder_heatmaps_with_the_turn_search_off(tmp_path):
    """roi.turn_search is on by default (session 57) and refuses a model without encoder heatmaps: the bench's
    rows of the baseline run with it off, unlabelled (before, they took the default, off)."""
    from ghnerf_runtime.cli import bench

    report_path = tmp_path / "bench.json"
    code = bench.main(["runtime", "--model-dir", str(Path(__file__).resolve().parents[2] / "models" / "baseline"),
                       "--sequences", "1", "--frames", "2", "--precisions", "int8", "--heatmap-sources", "rendered",
                       "--modes", "keypoints", "--warmup", "0", "--turn-searches", "on,off",
                       "--cache", str(tmp_path / "cache"), "--json", str(report_path)])
    assert code == 0
    runs = json.loads(report_path.read_text())["runs"]
    assert [(r["turn_search"], r["turn_search_label"]) for r in runs] == [(False, False)]


def test_bench_accuracy_counts_left_right_swaps_per_view():
    """A pair whose shoulders are exchanged in view 1 only: swapped there, not in view 0, not in both."""
    from types import SimpleNamespace

    from ghnerf_runtime.body25 import JOINT_INDEX, NUM_JOINTS
    from ghnerf_runtime.cli.simdata import Accuracy

    rng = np.random.default_rng(0)
    truth_2d = rng.uniform(100, 400, (2, NUM_JOINTS, 2))
    truth_2d[:, JOINT_INDEX["MidHip"]] = truth_2d[:, JOINT_INDEX["Neck"]] + [0.0, 150.0]  # PCK radius 30 px
    r, l, neck = JOINT_INDEX["RShoulder"], JOINT_INDEX["LShoulder"], truth_2d[:, JOINT_INDEX["Neck"]]
    truth_2d[:, r], truth_2d[:, l] = neck - [60.0, 0], neck + [60.0, 0]
    pred = {"a": truth_2d[0].copy(), "b": truth_2d[1].copy()}
    pred["b"][[r, l]] = pred["b"][[l, r]]
    none = np.zeros(NUM_JOINTS, bool)
    result = SimpleNamespace(joints_2d=pred, missing_2d={"a": none, "b": none}, joints_3d=np.zeros((NUM_JOINTS, 3)),
                             missing=none, confidence=np.ones(NUM_JOINTS, np.float32), tracked=True)
    acc = Accuracy()
    acc.add_truth(result, np.zeros((NUM_JOINTS, 3)), truth_2d, np.ones((2, NUM_JOINTS), bool))
    sw = acc.summary()["left_right_swaps"]
    assert sw["by_view"] == [0.0, pytest.approx(1 / 11)]  # 11 pairs, all evaluated in each view
    assert sw["by_view_evaluated"] == [11, 11]
    assert sw["all_views_frac"] == 0.0 and sw["all_views_evaluated"] == 11
    # the 2D error: 48 of the 50 visible joints exact, the two exchanged shoulders 120 px off
    e2 = acc.summary()["error_2d_px"]
    assert e2["median"] == 0.0 and e2["p90"] == 0.0


def test_bench_swap_shares_of_no_pairs_are_nan_not_zero(capsys):
    """A view with no left/right pair decoded (nothing found there) reported 0.0 % swapped, as if every pair
    were right: the share of nothing is nan (null in --json, n/a printed), with the count beside it."""
    from types import SimpleNamespace

    from ghnerf_runtime.body25 import JOINT_INDEX, NUM_JOINTS
    from ghnerf_runtime.cli import bench
    from ghnerf_runtime.cli.simdata import Accuracy

    truth_2d = np.random.default_rng(1).uniform(100, 400, (2, NUM_JOINTS, 2))
    truth_2d[:, JOINT_INDEX["MidHip"]] = truth_2d[:, JOINT_INDEX["Neck"]] + [0.0, 150.0]
    none, every = np.zeros(NUM_JOINTS, bool), np.ones(NUM_JOINTS, bool)
    result = SimpleNamespace(joints_2d={"a": truth_2d[0], "b": truth_2d[1]}, missing_2d={"a": none, "b": every},
                             joints_3d=np.zeros((NUM_JOINTS, 3)), missing=none,
                             confidence=np.ones(NUM_JOINTS, np.float32), tracked=True)
    acc = Accuracy()
    acc.add_truth(result, np.zeros((NUM_JOINTS, 3)), truth_2d, np.ones((2, NUM_JOINTS), bool))
    sw = acc.summary()["left_right_swaps"]
    assert sw["by_view"][0] == 0.0 and math.isnan(sw["by_view"][1]) and sw["by_view_evaluated"] == [11, 0]
    assert math.isnan(sw["all_views_frac"]) and sw["all_views_evaluated"] == 0
    bench._print_row({"precision": "fp32", "heatmaps": "encoder", "method": "triangulate", "mode": "keypoints",
                      "pairs_per_s": 1.0, "load_average": 0.0, "accuracy": {"left_right_swaps": sw},
                      **{name: {"median": 1.0, "p99": 1.0} for name in bench.STAGE_GROUPS}})
    line = [s for s in capsys.readouterr().out.splitlines() if "swapped" in s][0]
    assert "view 0 0.0 % (11 pairs), view 1 n/a (0 pairs)" in line and "in every view alike n/a (0 pairs)" in line


def test_bench_accuracy_jitter_chains_consecutive_frames_of_one_stream():
    """The jitter pools inner frames of runs of consecutive frames of one stream: a new stream or a
    skipped frame breaks the chain."""
    from types import SimpleNamespace

    from ghnerf_runtime.body25 import NUM_JOINTS
    from ghnerf_runtime.cli.simdata import Accuracy

    none = np.zeros(NUM_JOINTS, bool)
    acc = Accuracy()
    # stream "a": frames 0-3 with errors 0, 1, 0, 0 mm on every joint along x (jitter 2 then 1 mm);
    # stream "b": frames 0, 1, then 3 (2 skipped) with a 5 mm jump: no three consecutive frames
    for stream, i, err_mm in (("a", 0, 0), ("a", 1, 1), ("a", 2, 0), ("a", 3, 0), ("b", 0, 0), ("b", 1, 0),
                              ("b", 3, 5)):
        result = SimpleNamespace(joints_2d={}, missing_2d={}, joints_3d=np.full((NUM_JOINTS, 3), [err_mm / 1e3, 0, 0]),
                                 missing=none, confidence=np.ones(NUM_JOINTS, np.float32), tracked=True)
        acc.add_truth(result, np.zeros((NUM_JOINTS, 3)), frame=(stream, i))
    s = acc.summary()
    assert s["jitter_evaluated"] == 2 * NUM_JOINTS and s["jitter_mm"] == pytest.approx(1.5)
    plain = Accuracy()  # pairs that do not say which frame they are: no jitter
    plain.add_truth(result, np.zeros((NUM_JOINTS, 3)))
    assert "jitter_mm" not in plain.summary()


def test_bench_runtime_compares_novel_interior_strides_side_by_side(tiny_model_dir, tmp_path):  # noqa: F811
    from ghnerf_runtime.cli import bench

    report_path = tmp_path / "bench.json"
    assert bench.main(["runtime", "--model-dir", str(tiny_model_dir), "--sequences", "2", "--frames", "2",
                       "--precisions", "fp32", "--heatmap-sources", "encoder", "--modes", "novel", "--warmup", "0",
                       "--novel-interior-strides", "0,2", "--cache", str(tmp_path / "cache"),
                       "--json", str(report_path)]) == 0
    runs = json.loads(report_path.read_text())["runs"]
    assert [r["novel_interior_stride"] for r in runs] == [0, 2]
    assert all(r["pairs"] == 4 and r["mode"] == "keypoints+novel" for r in runs)


def test_bench_runtime_compares_the_proxy_blend_on_and_off(tiny_model_dir, tmp_path, capsys):  # noqa: F811
    from ghnerf_runtime.cli import bench

    report_path = tmp_path / "bench.json"
    assert bench.main(["runtime", "--model-dir", str(tiny_model_dir), "--sequences", "2", "--frames", "2",
                       "--precisions", "fp32", "--heatmap-sources", "encoder", "--modes", "keypoints,novel",
                       "--warmup", "0", "--proxy-blends", "off,on", "--cache", str(tmp_path / "cache"),
                       "--json", str(report_path)]) == 0
    runs = json.loads(report_path.read_text())["runs"]
    assert [(r["mode"], r.get("proxy_blend")) for r in runs] == [
        ("keypoints", None), ("keypoints+novel", False), ("keypoints+novel", True)]
    assert "no-proxy-blend" in capsys.readouterr().out


def test_bench_runtime_compares_the_painter_on_and_off(tiny_model_dir, tmp_path, capsys):  # noqa: F811
    import shutil

    from ghnerf_runtime.cli import bench
    from tests.ghnerf_runtime.test_novel_painter import blend_painter

    models = tmp_path / "models"
    shutil.copytree(tiny_model_dir, models)
    report_path = tmp_path / "bench.json"
    args = ["runtime", "--sequences", "1", "--frames", "2", "--precisions", "fp32", "--heatmap-sources", "encoder",
            "--modes", "novel", "--warmup", "0", "--painters", "off,on", "--cache", str(tmp_path / "cache"),
            "--json", str(report_path)]
    assert bench.main(["runtime", "--model-dir", str(models), *args[1:]]) != 0  # on, and the folder has none
    assert "no novel_painter.onnx" in capsys.readouterr().err
    blend_painter(models / "novel_painter.onnx")
    assert bench.main(["runtime", "--model-dir", str(models), *args[1:]]) == 0
    runs = json.loads(report_path.read_text())["runs"]
    assert [r.get("painter") for r in runs] == [False, True]
    assert "no-painter" in capsys.readouterr().out


def test_bench_runtime_compares_the_flip_test_and_encoder_following_on_and_off(tiny_model_dir, tmp_path, capsys):  # noqa: F811
    from ghnerf_runtime.cli import bench

    report_path = tmp_path / "bench.json"
    assert bench.main(["runtime", "--model-dir", str(tiny_model_dir), "--sequences", "2", "--frames", "2",
                       "--precisions", "fp32", "--heatmap-sources", "encoder,rendered", "--modes", "keypoints",
                       "--warmup", "0", "--flip-tests", "on,off", "--follow-encoder", "on,off",
                       "--cache", str(tmp_path / "cache"), "--json", str(report_path)]) == 0
    runs = json.loads(report_path.read_text())["runs"]
    # two encoder rows (the flip test on, off), two rendered rows (following the encoder or its own joints;
    # the flip test does not apply to them, nor the following to the encoder rows)
    assert [(r["heatmaps"], r["flip_test"], r["follow_encoder"]) for r in runs] == [
        ("encoder", True, True), ("encoder", False, True), ("rendered", False, True), ("rendered", False, False)]
    assert all(r["pairs"] == 4 for r in runs)
    out = capsys.readouterr().out
    assert "keypoints flip" in out and "keypoints no-flip" in out
    assert "keypoints follow-enc" in out and "keypoints follow-own" in out
    with pytest.raises(SystemExit):
        bench.main(["runtime", "--flip-tests", "maybe"])


def test_bench_runtime_compares_smoothing_on_and_off(tiny_model_dir, tmp_path, capsys):  # noqa: F811
    from ghnerf_runtime.cli import bench

    report_path = tmp_path / "bench.json"
    assert bench.main(["runtime", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "3",
                       "--precisions", "fp32", "--heatmap-sources", "encoder", "--modes", "keypoints",
                       "--warmup", "0", "--smoothing", "on,off", "--cache", str(tmp_path / "cache"),
                       "--json", str(report_path)]) == 0
    runs = json.loads(report_path.read_text())["runs"]
    assert [r["smoothing"] for r in runs] == [True, False] and all(r["pairs"] == 3 for r in runs)
    out = capsys.readouterr().out
    assert "keypoints smooth" in out and "keypoints no-smooth" in out and "mm/pair^2" in out


def test_simdata_doctests():
    """``depth_per_disparity_px``: a 1 m baseline, f = 500 px, 3 m away: 18 mm of depth per pixel."""
    import doctest

    from ghnerf_runtime.cli import simdata

    result = doctest.testmod(simdata, raise_on_error=False)
    assert result.attempted >= 5 and result.failed == 0, result  # 5 examples when written


_ONE_PAIR = ["--sequences", "1", "--frames", "1", "--warmup", "0", "--cache", "off"]  # quick, should a check miss


@pytest.mark.parametrize(("args", "words"), [
    (["--sequences", "0"], "at least 1"),
    (["--precisions", ","], "precisions are"),
    (["--sequences", "1", "--frames", "5", "--warmup", "10"], "nothing would be timed"),
    # empty lists: no row to run (a ZeroDivisionError once the sequences were rendered, minutes in)
    (["--modes", ",", *_ONE_PAIR], "modes keypoints,novel"),
    (["--heatmap-sources", "", *_ONE_PAIR], "heatmap sources are"),
])
def test_bench_refuses_a_run_that_would_time_nothing(args, words, capsys):
    from ghnerf_runtime.cli import bench

    assert bench.main(["runtime", "--model-dir", "unused", *args]) == 2
    assert words in capsys.readouterr().err


@pytest.mark.parametrize(("args", "words"), [
    (["--motion", "jump"], "unknown motion 'jump'"),  # the simulator's SimConfigError, a DriverError
    (["--frames", "0"], "--frames must be at least 1"),
    (["--frames", "-2"], "--frames must be at least 1"),
])
def test_bench_sim_pair_refuses_bad_input_with_a_message(args, words, tmp_path, capsys):
    from ghnerf_runtime.cli import bench

    assert bench.main(["sim-pair", "--out", str(tmp_path / "ex"), *args]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
    assert not (tmp_path / "ex" / "truth.json").exists()  # no empty set written


def test_a_still_pair_refines_its_cold_start_by_default(capsys):
    """One pair has no next pair to track with: its crude working-volume crop is run again on the subject."""
    def resolved(*args):
        assert cli_run.main(["--validate-config", *args]) == 0
        return json.loads(capsys.readouterr().out)["tracking"]["refine_cold_start"]

    assert resolved("--rig", "r.json", "--images", "a", "b") is True
    assert resolved("--rig", "r.json", "--images", "a", "b", "--no-refine-cold-start") is False
    assert resolved("--rig", "r.json", "--videos", "a", "b") is True  # the config's default: the first pair too
    assert resolved("--rig", "r.json", "--videos", "a", "b", "--no-refine-cold-start") is False


class _StubEstimator:
    """Answers ``estimate`` with a minimal result, raising ``fail`` at pair ``fail_at`` (a mid-run error), and
    appending each pair's ``timestamp_s`` to ``times`` when given."""

    size = 64

    def __init__(self, fail_at: int | None = None, fail: BaseException | None = None, times: list | None = None):
        self.fail_at, self.fail, self.times = fail_at, fail, times
        self.session = type("S", (), {"describe": staticmethod(lambda: {})})()

    def estimate_then_view(self, images, *, sequence, novel_view=None, timestamp_s=None):
        """Estimator.estimate_then_view: the result, and no novel view to finish."""
        if self.times is not None:
            self.times.append(timestamp_s)
        if sequence == self.fail_at:
            raise self.fail
        return type("R", (), {"to_json": lambda r: {"sequence": sequence}, "num_found": 0, "novel_view": None,
                              "sequence": sequence, "timing_ms": {"total": 1.0}})(), None


def _stub_run(monkeypatch, out: Path, pairs: int = 3, **stub) -> tuple[int, list]:
    """``ghnerf-run --videos`` over ``pairs`` blank pairs with the stub estimator: (exit status, estimators built)."""
    built = []

    def from_config(rig, cfg):
        built.append(_StubEstimator(**stub))
        return built[-1]

    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run.Estimator, "from_config", from_config)
    monkeypatch.setattr(cli_run, "_pairs", lambda args: iter([(np.zeros((4, 4, 3), np.uint8),) * 2] * pairs))
    return cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(out)]), built


def test_a_json_output_keeps_the_pairs_finished_before_an_error(monkeypatch, tmp_path, capsys):
    from ghnerf_runtime.errors import ModelRunError

    out = tmp_path / "joints.json"
    out.write_text("an earlier run's list\n")
    rc, _ = _stub_run(monkeypatch, out, fail_at=2, fail=ModelRunError("render_heat failed"))
    assert rc == 2  # before: the file was truncated at the start and the two finished pairs lost
    assert json.loads(out.read_text()) == [{"sequence": 0, "time_s": 0.0}, {"sequence": 1, "time_s": 0.033333}]
    err = capsys.readouterr().err
    assert "render_heat failed" in err and "2 pair(s) finished" in err
    assert [p.name for p in tmp_path.iterdir()] == ["joints.json"]  # no temporary file left behind


class _ViewStub(_StubEstimator):
    """As the stub, each pair's view left to finish (NovelViewPipeline then holds one pair in flight)."""

    def __init__(self, fail_at: int | None = None, fail: BaseException | None = None, view_fails_at=None):
        super().__init__(fail_at, fail)
        self.view_fails_at = view_fails_at

    def estimate_then_view(self, images, *, sequence, novel_view=None, timestamp_s=None):
        result, _ = super().estimate_then_view(images, sequence=sequence)

        def finish():
            if sequence == self.view_fails_at:
                raise ModelRunError(f"render_rgb failed on pair {sequence}")
            return result
        return result, finish


@pytest.mark.parametrize("fail", ["error", "ctrl_c"])
def test_a_stop_keeps_the_pair_whose_view_was_being_finished(monkeypatch, tmp_path, capsys, fail):
    """ghnerf-run --novel-view finishes pair N's view while pair N+1 is estimated: a stop at pair N+1 (an
    error, Ctrl-C) still writes pair N, as one by one it was written before N+1 began (it was dropped)."""
    out = tmp_path / "joints.jsonl"
    error = ModelRunError("encoder failed") if fail == "error" else KeyboardInterrupt()
    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _ViewStub(fail_at=2, fail=error))
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run, "_pairs", lambda args: iter([(np.zeros((4, 4, 3), np.uint8),) * 2] * 4))
    rc = cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(out)])
    assert rc == (2 if fail == "error" else 130)
    assert [json.loads(line)["sequence"] for line in out.read_text().splitlines()] == [0, 1]
    assert ("encoder failed" if fail == "error" else "stopped (SIGINT)") in capsys.readouterr().err


def test_a_pair_after_a_failed_view_is_not_written_past_the_gap(monkeypatch, tmp_path, capsys):
    """Pair 1's view fails while pair 2 is estimated: the run stops with that error, pairs 0 only (pair 2,
    finished behind it, is not written after the missing pair 1)."""
    out = tmp_path / "joints.jsonl"
    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _ViewStub(view_fails_at=1))
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run, "_pairs", lambda args: iter([(np.zeros((4, 4, 3), np.uint8),) * 2] * 4))
    assert cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(out)]) == 2
    assert [json.loads(line)["sequence"] for line in out.read_text().splitlines()] == [0]
    assert "render_rgb failed on pair 1" in capsys.readouterr().err


def test_a_json_output_is_left_as_it_was_when_no_pair_finished(monkeypatch, tmp_path):
    from ghnerf_runtime.errors import ModelRunError

    out = tmp_path / "joints.json"
    out.write_text("[{\"sequence\": 7}]\n")
    rc, _ = _stub_run(monkeypatch, out, fail_at=0, fail=ModelRunError("encoder failed"))
    assert rc == 2 and out.read_text() == "[{\"sequence\": 7}]\n"


def test_a_json_output_keeps_the_pairs_finished_before_ctrl_c(monkeypatch, tmp_path, capsys):
    out = tmp_path / "joints.json"
    rc, _ = _stub_run(monkeypatch, out, fail_at=1, fail=KeyboardInterrupt())
    assert rc == 130 and json.loads(out.read_text()) == [{"sequence": 0, "time_s": 0.0}]
    err = capsys.readouterr().err
    assert "ghnerf-run: stopped (SIGINT)" in err and "Traceback" not in err  # was a 25-line traceback
    rc, _ = _stub_run(monkeypatch, out)  # a whole run replaces it
    assert rc == 0 and len(json.loads(out.read_text())) == 3


def test_out_is_checked_before_the_model_loads(monkeypatch, tmp_path, capsys):
    (tmp_path / "dir.json").mkdir()
    rc, built = _stub_run(monkeypatch, tmp_path / "dir.json")
    assert rc == 2 and not built
    assert f"--out {tmp_path / 'dir.json'}: is a folder" in capsys.readouterr().err
    rc, _ = _stub_run(monkeypatch, tmp_path / "new" / "joints.jsonl")  # its folder is made, lines as they come
    assert rc == 0 and len((tmp_path / "new" / "joints.jsonl").read_text().splitlines()) == 3


def test_sigterm_stops_a_run_as_ctrl_c_does(monkeypatch, tmp_path, capsys):
    import os
    import signal

    out = tmp_path / "joints.jsonl"

    class _Killed(_StubEstimator):
        def estimate_then_view(self, images, *, sequence, novel_view=None, timestamp_s=None):
            if sequence == 1:
                os.kill(os.getpid(), signal.SIGTERM)  # as timeout(1) or systemd stop it
            return super().estimate_then_view(images, sequence=sequence)

    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _Killed())
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run, "_pairs", lambda args: iter([(np.zeros((4, 4, 3), np.uint8),) * 2] * 3))
    before = signal.getsignal(signal.SIGTERM)
    rc = cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(out)])
    assert rc == 143 and "stopped (SIGTERM)" in capsys.readouterr().err
    assert [json.loads(line)["sequence"] for line in out.read_text().splitlines()] == [0]
    assert signal.getsignal(signal.SIGTERM) == before  # put back


def test_a_jsonl_output_is_left_as_it_was_when_an_input_fails_before_the_first_pair(monkeypatch, tmp_path, capsys):
    out = tmp_path / "joints.jsonl"
    out.write_text("an earlier run's lines\n")

    def no_pairs(args):
        raise cli_run.UsageError("b.mp4: cannot open the video")
        yield  # pragma: no cover - a generator, as the real one

    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _StubEstimator())
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run, "_pairs", no_pairs)
    assert cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(out)]) == 2
    assert out.read_text() == "an earlier run's lines\n"  # was emptied before the input was read


def test_a_jsonl_output_on_a_full_disk_keeps_whole_lines_and_names_out(monkeypatch, tmp_path, capsys):
    """The disk fills at the third pair's line: it was OSError's bare "[Errno 28] No space left on device" (no
    option, no file named) with the line left half written."""
    import errno
    import os

    out = tmp_path / "joints.jsonl"
    writes = []

    def fills_up(fd, data):
        writes.append(data)
        if len(writes) == 3:
            os.write(fd, bytes(data[: len(data) // 2]))
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        os.write(fd, data)

    monkeypatch.setattr(cli_run, "_write_all", fills_up)
    rc, _ = _stub_run(monkeypatch, out, pairs=5)
    assert rc == 2 and len(writes) == 3  # no line past the gap
    assert [json.loads(line)["sequence"] for line in out.read_text().splitlines()] == [0, 1]
    assert out.read_text().endswith("}\n")
    err = capsys.readouterr().err
    assert f"--out {out}: cannot write pair 2's line (No space left on device); it holds the 2 pair(s)" in err


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full here")
def test_a_jsonl_output_that_cannot_be_written_names_out(monkeypatch, capsys):
    """/dev/full, a disk with no room from the first line."""
    rc, _ = _stub_run(monkeypatch, Path("/dev/full"), pairs=2)
    err = capsys.readouterr().err
    assert rc == 2 and "--out /dev/full: cannot write pair 0's line (No space left on device)" in err


def _disk_full(monkeypatch) -> None:
    """A disk that fills up under the image: OpenCV's imwrite truncates the file, writes part of it and returns
    False (libpng's "Write Error"); a file written from Python fails its fsync with ENOSPC."""
    import errno
    import os

    def imwrite(path, image):
        Path(path).write_bytes(cv2.imencode(".png", image)[1].tobytes()[:20])
        return False

    def fsync(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(cli_run.cv2, "imwrite", imwrite)
    monkeypatch.setattr(os, "fsync", fsync)


def test_an_image_output_that_cannot_be_written_names_its_option(monkeypatch, tmp_path):
    """A full disk: the error named the file only, and guessed a permission."""
    sink = cli_run._Sink(str(tmp_path / "novel.png"), flag="--novel-view")
    sink.add(np.zeros((4, 4, 3), np.uint8))
    _disk_full(monkeypatch)
    with pytest.raises(cli_run.UsageError,
                       match=r"^--novel-view .*novel\.png: cannot write the image \(No space left on device\)"):
        sink.close()


def test_an_image_output_that_cannot_be_written_leaves_the_earlier_one_whole(monkeypatch, tmp_path):
    """imwrite truncated the file before writing it: a full disk left the last run's novel.png cut short."""
    path = tmp_path / "novel.png"
    earlier = cv2.imencode(".png", np.full((4, 4, 3), 200, np.uint8))[1].tobytes()
    path.write_bytes(earlier)
    sink = cli_run._Sink(str(path), flag="--novel-view")
    sink.add(np.zeros((4, 4, 3), np.uint8))
    _disk_full(monkeypatch)
    with pytest.raises(cli_run.UsageError, match=r"cannot write the image"):
        sink.close()
    assert path.read_bytes() == earlier
    assert [p.name for p in tmp_path.iterdir()] == ["novel.png"]  # no temporary file left beside it


@pytest.mark.parametrize("name", ["novel.png", "novel.JPG"])
def test_an_image_output_is_written_in_the_format_its_suffix_names(tmp_path, name):
    image = np.random.default_rng(0).integers(0, 255, (8, 8, 3), np.uint8)
    sink = cli_run._Sink(str(tmp_path / name), flag="--novel-view")
    sink.add(image)
    sink.close()
    read = cv2.imread(str(tmp_path / name))
    assert read.shape == image.shape
    if name.endswith(".png"):
        assert np.array_equal(read, image)  # lossless


def test_a_closed_pipe_ends_the_run_quietly(monkeypatch, tmp_path):
    # `ghnerf-run ... --out - | head`: was "error: [Errno 32] Broken pipe" and status 2
    class _Closed:
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            pass

        def fileno(self):
            return -1

    monkeypatch.setattr(cli_run.sys, "stdout", _Closed())
    monkeypatch.setattr(cli_run.os, "dup2", lambda fd, target: None)
    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _StubEstimator())
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run, "_pairs", lambda args: iter([(np.zeros((4, 4, 3), np.uint8),) * 2] * 3))
    assert cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", "-"]) == 0


@pytest.mark.parametrize("rate", [float("nan"), 0.0, -25.0, float("inf")])
def test_a_video_without_a_usable_frame_rate_is_timed_at_30_fps(monkeypatch, tmp_path, rate):
    """A container whose rate reads NaN, 0, negative or inf: the pairs are timed at 30 fps (a NaN time is a
    FrameError since the estimator refuses it, which ended the run at its first pair)."""
    times = []

    # frames without presentation times (NaN), so each step is a frame at the rate
    monkeypatch.setattr(cli_run.cv2, "VideoCapture", _video_with_times([float("nan")] * 3, rate))
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _StubEstimator(times=times))
    assert cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(tmp_path / "j.jsonl")]) == 0
    assert times == pytest.approx([0.0, 1 / 30, 2 / 30])


def test_each_video_is_opened_once_its_rate_read_where_it_is_opened(monkeypatch, tmp_path):
    """The run opened the first video a second time, only to read its frame rate, before the pairs opened it
    again (twice the container's parsing, and a rate read from another capture than the frames'). Each capture
    is released at the end."""
    opened = []
    timed_capture = _video_with_times([0.0, float("nan"), float("nan")], 25.0)

    class _Counted(timed_capture):
        def __init__(self, path):
            super().__init__(path)
            self.path, self.released = path, False
            opened.append(self)

        def release(self):
            self.released = True

    times = []

    monkeypatch.setattr(cli_run.cv2, "VideoCapture", _Counted)
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _StubEstimator(times=times))
    assert cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(tmp_path / "j.jsonl")]) == 0
    assert [cap.path for cap in opened] == ["a.mp4", "b.mp4"]
    assert all(cap.released for cap in opened)
    assert times == pytest.approx([0.0, 0.04, 0.08])  # the rate (25 fps) of the capture the frames came from


def _video_with_times(pts_ms, fps):
    """A stand-in for ``cv2.VideoCapture``: 4x4 frames whose presentation times are ``pts_ms`` (NaN: the backend
    gives none), at the container rate ``fps``."""

    class _Cap:
        def __init__(self, path):
            self.k = -1

        def isOpened(self):
            return True

        def read(self):
            self.k += 1
            return self.k < len(pts_ms), np.zeros((4, 4, 3), np.uint8)

        def set(self, prop, value):
            return prop == cv2.CAP_PROP_ORIENTATION_AUTO

        def get(self, prop):
            if prop == cv2.CAP_PROP_ORIENTATION_AUTO:
                return 0.0
            return fps if prop == cv2.CAP_PROP_FPS else pts_ms[self.k]

        def release(self):
            pass

    return _Cap


def test_video_pairs_are_timed_by_their_frames_presentation_times(monkeypatch, tmp_path):
    """A variable frame rate (a phone's video), or a container whose rate reads 1000 fps for 30: frame number / fps
    made every step wrong (1 ms for 33: the smoothing then lagged a moving subject by most of each step). The
    frames' own times are used where they follow the last pair's, the last plus a frame at the rate where not (a
    backend that gives none, a time that stands still)."""
    pts_ms = [0.0, 33.0, 70.0, float("nan"), 140.0, 140.0, 210.0]
    times = []

    monkeypatch.setattr(cli_run.cv2, "VideoCapture", _video_with_times(pts_ms, 1000.0))
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _StubEstimator(times=times))
    assert cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(tmp_path / "j.jsonl")]) == 0
    assert times == pytest.approx([0.0, 0.033, 0.070, 0.071, 0.140, 0.141, 0.210])


def test_each_video_pair_s_output_says_when_it_was_filmed(monkeypatch, tmp_path):
    """With a variable frame rate the sequence number does not say when a pair was filmed: each pair's object
    carries ``time_s``, the time the estimator was given (the first video's presentation time, else the last
    plus a frame), so a user can line the joints up with the video. Before, the output had no time at all."""
    pts_ms = [0.0, 40.0, 70.0, float("nan"), 150.0]

    monkeypatch.setattr(cli_run.cv2, "VideoCapture", _video_with_times(pts_ms, 25.0))
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _StubEstimator())
    out = tmp_path / "j.jsonl"
    assert cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(out)]) == 0
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert [line["sequence"] for line in lines] == [0, 1, 2, 3, 4]
    # the fourth frame gives no time: the third's plus a frame at 25 fps
    assert [line["time_s"] for line in lines] == pytest.approx([0.0, 0.04, 0.07, 0.11, 0.15])


def test_the_novel_alpha_help_names_the_path_and_the_orbit_s_limit():
    """``--novel-alpha``'s help says what docs/novel-view.md does since ``novel_view.path``: the view moves on the
    line or an orbit, and an orbit's extrapolated distance to its pivot is refused too (it named the focal
    length only)."""
    action = next(a for a in cli_run.build_parser()._actions if "--novel-alpha" in a.option_strings)
    text = " ".join(action.help.split())
    assert "novel_view.path" in text and "distance to its pivot" in text
    assert set(NOVEL_PATHS) == {"line", "orbit", "auto"}  # the two paths the help names, and the rule choosing


@pytest.mark.parametrize("suffix", [".json", ".jsonl"])
def test_ctrl_c_pressed_again_while_the_outputs_are_written_leaves_them_whole(monkeypatch, tmp_path, capsys, suffix):
    """A stopped run writes the pairs it finished; a second Ctrl-C landing in that write (an impatient user, a
    long run's list taking a while) raised in it: the .json list was never written, and the message still said
    the outputs held the pairs finished."""
    import os
    import signal

    out = tmp_path / f"joints{suffix}"
    real_write, real_close = cli_run.write_text_atomic, cli_run._Sink.close

    def pressed_again() -> None:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)  # the handler runs here, in the main thread

    def write_text_atomic(path, text):
        pressed_again()
        real_write(path, text)

    def sink_close(sink):
        pressed_again()
        real_close(sink)

    monkeypatch.setattr(cli_run, "write_text_atomic", write_text_atomic)
    monkeypatch.setattr(cli_run._Sink, "close", sink_close)
    monkeypatch.setattr(cli_run.Estimator, "from_config",
                        lambda rig, cfg: _ViewStub(fail_at=2, fail=KeyboardInterrupt()))
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run, "_pairs", lambda args: iter([(np.zeros((4, 4, 3), np.uint8),) * 2] * 4))
    before = signal.getsignal(signal.SIGINT)
    rc = cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(out),
                       "--novel-view", str(tmp_path / "novel.png")])
    assert rc == 130 and "stopped (SIGINT)" in capsys.readouterr().err
    text = out.read_text()
    got = json.loads(text) if suffix == ".json" else [json.loads(line) for line in text.splitlines()]
    assert [p["sequence"] for p in got] == [0, 1]
    assert (tmp_path / "novel.png").is_file()  # the view's image written as well
    assert signal.getsignal(signal.SIGINT) is before  # put back


def test_the_first_video_is_released_when_the_second_does_not_open(monkeypatch, tmp_path):
    """``_pairs`` opened the first video, then raised for the second and left the first capture to the garbage
    collector (a file descriptor and a decoder thread held until then)."""
    opened = []

    class _Cap:
        def __init__(self, path):
            self.path, self.released = path, False
            opened.append(self)

        def isOpened(self):
            return self.path.endswith("first.mp4")

        def set(self, prop, value):
            return True

        def get(self, prop):
            return 0.0

        def release(self):
            self.released = True

    (tmp_path / "second.mp4").write_bytes(b"not a video")
    monkeypatch.setattr(cli_run.cv2, "VideoCapture", _Cap)
    args = cli_run.build_parser().parse_args(["--rig", "r.json", "--videos", str(tmp_path / "first.mp4"),
                                              str(tmp_path / "second.mp4")])
    with pytest.raises(cli_run.UsageError, match="second.mp4: cannot open the video"):
        next(cli_run._pairs(args))
    assert [cap.released for cap in opened] == [True, True]


@pytest.mark.parametrize("name, said", [("x.txt", "suffix '.txt'"), ("joints.csv", "suffix '.csv'"),
                                        ("joints", "no suffix")])
def test_an_out_of_another_kind_is_refused_naming_the_kinds(tmp_path, monkeypatch, capsys, name, said):
    """``--out x.txt`` (or .csv) was written as JSON lines, exit 0, though the help lists .json, .jsonl and -."""
    monkeypatch.setattr(cli_run, "_run", lambda args: pytest.fail("ran"))
    with pytest.raises(SystemExit) as e:
        cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(tmp_path / name)])
    err = capsys.readouterr().err
    assert e.value.code == 2 and f"--out {tmp_path / name}: {said}; give a .json or .jsonl file" in err
    assert not (tmp_path / name).exists()


@pytest.mark.parametrize("name", ["J.JSONL", "J.Json"])
def test_out_s_kind_is_told_by_its_suffix_in_any_case(monkeypatch, tmp_path, name):
    rc, _ = _stub_run(monkeypatch, tmp_path / name, pairs=2)
    text = (tmp_path / name).read_text()
    got = json.loads(text) if name.lower().endswith(".json") else [json.loads(line) for line in text.splitlines()]
    assert rc == 0 and [p["sequence"] for p in got] == [0, 1]


@pytest.mark.skipif(not Path("/dev/null").exists(), reason="no /dev/null here")
def test_a_device_or_pipe_as_out_gets_a_line_per_pair(monkeypatch):
    """No suffix to promise a format: /dev/stdout, a FIFO a reader waits on, /dev/null."""
    rc, _ = _stub_run(monkeypatch, Path("/dev/null"), pairs=2)
    assert rc == 0


def test_a_folder_as_out_is_named_a_folder_not_a_kind(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cli_run, "load_rig", lambda path: pytest.fail("read the rig"))
    (tmp_path / "joints").mkdir()
    rc = cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--out", str(tmp_path / "joints")])
    assert rc == 2 and f"--out {tmp_path / 'joints'}: is a folder" in capsys.readouterr().err


@pytest.mark.parametrize("still", ["a.png", "a.jpg", "a.mp4"])  # a.mp4: a PNG under a video's name
def test_a_still_image_given_as_a_video_is_refused_pointing_at_images(tmp_path, monkeypatch, capsys, still):
    """FFmpeg opens a PNG or JPEG as a one-frame video: the run reported that one pair, exit 0, as a clip."""
    monkeypatch.setattr(cli_run.Estimator, "from_config", lambda rig, cfg: _StubEstimator())
    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    (tmp_path / still).write_bytes(cv2.imencode(".png" if still != "a.jpg" else ".jpg",
                                                np.zeros((8, 8, 3), np.uint8))[1].tobytes())
    second = tmp_path / "b.avi"
    writer = cv2.VideoWriter(str(second), cv2.VideoWriter_fourcc(*"MJPG"), 30, (8, 8))
    for _ in range(3):
        writer.write(np.zeros((8, 8, 3), np.uint8))
    writer.release()
    out = tmp_path / "o.jsonl"
    for pair in ((tmp_path / still, second), (second, tmp_path / still)):
        assert cli_run.main(["--rig", "r.json", "--videos", *map(str, pair), "--out", str(out)]) == 2
        assert (f"--videos {tmp_path / still}: a still image, not a video; give a still pair as --images"
                in capsys.readouterr().err)
        assert not out.exists()


@pytest.mark.parametrize("prior", [None, object()])
def test_max_prior_error_without_a_prior_in_the_folder_is_warned_of_once(monkeypatch, tmp_path, caplog, prior):
    """``--skeleton-prior auto`` (the default) and a model folder without skeleton_prior.onnx, known only at load:
    the flag ran without effect and without a word. Once at load, not per pair; nothing where the prior runs."""
    def from_config(rig, cfg):
        estimator = _StubEstimator()
        estimator.skeleton_prior = prior
        return estimator

    monkeypatch.setattr(cli_run, "load_rig", lambda path: None)
    monkeypatch.setattr(cli_run.Estimator, "from_config", from_config)
    monkeypatch.setattr(cli_run, "_pairs", lambda args: iter([(np.zeros((4, 4, 3), np.uint8),) * 2] * 3))
    rc = cli_run.main(["--rig", "r.json", "--videos", "a.mp4", "b.mp4", "--model-dir", str(tmp_path / "m"),
                       "--max-prior-error", "0.3", "--out", str(tmp_path / "j.jsonl")])
    said = [r.getMessage() for r in caplog.records if "--max-prior-error" in r.getMessage()]
    assert rc == 0
    if prior is None:
        assert said == [f"--max-prior-error 0.3 has no effect: the model folder {tmp_path / 'm'} has no "
                        "skeleton_prior.onnx, so no skeleton prior runs (joints3d.skeleton_prior 'auto'; plain "
                        "triangulation)"]
    else:
        assert said == []


def test_the_tiny_model_without_a_prior_warns_of_max_prior_error(sim_pair, tiny_model_dir, tmp_path, caplog):  # noqa: F811
    assert not (Path(tiny_model_dir) / "skeleton_prior.onnx").exists()
    rc = cli_run.main(["--rig", sim_pair["rig"], "--images", sim_pair["left"], sim_pair["right"], "--model-dir",
                       str(tiny_model_dir), "--max-prior-error", "0.2", "--out", str(tmp_path / "j.json")])
    assert rc == 0
    assert [r.levelname for r in caplog.records if "--max-prior-error 0.2 has no effect" in r.getMessage()] == \
        ["WARNING"]


@pytest.mark.parametrize("verbose", [[], ["--verbose"]])
def test_the_rig_file_s_note_is_shown_without_verbose_once(tmp_path, verbose):
    """Loading notes at INFO a rig that cuts a standing person (``rig_file.rig_notes``; ``ghcal synth``'s rig shows
    84 % of their height), and ``ghnerf-run`` shows WARNING and over unless ``--verbose``: the note was dropped
    (session 68). Shown now beside the warnings, in the same format, once with ``--verbose`` as without. The run
    stops at the images (none there), after the rig loaded."""
    from calibration.render import example_rig
    from ghnerf_runtime.rig_file import save_rig

    rig = tmp_path / "synth_rig.json"
    save_rig(example_rig(), rig)
    proc = subprocess.run([sys.executable, "-m", "ghnerf_runtime.cli.run", "--rig", str(rig), "--images",
                           str(tmp_path / "a.png"), str(tmp_path / "b.png"), "--out", str(tmp_path / "j.json"),
                           *verbose], capture_output=True, text=True, timeout=120,
                           cwd=Path(__file__).resolve().parents[2])
    assert proc.returncode == 2 and "a.png: no such file" in proc.stderr, proc.stderr
    noted = framing_notes(proc.stderr)
    assert len(noted) == 1 and noted[0].startswith(f"INFO ghnerf_runtime.rig_file: {rig}: a 1.8 m person"), noted


def test_an_image_output_on_a_fifo_is_written_into_it(tmp_path):
    """`mkfifo novel.png` read by a viewer: the atomic write renamed a regular file over the FIFO, its reader never
    got the image (it waited on a FIFO no longer in the folder)."""
    import os
    import stat

    path = tmp_path / "novel.png"
    os.mkfifo(path)
    reader = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a reader there, so the writer's open does not block
    try:
        image = np.full((4, 4, 3), 200, np.uint8)
        sink = cli_run._Sink(str(path), flag="--novel-view")
        sink.add(image)
        sink.close()
        data = os.read(reader, 1 << 16)
    except BlockingIOError:  # nothing came through the FIFO
        data = b""
    finally:
        os.close(reader)
    assert stat.S_ISFIFO(path.lstat().st_mode)
    assert data == cv2.imencode(".png", image)[1].tobytes()


@pytest.mark.parametrize("flag", ["--novel-view", "--overlay"])
@pytest.mark.parametrize("name", ["novel.txt", "novel"])
def test_an_image_output_of_unknown_kind_names_its_option(tmp_path, flag, name):
    """The refusal named the path only: which of --novel-view and --overlay it was, the user had to guess."""
    with pytest.raises(cli_run.UsageError, match=rf"^{flag} .*{name}: cannot write an image of this kind"):
        cli_run._Sink(str(tmp_path / name), flag=flag)
