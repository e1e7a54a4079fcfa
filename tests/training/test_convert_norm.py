"""Scene normalisation: ``SceneNorm2d`` is BatchNorm's training-time function, and a BatchNorm-trained
checkpoint converts to it without touching the learnt weights (``training.convert_norm``)."""
from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from training.configs import preset  # noqa: E402
from training.convert_norm import main, to_scene_norm  # noqa: E402
from training.model import GHNeRF, ModelConfig  # noqa: E402
from training.model.layers import SceneNorm2d  # noqa: E402


def trained_looking_batchnorm_model() -> GHNeRF:
    torch.manual_seed(0)
    model = GHNeRF(preset("tiny"))
    g = torch.Generator().manual_seed(1)
    for m in model.feature_net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):  # running statistics far from any one scene's
            m.weight.data = 0.5 + torch.rand(m.num_features, generator=g)
            m.bias.data = torch.randn(m.num_features, generator=g) * 0.1
            m.running_mean = torch.randn(m.num_features, generator=g)
            m.running_var = 0.5 + torch.rand(m.num_features, generator=g) * 3
    return model


def test_scene_norm_is_batchnorm_in_training_mode():
    x = torch.randn(2, 6, 9, 7) * 3 + 1
    bn, sn = torch.nn.BatchNorm2d(6), SceneNorm2d(6)
    with torch.no_grad():
        bn.weight.uniform_(0.5, 2)
        bn.bias.uniform_(-1, 1)
    sn.load_state_dict({"weight": bn.weight.detach().clone(), "bias": bn.bias.detach().clone()})
    want = bn.train()(x)
    assert torch.allclose(sn.eval()(x), want, atol=1e-5)  # the same in eval mode: no running statistics
    assert torch.allclose(sn.train()(x), want, atol=1e-5)
    # each channel of the pair comes out with the affine's mean and spread
    y = SceneNorm2d(6)(x)
    assert torch.allclose(y.mean(dim=(0, 2, 3)), torch.zeros(6), atol=1e-5)
    assert torch.allclose(y.var(dim=(0, 2, 3), unbiased=False), torch.ones(6), atol=1e-3)


def test_a_batchnorm_checkpoint_converts_to_what_its_training_computed():
    model = trained_looking_batchnorm_model()
    ck = {"model": model.state_dict(), "model_config": model.config.to_dict(), "step": 7}
    conv = to_scene_norm(ck)
    assert conv["step"] == 7 and ck["model_config"]["features"]["norm"] == "batch"  # the input is untouched
    assert ModelConfig.from_dict(conv["model_config"]).features.norm == "scene"
    scene = GHNeRF(ModelConfig.from_dict(conv["model_config"]))
    scene.load_state_dict(conv["model"])  # strict: every weight has its place, no running statistics left
    images = torch.rand(2, 3, 64, 64)
    x = (images - model.mean) / model.std
    with torch.no_grad():
        trained = model.feature_net.train()(x)  # what every training step computed
        running = model.feature_net.eval()(x)  # what BatchNorm inference computes
        converted = scene.eval().feature_net(x)
    for k in trained:
        assert torch.allclose(converted[k], trained[k], atol=1e-5), k
    assert not torch.allclose(running["feat_s4"], trained["feat_s4"], atol=1e-2)
    # a weights-only file (the shipped format: the state dict with its config beside it)
    flat = to_scene_norm({**model.state_dict(), "model_config": model.config.to_dict()})
    assert not any(k.startswith("feature_net.") and k.endswith("running_mean") for k in flat)


def test_conversion_errors_name_the_problem(tmp_path, capsys):
    model = trained_looking_batchnorm_model()
    ck = {"model": model.state_dict(), "model_config": model.config.to_dict()}
    with pytest.raises(ValueError, match="model_config"):
        to_scene_norm({"model": model.state_dict()})
    with pytest.raises(ValueError, match="'scene', not 'batch'"):
        to_scene_norm(to_scene_norm(ck))
    src = tmp_path / "last.pt"
    torch.save(ck, src)
    assert main([str(src), str(src)]) == 2 and "is the input" in capsys.readouterr().err
    assert main([str(tmp_path / "missing.pt"), str(tmp_path / "x.pt")]) == 2
    assert "missing.pt" in capsys.readouterr().err
    assert main([str(src), str(tmp_path / "out" / "scene.pt")]) == 0
    assert (tmp_path / "out" / "scene.pt").exists()


def test_a_write_cut_short_leaves_the_earlier_conversion_whole_and_is_named(tmp_path, capsys, disk_full_at):
    """A full disk halfway through the write left half a checkpoint under the output's name, in place of the
    earlier conversion there, and a traceback."""
    model = trained_looking_batchnorm_model()
    src, dst = tmp_path / "last.pt", tmp_path / "scene.pt"
    torch.save({"model": model.state_dict(), "model_config": model.config.to_dict()}, src)
    assert main([str(src), str(dst)]) == 0
    before = dst.read_bytes()
    disk_full_at(tmp_path, "scene.pt")
    assert main([str(src), str(dst)]) == 1
    assert f"convert_norm: {dst}: cannot write the converted checkpoint (No space left on device); the file there " \
           "is as it was" in capsys.readouterr().err
    assert dst.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["last.pt", "scene.pt"]
