"""``python -m training.skeleton_prior`` end to end on the tiny model and a 64 px dataset: collect, train,
export, score, and record in a model card (the pipeline's ``prior_ghnerf`` stage runs exactly this)."""
from __future__ import annotations

import json
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

    argv = ["--model-dir", str(models / "ghnerf"), "--data", str(data64), "--extra-data", str(data64),
            "--steps", "3", "--hidden", "16", "--card", str(models)]
    assert sp.main(argv) == 0
    out = models / "ghnerf" / FILE_NAME
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["train_scenes"] == 6 and result["scenes"] == 2  # the extra folder's scenes are added
    assert result["command"].startswith("python -m training.skeleton_prior --model-dir")
    gated = result["metrics"]["gated"]
    assert set(gated) == {"0.03", "0.05", "0.075", "0.1", "0.15", "inf"}
    assert gated["inf"]["found"] == 1.0 and gated["inf"]["joints"] == result["metrics"]["all"]["joints"] == 50
    assert [g["found"] for g in gated.values()] == sorted(g["found"] for g in gated.values())
    prior = SkeletonPrior.load(out)
    assert prior.metadata["ghnerf_skeleton.scenes"] == "6"
    assert prior.metadata["ghnerf_skeleton.encoder_sha256"] == sp._sha256(models / "ghnerf" / result["encoder_file"])
    card = json.loads((models / "model_card.json").read_text())
    assert card["files"]["ghnerf/skeleton_prior.onnx"]["sha256"] == result["sha256"]
    assert card["skeleton_prior"]["ghnerf"]["metrics"] == result["metrics"]
    assert "### Skeleton prior (`ghnerf/skeleton_prior.onnx`)" in (models / "MODEL_CARD.md").read_text()
    est = prior.estimate(arrays["uv"], arrays["confidence"], arrays["valid"], arrays["P"])
    assert np.isfinite(est.points).all() and est.points.shape == (3, 25, 3)


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
