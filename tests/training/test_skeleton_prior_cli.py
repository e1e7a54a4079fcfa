"""``python -m training.skeleton_prior`` end to end on the tiny model and a 64 px dataset: collect, train,
export, score, and record in a model card (the pipeline's ``prior_ghnerf`` stage runs exactly this)."""
from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("onnx")


def test_collect_train_export_score_and_card(tmp_path, data64):
    from ghnerf_runtime.skeleton_prior import FILE_NAME, SkeletonPrior
    from tests.ghnerf_runtime.test_session import export_tiny
    from training import skeleton_prior as sp
    from training.model_card import write_card

    models = tmp_path / "models"
    shutil.copytree(export_tiny(tmp_path / "export"), models / "ghnerf")
    write_card(models, {"name": "t", "files": {}, "metrics": {}})

    arrays = sp.collect(models / "ghnerf", data64, "train", progress=False)
    assert arrays["uv"].shape == (3, 2, 25, 2) and arrays["P"].shape == (3, 2, 3, 4)
    assert str(arrays["encoder_file"]) in ("human.onnx", "human.int8.onnx")

    extra = shutil.copytree(data64, tmp_path / "extra")  # another folder (the same one twice is refused)
    argv = ["--model-dir", str(models / "ghnerf"), "--data", str(data64), "--extra-data", str(extra),
            "--steps", "3", "--hidden", "16", "--card", str(models), "--tilt-share", "0.5", "--tilt-mode", "body"]
    assert sp.main(argv) == 0
    out = models / "ghnerf" / FILE_NAME
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["train_scenes"] == 6 and result["scenes"] == 2  # the extra folder's scenes are added
    # and turned copies of half of them (the recorded config says how)
    assert result["tilted_scenes"] == 3 and result["config"]["tilt_share"] == 0.5
    assert result["config"]["tilt_mode"] == "body"
    assert result["command"].startswith("python -m training.skeleton_prior --model-dir")
    gated = result["metrics"]["gated"]
    assert set(gated) == {"0.03", "0.05", "0.075", "0.1", "0.15", "inf"}
    assert gated["inf"]["found"] == 1.0 and gated["inf"]["joints"] == result["metrics"]["all"]["joints"] == 50
    assert [g["found"] for g in gated.values()] == sorted(g["found"] for g in gated.values())
    prior = SkeletonPrior.load(out)
    assert prior.metadata["ghnerf_skeleton.scenes"] == "6" and prior.metadata["ghnerf_skeleton.tilted_scenes"] == "3"
    assert json.loads(prior.metadata["ghnerf_skeleton.config"])["tilt_share"] == 0.5
    assert prior.metadata["ghnerf_skeleton.encoder_sha256"] == sp._sha256(models / "ghnerf" / result["encoder_file"])
    card = json.loads((models / "model_card.json").read_text())
    assert card["files"]["ghnerf/skeleton_prior.onnx"]["sha256"] == result["sha256"]
    assert card["skeleton_prior"]["ghnerf"]["metrics"] == result["metrics"]
    assert card["skeleton_prior"]["ghnerf"]["tilted_scenes"] == 3  # the card says it learnt from turned copies
    card_md = (models / "MODEL_CARD.md").read_text()
    assert "### Skeleton prior (`ghnerf/skeleton_prior.onnx`)" in card_md
    assert "6 training scenes and 3 copies of them with the body turned to any angle (`--tilt-share 0.5`)" in card_md
    est = prior.estimate(arrays["uv"], arrays["confidence"], arrays["valid"], arrays["P"])
    assert np.isfinite(est.points).all() and est.points.shape == (3, 25, 3)


def test_out_goes_to_a_new_folder_and_a_folder_or_unmakeable_path_is_refused_before_training(tmp_path, data64,
                                                                                                capsys):
    from ghnerf_runtime.skeleton_prior import FILE_NAME
    from tests.ghnerf_runtime.test_session import export_tiny
    from training import skeleton_prior as sp

    model = export_tiny(tmp_path / "export")
    base = ["--model-dir", str(model), "--data", str(data64), "--steps", "2", "--hidden", "8"]
    out = tmp_path / "new" / "deeper" / FILE_NAME  # its folder does not exist yet: made
    assert sp.main([*base, "--out", str(out)]) == 0 and out.exists() and out.with_suffix(".json").exists()

    (tmp_path / "a_file").write_text("")
    for bad, says in ((tmp_path / "new", "is a folder"), (tmp_path / "a_file" / FILE_NAME, "cannot make the folder")):
        with pytest.raises(SystemExit) as e:
            sp.main([*base, "--out", str(bad)])
        assert e.value.code == 2 and says in capsys.readouterr().err


def test_outlier_tool_compares_prior_files_on_the_same_joints(tmp_path, data64, capsys):
    """``benchmarks/measure_prior_outliers.py`` runs a file of each feature version on one collection."""
    import onnx

    from benchmarks import measure_prior_outliers
    from ghnerf_runtime.skeleton_prior import FILE_NAME, META_PREFIX
    from tests.ghnerf_runtime.test_session import export_tiny
    from training import skeleton_prior as sp

    model = tmp_path / "ghnerf"  # a copy: the exported tiny model is shared by the session's tests
    shutil.copytree(export_tiny(tmp_path / "export"), model)
    assert sp.main(["--model-dir", str(model), "--data", str(data64), "--steps", "2", "--hidden", "8"]) == 0
    old = onnx.load(str(model / FILE_NAME))  # the same network stamped as version 1: run without the limit
    next(p for p in old.metadata_props if p.key == META_PREFIX + "feature_version").value = "1"
    onnx.save(old, str(tmp_path / "v1.onnx"))
    capsys.readouterr()
    assert measure_prior_outliers.main(["--model-dir", str(model), "--data", str(data64), "--split", "val",
                                        "--prior", str(model / FILE_NAME), "--prior", str(tmp_path / "v1.onnx")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("val: 2 scenes; DLT points farther than 2 m from the body:")
    assert len(out) == 3 and all("MPJPE" in line and "joints > 0.5 m off" in line for line in out[1:])


def test_ghnerf_eval_scores_the_folder_prior_and_skips_a_stale_one(tmp_path, data64, capsys):
    import onnx

    from ghnerf_runtime.skeleton_prior import FILE_NAME, META_PREFIX
    from tests.ghnerf_runtime.test_session import export_tiny
    from training import skeleton_prior as sp
    from training.data.torch_dataset import MultiViewDataset
    from training.evaluate import evaluate, make_renderer

    model = tmp_path / "ghnerf"  # a copy: the exported tiny model is shared by the session's tests
    shutil.copytree(export_tiny(tmp_path / "export"), model)
    assert make_renderer(str(model))[0].skeleton_prior is None  # no file: nothing to score
    assert sp.main(["--model-dir", str(model), "--data", str(data64), "--steps", "2", "--hidden", "8"]) == 0
    renderer, _ = make_renderer(str(model))
    assert renderer.skeleton_prior is not None
    res = evaluate(renderer, MultiViewDataset(data64, "val"), novel=False, progress=False)
    assert res["skeleton_prior_mpjpe_mm"] > 0 and 0.0 <= res["skeleton_prior_gated_found"] <= 1.0
    stale = onnx.load(str(model / FILE_NAME))
    next(p for p in stale.metadata_props if p.key == META_PREFIX + "feature_version").value = "1"
    onnx.save(stale, str(model / FILE_NAME))
    capsys.readouterr()
    assert make_renderer(str(model))[0].skeleton_prior is None
    assert "the skeleton prior is not scored" in capsys.readouterr().err


def test_hiding_a_view_also_hides_that_views_extra_columns():
    """A measurement's extra per-view columns (past ``JOINT_FEATURES``, view 0's half first) go with the view
    the augmentation hides; without extra columns the hiding is the same as before."""
    import torch

    from ghnerf_runtime.skeleton_prior import JOINT_FEATURES
    from training.skeleton_prior import _hide_in_one_view

    base = torch.rand(64, 25, JOINT_FEATURES) + 0.5  # nothing is 0 before hiding
    extra = torch.rand(64, 25, 6) + 0.5  # three columns per view
    plain = _hide_in_one_view(base, 0.3, torch.Generator().manual_seed(4))
    wide = _hide_in_one_view(torch.cat([base, extra], -1), 0.3, torch.Generator().manual_seed(4))
    torch.testing.assert_close(wide[..., :JOINT_FEATURES], plain)  # same draws, same hiding
    hidden0 = plain[..., 4] == 0  # view 0's peak value gone: that joint lost view 0
    hidden1 = plain[..., 5] == 0
    assert hidden0.any() and hidden1.any() and not (hidden0 & hidden1).any()
    ext = wide[..., JOINT_FEATURES:]
    assert (ext[hidden0][:, :3] == 0).all() and (ext[hidden0][:, 3:] > 0).all()
    assert (ext[hidden1][:, 3:] == 0).all() and (ext[hidden1][:, :3] > 0).all()
    kept = ~(hidden0 | hidden1)
    torch.testing.assert_close(ext[kept], extra[kept])


def test_peak_shape_reads_spread_along_the_epipolar_line_and_a_second_blob():
    """``benchmarks/measure_prior_peak_shape.peak_shape``: a heatmap stretched along the epipolar line spreads
    more along it than across; stretched across, the other way; a second blob takes mass from the peak."""
    from benchmarks.measure_prior_peak_shape import peak_shape
    from ghnerf_runtime.geometry.camera import Camera, look_at

    K = np.array([[60.0, 0, 31.5], [0, 60.0, 31.5], [0, 0, 1]])
    P = np.stack([Camera("c", 64, 64, K, [], *look_at((x, 0.0, 0.0), (0.0, 0.0, 3.0))).P for x in (-0.6, 0.6)])
    X = np.array([0.1, 0.2, 3.0, 1.0])
    uv = np.stack([(p @ X)[:2] / (p @ X)[2] for p in P])  # (2, 2) model px
    # the cameras stand side by side looking the same way: the epipolar lines run along the image x axis
    yy, xx = np.mgrid[:16, :16].astype(float)
    cell = (uv + 0.5) / 4 - 0.5

    def blob(c, sx, sy):
        return np.exp(-0.5 * (((xx - c[0]) / sx) ** 2 + ((yy - c[1]) / sy) ** 2))

    heat = np.zeros((2, 25, 16, 16))
    heat[:, 0] = [blob(cell[v], 2.0, 0.7) for v in range(2)]  # stretched along x: along the epipolar line
    heat[:, 1] = [blob(cell[v], 0.7, 2.0) for v in range(2)]  # stretched across it
    heat[:, 2] = [blob(cell[v], 1.0, 1.0) for v in range(2)]
    heat[:, 3] = [blob(cell[v], 1.0, 1.0) + blob(cell[v] - [0.0, 6.0], 1.0, 1.0) for v in range(2)]
    uvs = np.repeat(uv[:, None], 25, 1)
    valid = np.zeros((2, 25), bool)
    valid[:, :4] = True
    s = peak_shape(heat, uvs, valid, P, 64)
    assert s.shape == (2, 25, 3) and np.isfinite(s).all()
    assert (s[:, 0, 0] > s[:, 0, 1] + 0.5).all() and (s[:, 1, 1] > s[:, 1, 0] + 0.5).all()
    assert (s[:, 2, 2] > 0.95).all() and (np.abs(s[:, 3, 2] - 0.5) < 0.05).all()  # half the mass elsewhere
    assert (s[:, 4:] == 0).all()  # not decoded: nothing said
    wild = peak_shape(np.full((2, 25, 16, 16), np.nan), np.full((2, 25, 2), 1e12), np.ones((2, 25), bool), P, 64)
    assert np.isfinite(wild).all()


def _without_time(result: dict) -> dict:
    return {k: v for k, v in result.items() if k != "train_s"}


def test_peak_shape_measurement_trains_each_variant(tmp_path, data64, capsys):
    """``benchmarks/measure_prior_peak_shape.py`` collects through ``collect(per_scene=)``, caches, and scores
    a prior per variant on the same joints."""
    from benchmarks import measure_prior_peak_shape as m
    from tests.ghnerf_runtime.test_session import export_tiny

    model = tmp_path / "ghnerf"
    shutil.copytree(export_tiny(tmp_path / "export"), model)
    argv = ["--model-dir", str(model), "--data", str(data64), "--extra-data", str(data64), "--steps", "2",
            "--hidden", "8", "--threads", "1", "--cache", str(tmp_path / "c.npz")]
    capsys.readouterr()
    assert m.main(argv) == 0
    first = capsys.readouterr().out.splitlines()
    assert first[0].startswith("collected 6 training and 2 held-out scenes")
    assert [line.split(" ")[0] for line in first[1:4]] == ["base", "shape", "mass"]
    res = json.loads(first[-1])
    assert set(res) == {"base", "shape", "mass"} and all(r["mean_mm"] > 0 for r in res.values())
    z = np.load(tmp_path / "c.npz")
    assert z["tr_shape"].shape == (6, 2, 25, 4) and z["va_shape"].shape == (2, 2, 25, 4)
    assert m.main(argv + ["--variants", "base"]) == 0  # from the cache: the same answer
    again = capsys.readouterr().out.splitlines()
    assert not again[0].startswith("collected")
    # the same figures; its training time (whole seconds) may round differently on a second run
    assert _without_time(json.loads(again[-1])["base"]) == _without_time(res["base"])
    with pytest.raises(SystemExit):
        m.main(argv + ["--variants", "base,nope"])


def test_a_hidden_joint_is_what_the_device_builds_for_it():
    """Training hides a joint in one view as :func:`prior_inputs` builds a joint that view did not decode: no
    DLT point, angle or reprojection error in either view (the device has none without a point), no peak, ray or
    flag in that view. The scene is made so that the joint does not place the body's centre (its reprojection
    error is past the root's 3 px), so the device's frame is the same and the features must match exactly
    (training does not rebuild the frame: a joint that helps place the centre moves it a little)."""
    import torch

    from ghnerf_runtime.skeleton_prior import prior_inputs
    from tests.ghnerf_runtime.test_skeleton_prior import _observe, _rig, _skeleton
    from training.skeleton_prior import _hide_joints

    P, X = np.stack(_rig()), _skeleton(3)
    uv, conf, valid = _observe(list(P), X)
    conf = conf * np.linspace(0.4, 1.0, 25)
    uv = uv + np.random.default_rng(0).normal(0.0, 0.3, uv.shape)  # every joint a little off
    j = 7
    uv[0, j, 1] += 12.0  # across the epipolar lines: a reprojection error the DLT cannot absorb
    full = prior_inputs(uv[None], conf[None], valid[None], P[None])
    assert full.triangulated[0].all() and full.joint_features[0, j, 6:8].min() > 3.0 / 5.0
    for v in (0, 1):
        gone = valid.copy()
        gone[v, j] = False
        device = prior_inputs(uv[None], conf[None], gone[None], P[None])
        np.testing.assert_array_equal(device.frame.rotation, full.frame.rotation)
        np.testing.assert_array_equal(device.frame.origin, full.frame.origin)
        hide = torch.zeros(1, 25, dtype=torch.bool)
        hide[0, j] = True
        trained = _hide_joints(torch.from_numpy(full.joint_features), hide, torch.full((1, 25), v)).numpy()
        # one float32 computation on both sides: equal bit for bit
        np.testing.assert_array_equal(trained[0, j], device.joint_features[0, j])
        np.testing.assert_array_equal(trained, device.joint_features)  # the other joints are untouched


def _stop(*args, **kwargs):
    raise KeyboardInterrupt("stopped")


def test_an_interrupted_export_leaves_the_old_file_whole(tmp_path, monkeypatch):
    """The ONNX file is built in memory and replaces the old one whole: stopped before that, the old file (with
    its ``ghnerf_skeleton.*`` metadata, without which the runtime refuses it) is still there, and no other file."""
    import onnx

    from ghnerf_runtime.skeleton_prior import FILE_NAME, SkeletonPrior
    from training import skeleton_prior as sp

    path = tmp_path / FILE_NAME
    sp.export(sp.make_network(8), path, {"scenes": "1"})
    before = path.read_bytes()
    for name in ("load", "load_from_string", "save"):  # stopped while the metadata is added
        monkeypatch.setattr(onnx, name, _stop)
    with pytest.raises(KeyboardInterrupt):
        sp.export(sp.make_network(8), path, {"scenes": "2"})
    monkeypatch.undo()
    assert path.read_bytes() == before and SkeletonPrior.load(path).metadata["ghnerf_skeleton.scenes"] == "1"
    assert [p.name for p in tmp_path.iterdir()] == [FILE_NAME]


def test_the_models_folder_is_read_as_the_runtime_reads_it_and_a_stopped_run_leaves_no_stale_report(
        tmp_path, data64, monkeypatch):
    """``--model-dir models`` is ``models/ghnerf`` for the collection, the default ``--out`` and the encoder's
    hash alike; a run stopped after its file replaced the old one leaves no report of the old file beside it."""
    from ghnerf_runtime.skeleton_prior import FILE_NAME, SkeletonPrior
    from tests.ghnerf_runtime.test_session import export_tiny
    from training import skeleton_prior as sp

    models = tmp_path / "models"
    shutil.copytree(export_tiny(tmp_path / "export"), models / "ghnerf")
    base = ["--data", str(data64), "--steps", "2", "--hidden", "8", "--threads", "1"]
    assert sp.main(["--model-dir", str(models), *base]) == 0
    out = models / "ghnerf" / FILE_NAME
    assert out.is_file() and out.with_suffix(".json").is_file() and not (models / FILE_NAME).exists()
    SkeletonPrior.load(out).check_encoder(models / "ghnerf")  # the runtime takes it beside this encoder

    monkeypatch.setattr(SkeletonPrior, "estimate", _stop)  # stopped while scoring the new file
    with pytest.raises(KeyboardInterrupt):
        sp.main(["--model-dir", str(models / "ghnerf"), *base, "--seed", "1"])
    monkeypatch.undo()
    assert not out.with_suffix(".json").exists()  # the old figures went with the old file
    assert json.loads(SkeletonPrior.load(out).metadata["ghnerf_skeleton.config"])["seed"] == 1
    assert not [p.name for p in (models / "ghnerf").iterdir() if p.name.startswith(".")]  # no temporary left


@pytest.mark.parametrize("more, says", [
    (["--limit", "-1"], "--limit must be 0 (all scenes) or more, not -1"),
    (["--val-split", "train"], "--train-split and --val-split are both 'train'"),
    (["--extra-data", "{data}/../{name}"], "is the folder --data already gives"),
    (["--out", "{model}/prior_b.onnx", "--card", "{models}"], "--card records the prior the runtime loads"),
    (["--tilt-share", "1.5"], "--tilt-share must be a share from 0 to 1, not 1.5"),
    (["--tilt-share", "nan"], "--tilt-share must be a share from 0 to 1, not nan"),
    (["--tilt-mode", "rig"], "argument --tilt-mode: invalid choice: 'rig'"),
    # torch's 'Overflow when unpacking long long' (numpy's 'expected non-negative integer' with --tilt-share)
    # after collecting: the trainers' bound (training.run_limits)
    (["--seed", str(2 ** 64)], f"--seed: must be an integer in [0, {2 ** 32 - 1}], got {2 ** 64}"),
    (["--seed", "-1", "--tilt-share", "0.5"], f"--seed: must be an integer in [0, {2 ** 32 - 1}], got -1"),
    (["--seed", str(2 ** 32 - 1), "--members", "2"],
     f"--seed {2 ** 32 - 1} with --members 2: the last member's seed must be an integer in [0, {2 ** 32 - 1}], "
     f"got {2 ** 32}"),
    # a split or dataset that cannot be read: named before collecting (the val split was read only after)
    (["--val-split", "val_seen_motions"], "dataset.json: has no split 'val_seen_motions'"),
    (["--extra-data", "{models}"], "dataset.json: no dataset manifest here"),
])
def test_runs_whose_figures_would_mislead_are_refused_before_collecting(tmp_path, data64, capsys, more, says):
    """A negative ``--limit``; held-out scenes that are training scenes (the same split, or the same folder
    as extra data); a card entry for a file of another name (the card records ``skeleton_prior.onnx``, the file
    the runtime loads, and reads its figures from ``skeleton_prior.json``)."""
    from training import skeleton_prior as sp
    from training.model_card import write_card

    models = tmp_path / "models"
    (models / "ghnerf").mkdir(parents=True)  # no graphs: a run that got past the checks would fail otherwise
    write_card(models, {"name": "t", "files": {}, "metrics": {}})
    fill = {"data": str(data64), "name": data64.name, "model": str(models / "ghnerf"), "models": str(models)}
    argv = ["--model-dir", str(models / "ghnerf"), "--data", str(data64), *(a.format(**fill) for a in more)]
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        sp.main(argv)
    assert e.value.code == 2 and says in capsys.readouterr().err
    with pytest.raises(ValueError, match="runtime loads"):
        sp.add_to_card(models, models / "ghnerf" / "prior_b.onnx")


def test_ghnerf_eval_skips_a_prior_of_another_encoder_as_the_runtime_refuses_it(tmp_path, capsys):
    from ghnerf_runtime.skeleton_prior import FILE_NAME
    from tests.ghnerf_runtime.test_session import export_tiny
    from training import skeleton_prior as sp
    from training.evaluate import make_renderer

    model = tmp_path / "ghnerf"
    shutil.copytree(export_tiny(tmp_path / "export"), model)
    own = {"encoder_file": "human.onnx", "encoder_sha256": sp._sha256(model / "human.onnx")}
    sp.export(sp.make_network(8), model / FILE_NAME, own)
    assert make_renderer(str(model))[0].skeleton_prior is not None
    sp.export(sp.make_network(8), model / FILE_NAME, {**own, "encoder_sha256": "0" * 64})  # another encoder's
    capsys.readouterr()
    assert make_renderer(str(model))[0].skeleton_prior is None
    err = capsys.readouterr().err
    assert "the skeleton prior is not scored" in err and "human.onnx" in err


def test_ghnerf_eval_reads_the_2d_joints_from_the_human_graph_as_the_runtime_does(tmp_path, data64):
    """The ``human`` graph where the folder has one (the runtime's keypoint graph, and the prior's collection's;
    at int8 it differs from ``encoder``), else ``encoder``."""
    from tests.ghnerf_runtime.test_session import export_tiny
    from training.data.torch_dataset import MultiViewDataset
    from training.evaluate import OnnxRenderer

    model = tmp_path / "ghnerf"
    shutil.copytree(export_tiny(tmp_path / "export"), model)
    renderer = OnnxRenderer(model)
    assert renderer.keypoint_graph == "human"
    images = MultiViewDataset(data64, "val")[0]["images"].numpy()
    want = renderer.sessions["human"].run(["encoder_heatmaps"], {"images": images})[0]

    class Refuse:
        def run(self, *args, **kwargs):
            raise AssertionError("the encoder graph ran for the 2D joints")

    renderer.sessions["encoder"] = Refuse()
    np.testing.assert_array_equal(renderer.encoder_heatmaps({"images": images}), want)
    (model / "human.onnx").unlink()
    assert OnnxRenderer(model).keypoint_graph == "encoder"


def _prior_arrays(n: int = 16):
    """Random inputs of the prior's shapes (``train`` reads ``joint_features`` and ``context``) and a truth."""
    from types import SimpleNamespace

    from ghnerf_runtime.skeleton_prior import CONTEXT_FEATURES, JOINT_FEATURES

    rng = np.random.default_rng(0)
    inputs = SimpleNamespace(joint_features=rng.normal(size=(n, 25, JOINT_FEATURES)).astype(np.float32),
                             context=rng.normal(size=(n, CONTEXT_FEATURES)).astype(np.float32))
    return inputs, rng.normal(size=(n, 25, 3)), np.ones((n, 25), bool)


def _poisoned_networks(monkeypatch, from_call: int, grad_only: bool = False) -> list:
    """``make_network`` whose networks answer NaN joints from their ``from_call``-th forward pass on (or, with
    ``grad_only``, finite joints with a NaN gradient: the slope of sqrt at 0 times 0); the networks made."""
    import torch

    from training import skeleton_prior as sp

    real, made = sp.make_network, []

    def make(hidden, *args):
        net = real(hidden, *args)
        forward, calls = net.forward, []

        def poisoned(f, c):
            calls.append(1)
            joints, log_err = forward(f, c)
            if len(calls) >= from_call:
                joints = joints + 0.0 * torch.sqrt(joints * 0.0) if grad_only else joints * float("nan")
            return joints, log_err

        net.forward = poisoned
        made.append(net)
        return net

    monkeypatch.setattr(sp, "make_network", make)
    return made


@pytest.mark.parametrize("grad_only, says", [(False, "seed 3, step 2: non-finite loss (nan)"),
                                             (True, "seed 3, step 2: non-finite gradient of a finite loss")])
def test_a_non_finite_step_stops_the_prior_before_the_update(monkeypatch, grad_only, says):
    """AdamW used to apply the NaN to every weight and train on: the exported prior answered NaN joints and
    its held-out figures were NaN, exit 0 (the painter and the main trainer already stopped)."""
    from training import skeleton_prior as sp
    from training.step_guard import TrainingDiverged

    made = _poisoned_networks(monkeypatch, from_call=2, grad_only=grad_only)
    with pytest.raises(TrainingDiverged, match=re.escape(says)):
        sp.train(*_prior_arrays(), sp.PriorTrainConfig(steps=4, hidden=8, batch=4, seed=3), progress=False)
    # the first step's update went through; the second's NaN did not reach the weights
    assert all(bool(p.isfinite().all()) for p in made[0].parameters())


def test_members_trained_side_by_side_stop_alike_on_a_nan_loss():
    """In worker processes (two members, two threads) the divergence comes back to the caller by name."""
    from training import skeleton_prior as sp
    from training.step_guard import TrainingDiverged

    inputs, truth, valid = _prior_arrays()
    inputs.joint_features[:] = np.nan  # every batch: a NaN loss at the first step
    with pytest.raises(TrainingDiverged, match=r"seed [01], step 1: non-finite loss \(nan\)"):
        sp.train(inputs, truth, valid, sp.PriorTrainConfig(steps=3, hidden=8, batch=4, members=2), progress=False,
                 threads=2)


def test_the_cli_names_a_diverged_prior_and_writes_nothing(tmp_path, data64, monkeypatch, capsys):
    """Exit 1 with one line; the old file and its figures are left as they were, no new one is written."""
    from ghnerf_runtime.skeleton_prior import FILE_NAME
    from tests.ghnerf_runtime.test_session import export_tiny
    from training import skeleton_prior as sp

    model = tmp_path / "ghnerf"
    shutil.copytree(export_tiny(tmp_path / "export"), model)
    old = model / FILE_NAME
    sp.export(sp.make_network(8), old, {"scenes": "1"})
    old.with_suffix(".json").write_text("{}\n")
    before = {p.name: p.read_bytes() for p in model.iterdir()}
    _poisoned_networks(monkeypatch, from_call=1)
    capsys.readouterr()
    new = tmp_path / "new" / FILE_NAME
    for out in (old, new):
        argv = ["--model-dir", str(model), "--data", str(data64), "--steps", "3", "--hidden", "8", "--threads", "1",
                "--out", str(out)]
        assert sp.main(argv) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1] == ("error: training diverged: seed 0, step 1: non-finite loss (nan); the weights were not "
                           "updated")
    assert {p.name: p.read_bytes() for p in model.iterdir()} == before
    assert not new.exists() and not new.with_suffix(".json").exists()
