"""The runtime's learnt painter (``ghnerf_runtime.novel_painter``) against what it was trained on: the
runtime builds the same inputs as the training caches (``training.fill_features``), and the exported
graph (``training.learnt_fill export``) paints what the torch net paints."""
from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from ghnerf_runtime.errors import ModelContractError, ModelLoadError  # noqa: E402
from ghnerf_runtime.novel_painter import NovelPainter, PainterPlanes, painter_planes  # noqa: E402
from training.body_proxy import proxy_scene, view_camera  # noqa: E402
from training.fill_features import stack, view_features  # noqa: E402
from training.learnt_fill import (FillNet, FillNetConfig, FillTrainConfig, PainterGraph, export_painter,  # noqa: E402
                                  main, painter_planes_of, save_net, to_device)


def _scenes(data, split="val"):
    from training.data.torch_dataset import MultiViewDataset

    ds = MultiViewDataset(data, split=split)
    return [{k: v.numpy() for k, v in ds[i].items()} for i in range(len(ds))]


def _net(seed: int = 0) -> FillNet:
    """A painter whose residual is not zero (a trained one's is not)."""
    torch.manual_seed(seed)
    net = FillNet(FillNetConfig(width=8, relit_input=False, shown_input=True))
    torch.nn.init.normal_(net.head.weight, std=0.05)
    return net.eval()


def _both(scene, joints, t):
    """One view's cache features (as training reads them) and the runtime's planes, from the same proxy."""
    valid = np.ones(25, bool)
    geometry, _ = proxy_scene({**scene, "joints_3d": joints, "joints_3d_valid": valid}, joints, valid)
    rng = np.random.default_rng(t)
    H, W = scene["tgt_masks"].shape[-2:]
    shown = np.round(rng.uniform(0, 1, (H, W, 3)) * 255) / 255
    f = view_features(geometry, t, None, 0.0, truth=scene, shown=shown, geometry="proxy")
    src = [v for v in range(len(scene["tgt_is_source"])) if scene["tgt_is_source"][v]]
    rt = painter_planes(shown, view_camera(scene, t), geometry["tgt_depth"][t], [view_camera(scene, s) for s in src],
                        np.asarray(scene["images"]).transpose(0, 2, 3, 1), [geometry["tgt_depth"][s] for s in src],
                        joints, valid)
    planes, j = painter_planes_of(to_device(stack([f]), torch.device("cpu")))
    return planes[0].numpy(), j[0].numpy(), rt


def test_the_runtime_builds_the_inputs_the_painter_was_trained_on(data64):
    scene = _scenes(data64)[0]
    joints = scene["joints_3d"] + 0.01
    novel = [t for t in range(len(scene["tgt_is_source"])) if not scene["tgt_is_source"][t]]
    for t in novel:
        want, want_j, rt = _both(scene, joints, t)
        got = rt.planes
        assert got.shape == want.shape == (12, 64, 64)
        assert np.array_equal(got[3:5], want[3:5])  # the proxy's mask and what the sources see of it
        assert np.array_equal(rt.mask, want[3] > 0)
        assert rt.mask.sum() > 100
        np.testing.assert_allclose(got[9:], want[9:], atol=1e-6)  # the picture
        # colours and normals: the same up to a rounding step where float64 and float32 maths round apart
        assert np.mean(np.abs(got[:3] - want[:3]) <= 1.01 / 255) > 0.999
        assert np.mean(np.abs(got[5:8] - want[5:8]) <= 1.01 / 127) > 0.995
        np.testing.assert_allclose(got[8], want[8], atol=2e-3)  # depth about its median (float16)
        np.testing.assert_allclose(rt.joints, want_j, atol=1e-3)


def test_a_nan_depth_is_off_the_mask_on_the_device_and_in_the_cache_alike(data64):
    """Review 52: the device's painter mask is where the depth shows a surface (depth > 0: a NaN pixel off), while
    the cache took the geometry's mask as it was (a NaN pixel on): the net trained on a mask plane the device never
    builds there. Both call ghnerf_runtime.geometry.surface.surface_mask now: a NaN depth is no surface."""
    scene = _scenes(data64)[0]
    joints, valid = scene["joints_3d"] + 0.01, np.ones(25, bool)
    geometry, _ = proxy_scene({**scene, "joints_3d": joints, "joints_3d_valid": valid}, joints, valid)
    t = next(t for t in range(len(scene["tgt_is_source"])) if not scene["tgt_is_source"][t]
             and geometry["tgt_masks"][t].sum() > 100)
    depth = np.array(geometry["tgt_depth"], np.float64)
    ys, xs = np.nonzero(geometry["tgt_masks"][t])
    y, x = ys[len(ys) // 2], xs[len(xs) // 2]
    depth[t, y, x] = np.nan  # inside the proxy's silhouette, as the geometry's mask still says
    geometry = {**geometry, "tgt_depth": depth}
    shown = np.zeros(scene["tgt_images"].shape[-2:] + (3,))
    f = view_features(geometry, t, None, 0.0, truth=scene, shown=shown, geometry="proxy")
    src = [v for v in range(len(scene["tgt_is_source"])) if scene["tgt_is_source"][v]]
    rt = painter_planes(shown, view_camera(scene, t), depth[t], [view_camera(scene, s) for s in src],
                        np.asarray(scene["images"]).transpose(0, 2, 3, 1), [depth[s] for s in src], joints, valid)
    planes, _ = painter_planes_of(to_device(stack([f]), torch.device("cpu")))
    want = planes[0].numpy()
    assert want[3, y, x] == 0.0 and rt.planes[3, y, x] == 0.0 and not rt.mask[y, x]  # off on both sides
    np.testing.assert_array_equal(rt.planes[3:5], want[3:5])  # the whole mask and seen planes agree
    assert want[3].sum() > 100


def test_the_exported_painter_paints_what_the_torch_net_paints(data64, tmp_path):
    scene = _scenes(data64)[0]
    t = next(t for t in range(len(scene["tgt_is_source"])) if not scene["tgt_is_source"][t])
    net = _net()
    path = export_painter(net, tmp_path / "novel_painter.onnx", {"trained_on": "test"})
    painter = NovelPainter.load(path)
    assert painter.meta["ghnerf_painter.width"] == "8"
    want_planes, want_j, rt = _both(scene, scene["joints_3d"], t)
    with torch.no_grad():
        want = PainterGraph(net)(torch.from_numpy(want_planes)[None], torch.from_numpy(want_j)[None])[0]
    got = painter.paint(rt)
    assert got.shape == (64, 64, 3)
    assert np.abs(got - want.permute(1, 2, 0).numpy()).max() < 3e-3
    assert np.abs(got - rt.planes[9:].transpose(1, 2, 0)).max() > 0.01  # it does repaint
    # any image size the network's levels divide
    wide = PainterPlanes(np.zeros((12, 48, 80), np.float32), np.zeros((25, 3), np.float32), np.zeros((48, 80), bool))
    assert painter.paint(wide).shape == (48, 80, 3)


def test_only_a_net_that_reads_what_a_device_has_is_exported(tmp_path):
    with pytest.raises(ValueError, match="relit_input=false"):
        PainterGraph(FillNet(FillNetConfig(width=8)))


def test_a_broken_painter_file_is_named(tmp_path):
    with pytest.raises(ModelLoadError, match="no such novel-view painter"):
        NovelPainter.load(tmp_path / "missing.onnx")
    bad = tmp_path / "novel_painter.onnx"
    bad.write_bytes(b"\x08\x07not onnx")
    with pytest.raises(ModelLoadError, match="novel_painter.onnx.*corrupt"):
        NovelPainter.load(bad)
    import onnx

    path = export_painter(_net(), tmp_path / "old.onnx", {})
    model = onnx.load(str(path))
    for p in model.metadata_props:
        if p.key == "ghnerf_painter.feature_version":
            p.value = "0"
    onnx.save(model, str(path))
    with pytest.raises(ModelContractError, match="feature version '0'"):
        NovelPainter.load(path)


def _export_setup(tmp_path, data64):
    """A saved net, an empty model card and a one-scene cache: what ``export`` reads."""
    from training.model_card import write_card

    net = _net()
    save_net(net, FillTrainConfig(net=net.cfg), tmp_path / "fill_net.pt", steps=7, seconds=1.0, hardware="cpu",
             train_views=3)
    card_dir = tmp_path / "models"
    (card_dir / "ghnerf").mkdir(parents=True)
    write_card(card_dir, {"files": {}})
    scene = _scenes(data64)[0]
    valid = np.ones(25, bool)
    geometry, _ = proxy_scene(scene, scene["joints_3d"], valid)
    views = [view_features(geometry, t, None, 45.0, truth=scene, shown=scene["tgt_images"][t].transpose(1, 2, 0),
                           geometry="proxy") for t in range(len(scene["tgt_is_source"])) if not scene["tgt_is_source"][t]]
    np.savez(tmp_path / "cache.npz", **stack([v for v in views if v is not None]))
    return card_dir, card_dir / "ghnerf" / "novel_painter.onnx"


def test_the_export_command_writes_both_graphs_their_figures_and_the_card(tmp_path, data64):
    card_dir, out = _export_setup(tmp_path, data64)
    rows = {"novel, all": {"n": 3, "shown": 19.0, "fill:learnt": 20.0}}
    config = torch.load(tmp_path / "fill_net.pt", weights_only=True)["config"]
    (tmp_path / "score.json").write_text(json.dumps({"rows": rows, "seconds": 1.0, "hardware": "cpu",
                                                     "train_views": 3, "steps": 7, "config": config}))
    assert main(["export", "--net", str(tmp_path / "fill_net.pt"), "--out", str(out), "--card-dir", str(card_dir),
                 "--val-cache", str(tmp_path / "cache.npz"), "--calib-cache", str(tmp_path / "cache.npz")]) == 0
    report = json.loads(out.with_suffix(".json").read_text())
    assert report["steps"] == 7 and report["held_out"] == rows
    assert report["parity"]["max_abs"] < 1e-3
    fp32, int8 = (report["onnx_held_out"][k]["novel, all"]["fill:learnt"] for k in ("fp32", "int8"))
    assert abs(fp32 - int8) < 1.0 and fp32 > 10.0
    card = json.loads((card_dir / "model_card.json").read_text())
    assert card["novel_painter"]["ghnerf"]["steps"] == 7
    assert {"ghnerf/novel_painter.onnx", "ghnerf/novel_painter.int8.onnx"} <= set(card["files"])
    assert "Novel-view painter" in (card_dir / "MODEL_CARD.md").read_text()
    assert NovelPainter.load(out).meta["ghnerf_painter.steps"] == "7"
    int8_painter = NovelPainter.load(out.with_suffix(".int8.onnx"))
    assert int8_painter.precision == "int8" and NovelPainter.load(out).precision == "fp32"
    assert NovelPainter.find(out.parent).name == "novel_painter.int8.onnx"
    # the fp32 file it was quantized from, by its bytes: what the runtime's stale-int8 check compares first
    from training.model_card import sha256
    assert int8_painter.meta["ghnerf_painter.fp32_sha256"] == sha256(out)


@pytest.mark.parametrize("score_file", ["none", "another run's"])
def test_a_net_exported_without_its_score_file_keeps_its_record_and_is_scored_on_the_cache(tmp_path, data64,
                                                                                         score_file):
    # A net brought back alone from a GPU machine: the checkpoint's own record fills the card, and the
    # torch net's held-out figures come from the given cache. Another run's score.json beside it lends nothing.
    card_dir, out = _export_setup(tmp_path, data64)
    if score_file != "none":
        (tmp_path / "score.json").write_text(json.dumps({
            "rows": {"novel, all": {"n": 9, "fill:learnt": 99.0}}, "steps": 123, "hardware": "elsewhere",
            "seconds": 5.0, "train_views": 99, "config": {"batch": 1}}))
    assert main(["export", "--net", str(tmp_path / "fill_net.pt"), "--out", str(out), "--card-dir", str(card_dir),
                 "--val-cache", str(tmp_path / "cache.npz")]) == 0
    report = json.loads(out.with_suffix(".json").read_text())
    assert report["hardware"] == "cpu" and report["train_views"] == 3 and report["train_s"] == 1.0
    assert report["config"]["net"]["width"] == 8 and report["config"]["net"]["shown_input"] is True
    assert report["held_out_cache"] == str(tmp_path / "cache.npz") and report["steps"] == 7
    torch_all = report["held_out"]["novel, all"]["fill:learnt"]
    assert abs(torch_all - report["onnx_held_out"]["fp32"]["novel, all"]["fill:learnt"]) < 0.01
    assert "Novel-view painter" in (card_dir / "MODEL_CARD.md").read_text()


def _strict(text: str):
    """``json.loads`` that refuses the bare NaN / Infinity Python's ``json.dumps`` writes and other readers refuse."""
    def refuse(word):
        raise ValueError(f"not JSON: {word}")

    return json.loads(text, parse_constant=refuse)


def test_the_painters_figures_are_strict_json(tmp_path, data64):
    # Review 51: a held-out bin without views scores NaN (identical pictures inf), and json.dumps wrote the
    # painter's .json with bare NaN / Infinity, which jq, browsers and most languages refuse
    card_dir, out = _export_setup(tmp_path, data64)
    rows = {"novel, all": {"n": 3, "shown": 19.0, "fill:learnt": 20.0},
            "novel, 150-180": {"n": 0, "shown": float("nan"), "fill:learnt": float("inf")}}
    config = torch.load(tmp_path / "fill_net.pt", weights_only=True)["config"]
    (tmp_path / "score.json").write_text(json.dumps({"rows": rows, "seconds": 1.0, "hardware": "cpu",
                                                     "train_views": 3, "steps": 7, "config": config}))
    assert main(["export", "--net", str(tmp_path / "fill_net.pt"), "--out", str(out)]) == 0
    report = _strict(out.with_suffix(".json").read_text())
    assert report["held_out"]["novel, 150-180"] == {"n": 0, "shown": None, "fill:learnt": None}
    assert report["held_out"]["novel, all"] == rows["novel, all"] and report["steps"] == 7


def test_an_export_cut_short_leaves_the_previous_graph_not_half_of_one(tmp_path, disk_full_at, monkeypatch):
    """export_painter wrote the graph in place, then rewrote it with its metadata: a crash or a full disk left
    a graph without its contract, or half of one, under the name the runtime loads."""
    out = export_painter(_net(0), tmp_path / "novel_painter.onnx", {"trained_on": "first"})
    before = out.read_bytes()
    disk_full_at(tmp_path, "novel_painter.onnx")
    with pytest.raises(OSError, match="No space left"):
        export_painter(_net(1), out, {"trained_on": "second"})
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["novel_painter.onnx"]  # no temporary file beside it
    assert out.read_bytes() == before and NovelPainter.load(out).meta["ghnerf_painter.trained_on"] == "first"


def test_an_export_without_int8_removes_the_int8_file_of_the_painter_it_replaces(tmp_path, data64, capsys):
    """The previous painter's novel_painter.int8.onnx stayed beside the new fp32 one, and the runtime, which takes
    the int8 file first (precision auto or int8), ran the old painter without a word; the card kept listing it."""
    card_dir, out = _export_setup(tmp_path, data64)
    assert main(["export", "--net", str(tmp_path / "fill_net.pt"), "--out", str(out), "--card-dir", str(card_dir),
                 "--calib-cache", str(tmp_path / "cache.npz")]) == 0
    assert NovelPainter.find(out.parent).name == "novel_painter.int8.onnx"
    net = _net(1)
    save_net(net, FillTrainConfig(net=net.cfg), tmp_path / "next.pt", steps=9, seconds=1.0, hardware="cpu")
    capsys.readouterr()
    assert main(["export", "--net", str(tmp_path / "next.pt"), "--out", str(out), "--card-dir", str(card_dir)]) == 0
    assert not out.with_suffix(".int8.onnx").exists()
    assert f"{out.with_suffix('.int8.onnx')}: removed" in capsys.readouterr().err
    found = NovelPainter.find(out.parent)
    assert found == out and NovelPainter.load(found).meta["ghnerf_painter.steps"] == "9"
    files = json.loads((card_dir / "model_card.json").read_text())["files"]
    assert "ghnerf/novel_painter.onnx" in files and "ghnerf/novel_painter.int8.onnx" not in files


@pytest.mark.parametrize(("card", "said"), [
    ('{"files": {"ghnerf/encoder.onnx"', "cannot be read as JSON (JSONDecodeError"),  # cut short
    ('[]', "holds a JSON list, not a model card object"),
    ('{"files": []}', "'files' is a JSON list, not an object"),
    ('{"novel_painter": "w16"}', "'novel_painter' is a JSON str, not an object"),
    # another variant's entry no object: the MODEL_CARD.md written with the record failed on it
    ('{"novel_painter": {"baseline": "w16"}}', "MODEL_CARD.md cannot be made from it (AttributeError"),
])
def test_a_card_that_cannot_take_the_record_is_named_before_the_export(tmp_path, data64, capsys, card, said):
    """A cut or hand-edited model_card.json was read only once the painter had been written into the model
    folder: a JSONDecodeError or TypeError traceback, the new painter in place and no card record of it."""
    card_dir, out = _export_setup(tmp_path, data64)
    (card_dir / "model_card.json").write_text(card)
    with pytest.raises(SystemExit) as e:
        main(["export", "--net", str(tmp_path / "fill_net.pt"), "--out", str(out), "--card-dir", str(card_dir)])
    assert e.value.code == 2
    assert f"--card-dir {card_dir}: " in (err := capsys.readouterr().err) and said in err
    assert not out.exists() and (card_dir / "model_card.json").read_text() == card


def test_an_export_stopped_in_its_calibration_leaves_no_int8_file_of_the_previous_painter(tmp_path, data64,
                                                                                         monkeypatch):
    """A Ctrl-C while the int8 file was calibrated left the new fp32 painter beside the previous painter's int8
    file, which the runtime takes first."""
    from training import learnt_fill

    card_dir, out = _export_setup(tmp_path, data64)
    assert main(["export", "--net", str(tmp_path / "fill_net.pt"), "--out", str(out), "--card-dir", str(card_dir),
                 "--calib-cache", str(tmp_path / "cache.npz")]) == 0

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(learnt_fill, "quantize_painter", stopped)
    net = _net(1)
    save_net(net, FillTrainConfig(net=net.cfg), tmp_path / "next.pt", steps=9, seconds=1.0, hardware="cpu")
    with pytest.raises(KeyboardInterrupt):
        main(["export", "--net", str(tmp_path / "next.pt"), "--out", str(out), "--calib-cache",
              str(tmp_path / "cache.npz")])
    assert not out.with_suffix(".int8.onnx").exists()
    assert NovelPainter.load(NovelPainter.find(out.parent)).meta["ghnerf_painter.steps"] == "9"


@pytest.mark.parametrize(("score", "said"), [
    ('{"rows": {"novel, all"', "cannot be read as JSON (JSONDecodeError"),  # cut short
    ("[]", "holds a JSON list, not the train command's record"),
])
def test_an_unreadable_score_file_beside_the_net_is_named_and_the_export_goes_on(tmp_path, data64, capsys, score,
                                                                                 said):
    """A cut or hand-edited score.json beside the net was a JSONDecodeError or AttributeError traceback: it is read
    only for the held-out figures, which the export does without (as for another run's file)."""
    _, out = _export_setup(tmp_path, data64)
    (tmp_path / "score.json").write_text(score)
    assert main(["export", "--net", str(tmp_path / "fill_net.pt"), "--out", str(out)]) == 0
    assert f"{tmp_path / 'score.json'}: {said}" in capsys.readouterr().err
    report = json.loads(out.with_suffix(".json").read_text())
    assert report["held_out"] is None and report["steps"] == 7
    assert NovelPainter.load(out).meta["ghnerf_painter.steps"] == "7"


@pytest.mark.parametrize("flag", ["--calib-cache", "--val-cache"])
def test_a_cache_of_no_views_is_named_before_the_export_and_the_previous_painter_stays(tmp_path, data64, capsys,
                                                                                      flag):
    """A cache of no views (an empty int8 calibration set, or held-out set) was onnxruntime's 'calibration needs at
    least one feed dict' or numpy's 'need at least one array to concatenate', tracebacks after the new fp32
    painter had replaced the previous one, its card record not written."""
    card_dir, out = _export_setup(tmp_path, data64)
    assert main(["export", "--net", str(tmp_path / "fill_net.pt"), "--out", str(out), "--card-dir", str(card_dir),
                 "--calib-cache", str(tmp_path / "cache.npz")]) == 0
    before = {p: p.read_bytes() for p in (out, out.with_suffix(".int8.onnx"))}
    with np.load(tmp_path / "cache.npz") as z:
        np.savez(tmp_path / "empty.npz", **{k: z[k][:0] for k in z.files})
    net = _net(1)
    save_net(net, FillTrainConfig(net=net.cfg), tmp_path / "next.pt", steps=9, seconds=1.0, hardware="cpu")
    capsys.readouterr()
    assert main(["export", "--net", str(tmp_path / "next.pt"), "--out", str(out), "--card-dir", str(card_dir),
                 flag, str(tmp_path / "empty.npz")]) == 2
    assert f"{tmp_path / 'empty.npz'}: fill-feature cache holds no views" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in before} == before


def test_a_net_the_device_cannot_run_is_refused_before_the_previous_painter_is_touched(tmp_path, data64, capsys):
    """A net trained with the relit fill (FillNetConfig's default) was refused by PainterGraph only after the
    previous painter's int8 file had been removed ('removed, the int8 file of the painter this export replaces'):
    a ValueError traceback, and the model folder left with the previous fp32 painter alone."""
    card_dir, out = _export_setup(tmp_path, data64)
    assert main(["export", "--net", str(tmp_path / "fill_net.pt"), "--out", str(out), "--card-dir", str(card_dir),
                 "--calib-cache", str(tmp_path / "cache.npz")]) == 0
    before = {p: p.read_bytes() for p in (out, out.with_suffix(".int8.onnx"), card_dir / "model_card.json")}
    relit = FillNet(FillNetConfig(width=8))
    save_net(relit, FillTrainConfig(net=relit.cfg), tmp_path / "relit.pt", steps=9)
    capsys.readouterr()
    assert main(["export", "--net", str(tmp_path / "relit.pt"), "--out", str(out), "--card-dir", str(card_dir)]) == 2
    err = capsys.readouterr().err
    assert f"error: --net {tmp_path / 'relit.pt'}: the runtime's painter is trained with net.relit_input=false" in err
    assert "removed" not in err
    assert {p: p.read_bytes() for p in before} == before
