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
