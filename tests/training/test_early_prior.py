"""``training.early_prior``: the keypoint graph exported from the pretraining's ``human.pt``."""
from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from tests.training.test_pretrain_human import tiny_pretrain  # noqa: E402  (data64: conftest)
from training.early_prior import export_keypoint_graph  # noqa: E402
from training.model_card import graph_sha256  # noqa: E402
from training.pretrain_human import pretrain  # noqa: E402


def test_export_does_not_read_a_model_human_init_moved_since_the_pretraining(data64, tmp_path):
    """``human_init`` replaces every encoder weight: the export built the model by reading the joint run's
    ``model.human.init`` too, and a file moved since the pretraining (a pipeline run again after a stop) failed
    the early prior; the graph is the same either way."""
    from tests.training.test_resnet18_names import fake_state_dict

    weights = tmp_path / "resnet18.pth"
    torch.save(fake_state_dict(), weights)
    model = {"human": {"init": str(weights)}}
    pretrain(tiny_pretrain(data64, iterations=1, eval_every=0, model=model), tmp_path / "pre", quiet=True)
    train_config = {"preset": "tiny", "data": str(data64), "model": model,
                    "human_init": str(tmp_path / "pre" / "human.pt")}
    before = export_keypoint_graph(train_config, data64, 1, tmp_path / "before")
    weights.rename(tmp_path / "moved.pth")
    after = export_keypoint_graph(train_config, data64, 1, tmp_path / "after")
    assert {k: graph_sha256(p) for k, p in after.items()} == {k: graph_sha256(p) for k, p in before.items()}


def test_a_full_disk_in_the_request_write_leaves_no_half_request(tmp_path, disk_full_at, monkeypatch):
    """``request.json`` is written last, as the mark of a finished early prior: written in place, a full disk left
    half of one, which the pipeline's prior stage then read as no early prior and trained the prior again."""
    import json

    import training.pipeline
    from training import early_prior, skeleton_prior
    from training.early_prior import JOB_FILE, REQUEST_FILE

    human, prior = tmp_path / "human.pt", tmp_path / "skeleton_prior.onnx"
    human.write_bytes(b"encoder")
    job = tmp_path / JOB_FILE
    job.write_text(json.dumps({"prior_argv": ["--out", str(prior)], "train_config": {"human_init": str(human)},
                               "request": {"steps": 1}, "threads": 1, "data": "d", "calib_scenes": 1}))
    graph = tmp_path / "human.onnx"
    graph.write_bytes(b"graph")
    monkeypatch.setattr(training.pipeline, "early_prior_current", lambda *a: False)
    monkeypatch.setattr(early_prior, "export_keypoint_graph", lambda *a: {"human.onnx": graph})
    monkeypatch.setattr("training.model_card.graph_sha256", lambda path: "0" * 64)

    def train_prior(argv: list[str]) -> int:
        prior.write_bytes(b"prior")
        return 0

    monkeypatch.setattr(skeleton_prior, "main", train_prior)
    disk_full_at(tmp_path, REQUEST_FILE)
    with pytest.raises(OSError, match="No space left"):
        early_prior.main([str(job)])
    assert prior.read_bytes() == b"prior"  # the prior was trained: only its mark failed
    assert not (tmp_path / REQUEST_FILE).exists()
    assert not any(p.name.startswith(f".{REQUEST_FILE}") for p in tmp_path.iterdir())
