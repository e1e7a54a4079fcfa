"""The novel view's learnt painter on the device (``ghnerf_runtime.novel_painter``): its inputs against the
simulator's truth, its file contract, and where it may change the picture.

The painter here is a graph written with ``onnx.helper`` (no torch): it returns its two-source blend plane,
which is enough to check what the runtime feeds it and what it keeps of the answer; that a trained
painter is fed what it was trained on is ``tests/training/test_novel_painter_export.py``."""
from __future__ import annotations

import os
import re
import time
from pathlib import Path

import numpy as np
import pytest

from ghnerf_runtime.body_proxy import proxy_body, proxy_depth
from ghnerf_runtime.config import ConfigError, NovelViewConfig
from ghnerf_runtime.errors import ModelContractError, ModelLoadError, ModelRunError, ShapeError
from ghnerf_runtime.metrics import masked_psnr
from ghnerf_runtime.novel_painter import (FEATURE_VERSION, META_PREFIX, PLANES, NovelPainter, PainterPlanes,
                                          angle_from_sources_deg, painter_planes)

pytest.importorskip("drivers.sim")  # the shot fixture renders with the simulator
onnx = pytest.importorskip("onnx")


def blend_painter(path: Path, version: int = FEATURE_VERSION, planes: int = len(PLANES)) -> Path:
    """A painter graph that answers its blend planes (0-2) and ignores the rest."""
    from onnx import TensorProto, helper

    consts = [helper.make_tensor(n, TensorProto.INT64, [1], [v]) for n, v in (("s", 0), ("e", 3), ("a", 1))]
    node = helper.make_node("Slice", ["planes", "s", "e", "a"], ["rgb"])
    graph = helper.make_graph(
        [node], "blend_painter",
        [helper.make_tensor_value_info("planes", TensorProto.FLOAT, ["N", planes, "H", "W"]),
         helper.make_tensor_value_info("joints", TensorProto.FLOAT, ["N", 25, 3])],
        [helper.make_tensor_value_info("rgb", TensorProto.FLOAT, ["N", 3, "H", "W"])], initializer=consts)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    entry = model.metadata_props.add()
    entry.key, entry.value = META_PREFIX + "feature_version", str(version)
    onnx.save(model, str(path))
    return path


def _planes(shot, shown=None):
    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    shown = np.zeros((128, 128, 3)) if shown is None else shown
    return painter_planes(shown, target, proxy_depth(body, target), sources, rgb,
                          [proxy_depth(body, c) for c in sources], joints, np.ones(25, bool))


def test_the_inputs_describe_the_subject_the_simulator_drew(shot):
    joints, sources, rgb, target, image, truth = shot
    p = _planes(shot)
    assert p.planes.shape == (len(PLANES), 128, 128) and p.planes.dtype == np.float32
    mask, seen = p.planes[3] > 0, p.planes[4] > 0
    assert np.array_equal(mask, p.mask)
    assert (mask & truth.mask).sum() / (mask | truth.mask).sum() > 0.8  # the proxy's silhouette
    assert seen.sum() > 0.7 * mask.sum() and not (seen & ~mask).any()  # halfway: the sources see most of it
    blend = p.planes[:3].transpose(1, 2, 0).astype(np.float64)
    assert masked_psnr(blend, image[..., ::-1] / 255.0, seen & truth.mask).value > 23.0  # its own colours
    normals = p.planes[5:8]
    assert np.allclose(np.linalg.norm(normals[:, mask], axis=0), 1.0, atol=0.02)
    assert np.median(normals[2, mask]) < -0.5  # camera frame: the surface faces the camera (-z)
    assert abs(np.median(p.planes[8][mask])) < 1e-3 and not p.planes[8][~mask].any()
    uv, _ = target.project(joints, distort=False)
    np.testing.assert_allclose(p.joints[:, :2], uv, atol=1e-3)
    assert p.joints[:, 2].all()


def test_unknown_joints_are_marked_and_bad_inputs_named(shot):
    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    depth, src = proxy_depth(body, target), [proxy_depth(body, c) for c in sources]
    valid = np.ones(25, bool)
    valid[4] = False
    p = painter_planes(np.zeros((128, 128, 3)), target, depth, sources, rgb, src, joints, valid)
    assert p.joints[4].tolist() == [0.0, 0.0, 0.0] and p.joints[3, 2] == 1.0
    # a known joint the view has no pixel for (in front, but inside Camera.project's 1e-9 m near plane) is
    # marked unknown too: it was marked known at pixel (0, 0)
    close = joints.copy()
    close[5] = target.center + 5e-10 * target.R[2] + 0.1 * target.R[0]
    assert 0 < target.to_camera(close[5])[2] < 1e-9
    p = painter_planes(np.zeros((128, 128, 3)), target, depth, sources, rgb, src, close, valid)
    assert p.joints[5].tolist() == [0.0, 0.0, 0.0] and p.joints[6, 2] == 1.0
    with pytest.raises(ShapeError, match="picture"):
        painter_planes(np.zeros((64, 64, 3)), target, depth, sources, rgb, src, joints, valid)
    with pytest.raises(ShapeError, match="2 source cameras, 1 images"):
        painter_planes(np.zeros((128, 128, 3)), target, depth, sources, rgb[:1], src, joints, valid)
    with pytest.raises(ShapeError, match="joints"):
        painter_planes(np.zeros((128, 128, 3)), target, depth, sources, rgb, src, joints[:24], valid)
    empty = painter_planes(np.zeros((128, 128, 3)), target, np.zeros((128, 128)), sources, rgb, src, joints, valid)
    assert not empty.mask.any() and np.isfinite(empty.planes).all()


def test_the_painter_changes_only_the_proxy_and_the_region(shot, tmp_path):
    joints, sources, rgb, target, image, truth = shot
    painter = NovelPainter.load(blend_painter(tmp_path / "p.onnx"))
    body = proxy_body(joints, np.ones(25, bool))
    grey = np.full((128, 128, 3), 77, np.uint8)
    out, changed = painter.repaint(grey, target, body, sources, rgb, joints, np.ones(25, bool))
    proxy = proxy_depth(body, target) > 0
    assert np.array_equal(changed, proxy)
    assert np.array_equal(out[~changed], grey[~changed])
    assert masked_psnr(out[..., ::-1] / 255.0, image[..., ::-1] / 255.0, proxy & truth.mask).value > 20.0
    region = np.zeros((128, 128), bool)
    region[:10, :10] = True  # a corner the proxy does not reach: painted too (the picture says subject)
    _, changed = painter.repaint(grey, target, body, sources, rgb, joints, np.ones(25, bool), region=region)
    assert np.array_equal(changed, proxy | region)
    # the painted box is the proxy's and the region's, padded: the same colours as painting the whole view
    whole, _ = painter.repaint(grey, target, body, sources, rgb, joints, np.ones(25, bool), margin_px=128)
    boxed, _ = painter.repaint(grey, target, body, sources, rgb, joints, np.ones(25, bool))
    assert np.array_equal(whole, boxed)
    given, _ = painter.repaint(grey, target, body, sources, rgb, joints, np.ones(25, bool),
                               depth=proxy_depth(body, target), source_depth=[proxy_depth(body, c) for c in sources])
    assert np.array_equal(given, boxed)
    nobody = proxy_body(joints, np.zeros(25, bool))
    same, none = painter.repaint(grey, target, nobody, sources, rgb, joints, np.zeros(25, bool))
    assert not none.any() and np.array_equal(same, grey)


def test_a_painter_file_of_another_contract_is_refused(tmp_path):
    with pytest.raises(ModelLoadError, match="no such novel-view painter"):
        NovelPainter.load(tmp_path / "none.onnx")
    (tmp_path / "bad.onnx").write_bytes(b"\x00" * 10)
    with pytest.raises(ModelLoadError, match="bad.onnx.*corrupt"):
        NovelPainter.load(tmp_path / "bad.onnx")
    with pytest.raises(ModelContractError, match="feature version '99'"):
        NovelPainter.load(blend_painter(tmp_path / "v99.onnx", version=99))
    with pytest.raises(ModelContractError, match="planes"):
        NovelPainter.load(blend_painter(tmp_path / "p11.onnx", planes=11))
    painter = NovelPainter.load(blend_painter(tmp_path / "ok.onnx"))
    p = PainterPlanes(np.full((12, 16, 16), np.nan, np.float32), np.zeros((25, 3), np.float32), np.ones((16, 16), bool))
    from ghnerf_runtime.errors import ModelRunError

    with pytest.raises(ModelRunError, match="non-finite"):
        painter.paint(p)


def test_the_painter_setting_is_checked():
    assert NovelViewConfig().painter == "auto"
    assert NovelViewConfig(enabled=True).uses_painter(True) and not NovelViewConfig(enabled=True).uses_painter(False)
    assert not NovelViewConfig(enabled=True, painter="off").uses_painter(True)
    assert not NovelViewConfig(enabled=False).uses_painter(True)
    with pytest.raises(ConfigError, match="painter"):
        NovelViewConfig(painter="maybe")


def test_the_folder_gives_the_int8_painter_where_the_precision_allows(tmp_path):
    assert NovelPainter.find(tmp_path) is None
    blend_painter(tmp_path / "novel_painter.onnx")
    assert NovelPainter.find(tmp_path, "auto").name == "novel_painter.onnx"
    blend_painter(tmp_path / "novel_painter.int8.onnx")
    assert NovelPainter.find(tmp_path, "auto").name == "novel_painter.int8.onnx"
    assert NovelPainter.find(tmp_path, "int8").name == "novel_painter.int8.onnx"
    assert NovelPainter.find(tmp_path, "fp32").name == "novel_painter.onnx"


def _recorded(path: Path, age_s: float = 0.0, **record: str) -> Path:
    """``path`` with ``record`` added to its metadata (``ghnerf_painter.`` keys), ``age_s`` seconds in the past."""
    model = onnx.load(str(path))
    for k, v in record.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = META_PREFIX + k, v
    onnx.save(model, str(path))
    os.utime(path, (time.time() - age_s, time.time() - age_s))
    return path


def test_an_int8_painter_not_quantized_from_the_fp32_one_beside_it_is_not_run(tmp_path, caplog):
    """A folder exported before session 73 keeps the int8 file of the painter an export replaced, and ``auto`` ran
    it. ``quantize_painter`` carries the fp32 file's training record over: one that differs gives the fp32 file,
    said once naming both and the command that quantizes it again; the same record gives the int8 file, however old
    its time. Without a record (a hand-made painter) the times decide."""
    import logging

    fp32 = _recorded(blend_painter(tmp_path / "novel_painter.onnx"), steps="4704", trained_on="out/new/fill_net.pt")
    int8 = _recorded(blend_painter(tmp_path / "novel_painter.int8.onnx"), age_s=-60.0, steps="1000",
                     trained_on="out/old/fill_net.pt", precision="int8", calibration_views="64")
    for precision in ("auto", "int8"):
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            assert NovelPainter.choose(tmp_path, precision) == fp32
        [said] = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
        assert "novel_painter.int8.onnx is not quantized from novel_painter.onnx (its steps, trained_on differ" in said
        assert f"python -m training.learnt_fill export --net out/new/fill_net.pt --out {fp32} --calib-cache" in said
    assert NovelPainter.find(tmp_path, "auto") == int8  # (find says which files the folder has)
    _recorded(blend_painter(int8), age_s=30 * 86400.0, steps="4704", trained_on="out/new/fill_net.pt",
              precision="int8", calibration_views="64")
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        assert NovelPainter.choose(tmp_path) == int8
    assert not caplog.records
    for age_s, chosen in ((2 * 86400.0, fp32), (5.0, int8)):  # no record: a copy's seconds apart is no stale file
        blend_painter(fp32)
        _recorded(blend_painter(int8), age_s=age_s)
        assert NovelPainter.choose(tmp_path) == chosen


def test_the_fp32_painters_sha256_an_int8_painter_records_decides_before_the_record_and_times(tmp_path, caplog):
    """``quantize_painter`` records the fp32 file's sha256 (``fp32_sha256``): the same bytes beside the int8 file
    take it, however much older its time and without a training record to compare (the times alone said stale);
    other bytes give the fp32 file with the same training record and the int8 file the newer, said naming both."""
    import hashlib
    import logging

    def sha(path: Path) -> str:
        return hashlib.sha256(path.read_bytes()).hexdigest()

    fp32 = blend_painter(tmp_path / "novel_painter.onnx")
    int8 = _recorded(blend_painter(tmp_path / "novel_painter.int8.onnx"), age_s=2 * 86400.0, precision="int8",
                     fp32_sha256=sha(fp32))
    assert NovelPainter.choose(tmp_path) == int8

    _recorded(blend_painter(fp32), steps="4704")
    quantized_from = sha(fp32)
    _recorded(blend_painter(int8), steps="4704", precision="int8", calibration_views="64", fp32_sha256=quantized_from)
    _recorded(fp32, age_s=3600.0, width="16")  # rewritten since (the record the int8 file carried over differs too)
    _recorded(blend_painter(int8), steps="4704", precision="int8", calibration_views="64", fp32_sha256=quantized_from,
              width="16")  # the same record, the newer file
    with caplog.at_level(logging.WARNING):
        assert NovelPainter.choose(tmp_path) == fp32
    [said] = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert (f"novel_painter.int8.onnx is not quantized from novel_painter.onnx (it was quantized from a file of "
            f"sha256 {quantized_from[:12]}..., and novel_painter.onnx has sha256 {sha(fp32)[:12]}...)") in said


def test_the_views_angle_from_the_sources_is_ghnerf_evals(shot):
    joints, sources, _, target, _, _ = shot
    valid = np.ones(25, bool)
    assert angle_from_sources_deg(sources[0], sources, joints, valid) == pytest.approx(0.0, abs=1e-6)
    centre = joints.mean(0)
    a, b = (c.center - centre for c in sources)
    between = np.degrees(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))
    assert 0.3 * between < angle_from_sources_deg(target, sources, joints, valid) <= 0.5 * between + 1e-6
    assert np.isnan(angle_from_sources_deg(target, sources, joints, np.zeros(25, bool)))
    with pytest.raises(ConfigError, match="painter_min_angle_deg"):
        NovelViewConfig(painter_min_angle_deg=-1.0)


def test_a_painter_whose_inputs_have_another_rank_is_refused(tmp_path):
    # the shapes were indexed before their rank was checked: an IndexError instead of the contract's error
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("Identity", ["joints"], ["rgb"])], "odd_painter",
        [helper.make_tensor_value_info("planes", TensorProto.FLOAT, ["N"]),
         helper.make_tensor_value_info("joints", TensorProto.FLOAT, ["N", 25, 3])],
        [helper.make_tensor_value_info("rgb", TensorProto.FLOAT, ["N", 25, 3])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    entry = model.metadata_props.add()
    entry.key, entry.value = META_PREFIX + "feature_version", str(FEATURE_VERSION)
    onnx.save(model, str(tmp_path / "odd.onnx"))
    with pytest.raises(ModelContractError, match=r"inputs planes \(N, 12, H, W\)") as e:
        NovelPainter.load(tmp_path / "odd.onnx")
    assert e.value.key == "planes" and "odd.onnx" in str(e.value)


def _answering_painter(path: Path, nodes: list, consts: list) -> Path:
    """A painter graph of ``nodes`` that ends in ``rgb`` (the blend painter's file contract)."""
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        nodes, "answering_painter",
        [helper.make_tensor_value_info("planes", TensorProto.FLOAT, ["N", len(PLANES), "H", "W"]),
         helper.make_tensor_value_info("joints", TensorProto.FLOAT, ["N", 25, 3])],
        [helper.make_tensor_value_info("rgb", TensorProto.FLOAT, None)], initializer=consts)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    entry = model.metadata_props.add()
    entry.key, entry.value = META_PREFIX + "feature_version", str(FEATURE_VERSION)
    onnx.save(model, str(path))
    return path


def test_a_painter_answer_past_white_or_black_is_clipped_not_wrapped(shot, tmp_path):
    # np.round(1.2 * 255) = 306 became uint8 50: the brightest pixels turned dark (and -0.2: 205, near white)
    from onnx import TensorProto, helper

    joints, sources, rgb, target, _, _ = shot
    consts = [helper.make_tensor(n, TensorProto.INT64, [1], [v]) for n, v in (("s", 0), ("e", 3), ("a", 1))]
    consts.append(helper.make_tensor("gain", TensorProto.FLOAT, [], [8.0]))
    consts.append(helper.make_tensor("one", TensorProto.FLOAT, [], [1.0]))
    nodes = [helper.make_node("Slice", ["planes", "s", "e", "a"], ["blend"]),
             helper.make_node("Mul", ["blend", "gain"], ["loud"]),
             helper.make_node("Sub", ["loud", "one"], ["rgb"])]  # 8 x - 1: [-1, 7]
    painter = NovelPainter.load(_answering_painter(tmp_path / "loud.onnx", nodes, consts))
    body = proxy_body(joints, np.ones(25, bool))
    planes = _planes(shot)
    painted = painter.paint(planes)
    want = np.clip(8.0 * planes.planes[:3].transpose(1, 2, 0) - 1.0, 0.0, 1.0)
    assert want.max() == 1.0 and want.min() == 0.0  # both ends overshot
    np.testing.assert_allclose(painted, want, atol=1e-6)
    out, changed = painter.repaint(np.full((128, 128, 3), 77, np.uint8), target, body, sources, rgb, joints,
                                   np.ones(25, bool))
    expected = np.round(want[..., ::-1] * 255.0)  # BGR; the boxed crop paints as the whole view (above)
    np.testing.assert_allclose(out[changed], expected[changed], atol=1)
    assert (out[changed] == 255).sum() > 20 and (out[changed] == 0).sum() > 20


def test_a_painter_answer_of_another_size_is_a_model_error(shot, tmp_path):
    from onnx import TensorProto, helper

    consts = [helper.make_tensor(n, TensorProto.INT64, [2], v) for n, v in (("s", [0, 0]), ("e", [3, -1]),
                                                                           ("a", [1, 2]))]
    nodes = [helper.make_node("Slice", ["planes", "s", "e", "a"], ["rgb"])]  # one row short
    painter = NovelPainter.load(_answering_painter(tmp_path / "short.onnx", nodes, consts))
    with pytest.raises(ModelRunError, match=r"shape \(1, 3, 127, 128\), expected \(1, 3, 128, 128\)") as e:
        painter.paint(_planes(shot))
    assert "short.onnx" in str(e.value)


def test_a_region_of_another_shape_is_named_not_broadcast(shot, tmp_path):
    # a (128,) region broadcast over the rows and repainted the whole view; (64, 64) was numpy's ValueError
    joints, sources, rgb, target, _, _ = shot
    painter = NovelPainter.load(blend_painter(tmp_path / "p.onnx"))
    body = proxy_body(joints, np.ones(25, bool))
    grey = np.full((128, 128, 3), 77, np.uint8)
    for bad in (np.ones(128, bool), np.ones((64, 64), bool), np.ones((1, 128), bool)):
        with pytest.raises(ShapeError, match=re.escape(f"region must be (128, 128), got {bad.shape}")):
            painter.repaint(grey, target, body, sources, rgb, joints, np.ones(25, bool), region=bad)


def test_8_bit_pictures_and_sources_are_named_not_taken_for_white(shot):
    # planes built from 0..255 colours were all ones (white): what the painter repainted was not the view
    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    depth, src = proxy_depth(body, target), [proxy_depth(body, c) for c in sources]
    valid = np.ones(25, bool)
    shown8 = np.full((128, 128, 3), 200, np.uint8)
    with pytest.raises(ShapeError, match=r"picture must be float RGB in \[0, 1\], got uint8 up to 200"):
        painter_planes(shown8, target, depth, sources, rgb, src, joints, valid)
    with pytest.raises(ShapeError, match=r"source image 1 must be float RGB in \[0, 1\], got float32 up to 1\.\d+$"):
        painter_planes(shown8 / 255.0, target, depth, sources, [rgb[0], rgb[1] + 0.5], src, joints, valid)
    p = painter_planes(shown8 / 255.0, target, depth, sources, rgb, src, joints, valid)
    assert np.allclose(p.planes[9:], 200 / 255.0, atol=1e-6) and p.planes[:3].max() < 1.0


def test_a_nan_joint_marked_valid_does_not_make_the_angle_nan(shot):
    # the mean of the valid joints was NaN, and so the angle: "angle < painter_min_angle_deg" was False, and
    # the painter ran on views next to a source camera
    joints, sources, _, target, _, _ = shot
    valid = np.ones(25, bool)
    broken = joints.copy()
    broken[4] = np.nan
    without = valid.copy()
    without[4] = False
    got = angle_from_sources_deg(sources[0], sources, broken, valid)
    assert got == angle_from_sources_deg(sources[0], sources, joints, without)
    assert got == pytest.approx(0.0, abs=1e-6)
    assert np.isnan(angle_from_sources_deg(target, sources, np.full((25, 3), np.nan), valid))


def test_a_depth_beyond_float16_is_held_at_its_largest_not_inf(shot):
    # the depth plane is float16 about the median: a surface 70 km behind the subject (a wild joint's
    # ellipsoid) became inf, and the painter's answer NaN, a ModelRunError for the view
    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    depth = proxy_depth(body, target)
    far = depth.copy()
    far[0, :8] = 7e4
    p = painter_planes(np.zeros((128, 128, 3)), target, far, sources, rgb, [proxy_depth(body, c) for c in sources],
                       joints, np.ones(25, bool))
    assert np.isfinite(p.planes).all()
    assert p.planes[8, 0, :8].min() == np.finfo(np.float16).max
    assert np.abs(p.planes[8][depth > 0]).max() < 1.0  # the subject keeps its depth about the median


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_pixel_without_a_finite_depth_has_no_normal_and_its_neighbours_keep_theirs(shot, bad):
    """Review 52: an infinite depth inside the proxy (depth > 0 holds it) made a NaN normal plane there (inf - inf),
    so the painter's answer NaN; a NaN one (off the mask) turned its neighbours' normals to face the camera. Both
    have no normal now (the zero vector, as off the subject) and their neighbours difference across them as across
    the silhouette: the normals are those with the pixel off the proxy, as the training caches make them
    (training.fill_features, through the same ghnerf_runtime.geometry.surface.surface_normals)."""
    import warnings

    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    depth = proxy_depth(body, target)
    src_depth = [proxy_depth(body, c) for c in sources]
    ys, xs = np.nonzero(depth > 0)
    y, x = ys[len(ys) // 2], xs[len(xs) // 2]
    wild, off = depth.copy(), depth.copy()
    wild[y, x], off[y, x] = bad, 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        p = painter_planes(np.zeros((128, 128, 3)), target, wild, sources, rgb, src_depth, joints, np.ones(25, bool))
    ref = painter_planes(np.zeros((128, 128, 3)), target, off, sources, rgb, src_depth, joints, np.ones(25, bool))
    assert np.isfinite(p.planes).all()
    assert not p.planes[5:8, y, x].any()  # no normal
    np.testing.assert_array_equal(p.planes[5:8], ref.planes[5:8])
    assert np.abs(p.planes[5:8, y - 1:y + 2, x - 1:x + 2]).sum() > 0  # its neighbours have normals


def test_a_nan_depth_is_the_planes_no_depth_value_and_an_infinite_one_its_largest():
    """float16_depth passed NaN through (np.clip keeps it): one NaN pixel spread through the painter's
    convolutions into a NaN patch. NaN is now 0, the plane's value off the subject; +-inf clip as a wild finite
    depth does. The training caches call the same function (training.fill_features), so both sides agree."""
    from ghnerf_runtime.novel_painter import F16_MAX, float16_depth

    rel = np.array([[np.nan, np.inf, -np.inf], [1.5, 7e4, -7e4]])
    got = float16_depth(rel)
    assert got.dtype == np.float16 and np.isfinite(got).all()
    assert got.astype(np.float64).tolist() == [[0.0, F16_MAX, -F16_MAX], [1.5, F16_MAX, -F16_MAX]]
    assert float16_depth(np.float64(np.nan)) == 0.0  # a scalar too


def test_the_depth_plane_is_about_the_median_of_the_subject_s_finite_depths(shot):
    """The device's subject mask is depth > 0, which holds +inf: the median counted it (a third of the subject at
    inf moved it to the rest's 75th percentile), while the training caches' median is over finite depths
    (training.fill_features; a NaN there made the whole plane 0). Both call depth_about_median now."""
    joints, sources, rgb, target, _, _ = shot
    body = proxy_body(joints, np.ones(25, bool))
    depth = proxy_depth(body, target)
    ys, xs = np.nonzero(depth > 0)
    wild = depth.copy()
    wild[ys[::3], xs[::3]] = np.inf  # no finite depth known for a third of the subject
    finite = (depth > 0) & np.isfinite(wild)
    p = painter_planes(np.zeros((128, 128, 3)), target, wild, sources, rgb,
                       [proxy_depth(body, c) for c in sources], joints, np.ones(25, bool))
    expect = (depth[finite] - np.median(depth[finite])).astype(np.float16).astype(np.float32)
    np.testing.assert_array_equal(p.planes[8][finite], expect)

    from ghnerf_runtime.novel_painter import depth_about_median  # what both sides call

    rel = depth_about_median(np.array([[1.0, np.nan, 3.0], [np.inf, 2.0, 9.0]]),
                             np.array([[True, True, True], [True, True, False]]))
    assert rel[0, 0] == -1.0 and rel[1, 1] == 0.0 and rel[0, 2] == 1.0 and rel[1, 2] == 0.0  # median 2, of 1, 2, 3
    assert np.isnan(rel[0, 1]) and rel[1, 0] == np.inf  # float16_depth's to make 0 and 65504
    assert not depth_about_median(np.full((2, 2), np.nan), np.ones((2, 2), bool)).any()  # nothing to measure from
    with pytest.raises(ShapeError, match=r"depth \(2, 2\) and subject mask \(2, 3\)"):
        depth_about_median(np.zeros((2, 2)), np.zeros((2, 3), bool))


def test_the_painter_mask_is_where_the_depth_shows_a_surface():
    """The one rule the device's painter_planes and the training caches (training.fill_features) call: inside the
    geometry's silhouette with a positive depth; a NaN depth is no surface (off), +inf a wild one (on)."""
    from ghnerf_runtime.geometry.surface import surface_mask

    depth = np.array([[1.0, np.nan, np.inf], [0.0, -2.0, 3.0]])
    assert surface_mask(depth).tolist() == [[True, False, True], [False, False, True]]
    subject = np.array([[True, True, True], [True, True, False]])
    assert surface_mask(depth, subject).tolist() == [[True, False, True], [False, False, False]]
    with pytest.raises(ShapeError, match=r"subject mask \(2, 2\) must be the depth map's shape \(2, 3\)"):
        surface_mask(depth, np.ones((2, 2), bool))


def _cam_at(centre, name: str):
    from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov
    c = np.asarray(centre, np.float64)
    return Camera(name, 64, 64, intrinsics_from_fov(64, 64, 40.0), np.zeros(5), np.eye(3), -c)


def test_a_view_at_the_subjects_centre_is_at_angle_0_not_nan():
    """The view exactly at the joints' centre: its direction normalised to NaN, the angle was NaN, and
    ``angle < painter_min_angle_deg`` (False for NaN) let the painter run. By the documented rule it is 0."""
    centre = np.array([0.0, -1.0, 3.0])  # the mean of 25 copies is exactly it (x = 0: 1e-200 beside it counts)
    joints, valid = np.tile(centre, (25, 1)), np.ones(25, bool)
    sources = [_cam_at(centre + [0.0, 0.0, -3.0], "a"), _cam_at(centre + [1.0, 0.0, -3.0], "b")]
    view = _cam_at(centre, "view")
    assert np.array_equal(view.center, centre)
    assert angle_from_sources_deg(view, sources, joints, valid) == 0.0
    assert not angle_from_sources_deg(view, sources, joints, valid) >= NovelViewConfig().painter_min_angle_deg
    # 1e-200 m off the centre is a direction still: its squares underflowed, and the norm to 0 (NaN again)
    beside = _cam_at(centre + [1e-200, 0.0, 0.0], "beside")
    want = np.degrees(np.arccos(1.0 / np.sqrt(10.0)))  # +x from the centre against source b's (1, 0, -3)
    assert angle_from_sources_deg(beside, sources, joints, valid) == pytest.approx(want, abs=1e-9)
    # a source at the centre sees the subject from no side: the other source gives the angle
    assert angle_from_sources_deg(beside, [_cam_at(centre, "in"), sources[1]], joints, valid) == \
        pytest.approx(want, abs=1e-9)
    assert angle_from_sources_deg(beside, [_cam_at(centre, "in")], joints, valid) == 0.0
