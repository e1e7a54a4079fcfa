"""The ResNet18 human encoder loads a torchvision-format state dict with strict key matching.

torchvision is not a dependency: the expected key list is written out here by hand from
torchvision's ``resnet18`` layout (BasicBlock: conv1, bn1, conv2, bn2, downsample.0/.1).
"""
from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from training.model.human_encoder import (  # noqa: E402
    HumanEncoder, HumanEncoderConfig, ResNet18Trunk, load_torchvision_resnet18,
)

BN = ("weight", "bias", "running_mean", "running_var", "num_batches_tracked")


def torchvision_resnet18_shapes() -> dict[str, tuple[int, ...]]:
    """Every key of torchvision's resnet18().state_dict() with its shape."""
    shapes: dict[str, tuple[int, ...]] = {"conv1.weight": (64, 3, 7, 7)}

    def bn(prefix: str, c: int) -> None:
        for k in BN:
            shapes[f"{prefix}.{k}"] = () if k == "num_batches_tracked" else (c,)

    bn("bn1", 64)
    inplanes = 64
    for layer, planes in enumerate((64, 128, 256, 512), start=1):
        for block in range(2):
            p = f"layer{layer}.{block}"
            cin = inplanes if block == 0 else planes
            shapes[f"{p}.conv1.weight"] = (planes, cin, 3, 3)
            bn(f"{p}.bn1", planes)
            shapes[f"{p}.conv2.weight"] = (planes, planes, 3, 3)
            bn(f"{p}.bn2", planes)
            if block == 0 and layer > 1:
                shapes[f"{p}.downsample.0.weight"] = (planes, inplanes, 1, 1)
                bn(f"{p}.downsample.1", planes)
        inplanes = planes
    shapes["fc.weight"] = (1000, 512)
    shapes["fc.bias"] = (1000,)
    return shapes


def fake_state_dict() -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    out = {}
    for k, shape in torchvision_resnet18_shapes().items():
        out[k] = torch.tensor(7, dtype=torch.long) if k.endswith("num_batches_tracked") else torch.randn(
            shape, generator=g)
    return out


def test_expected_key_count():
    # torchvision resnet18 has 122 state-dict entries (102 without num_batches_tracked)
    assert len(torchvision_resnet18_shapes()) == 122


@pytest.mark.parametrize("num_layers", [2, 3, 4])
def test_trunk_keys_equal_torchvision_keys_of_used_layers(num_layers):
    trunk = ResNet18Trunk(num_layers)
    ours = {k: tuple(v.shape) for k, v in trunk.state_dict().items()}
    unused = ("fc.",) + tuple(f"layer{i}." for i in range(num_layers + 1, 5))
    expected = {k: s for k, s in torchvision_resnet18_shapes().items() if not k.startswith(unused)}
    assert ours == expected


def test_strict_load_and_dropped_keys():
    trunk = ResNet18Trunk(3)
    state = fake_state_dict()
    dropped = load_torchvision_resnet18(trunk, state)
    assert "fc.weight" in dropped and "layer4.0.conv1.weight" in dropped
    assert all(k.startswith(("fc.", "layer4.")) for k in dropped)
    torch.testing.assert_close(trunk.layer3[1].bn2.running_var, state["layer3.1.bn2.running_var"])
    torch.testing.assert_close(trunk.conv1.weight, state["conv1.weight"])


def test_load_from_file_with_wrapper_and_module_prefix(tmp_path):
    state = {f"module.{k}": v for k, v in fake_state_dict().items()}
    path = tmp_path / "resnet18.pth"
    torch.save({"state_dict": state}, path)
    enc = HumanEncoder(HumanEncoderConfig(num_layers=3, out_channels=8, init=str(path)))
    torch.testing.assert_close(enc.trunk.layer1[0].conv1.weight, state["module.layer1.0.conv1.weight"])


def test_missing_used_key_fails_strictly():
    state = fake_state_dict()
    del state["layer2.0.downsample.1.running_mean"]
    with pytest.raises(RuntimeError, match="downsample.1.running_mean"):
        load_torchvision_resnet18(ResNet18Trunk(3), state)


def test_wrong_shape_fails():
    state = fake_state_dict()
    state["layer1.0.conv1.weight"] = torch.zeros(64, 64, 1, 1)
    with pytest.raises(RuntimeError, match="layer1.0.conv1.weight"):
        load_torchvision_resnet18(ResNet18Trunk(2), state)


def test_a_mismatch_is_named_by_its_first_key_whole():
    """torch's strict-load message lists every key and was cut at 200 characters by the trainer, before the shapes
    of a mis-shaped key or the name of a missing one behind a long list of others."""
    from training.model.human_encoder import ResNet18WeightsError

    state = fake_state_dict()
    state["layer1.0.conv1.weight"] = torch.zeros(64, 64, 1, 1)
    with pytest.raises(ResNet18WeightsError, match=r"^'layer1\.0\.conv1\.weight' has shape \[64, 64, 1, 1\], "
                                                   r"resnet18 \[64, 64, 3, 3\]$"):
        load_torchvision_resnet18(ResNet18Trunk(2), state)
    prefixed = {f"net.{k}": v for k, v in fake_state_dict().items()}
    with pytest.raises(ResNet18WeightsError, match=r"^no key 'conv1\.weight' and 59 more; unexpected key "
                                                   r"'net\.conv1\.weight' and 121 more$"):
        load_torchvision_resnet18(ResNet18Trunk(2), prefixed)
    with pytest.raises(ResNet18WeightsError, match="^holds a list, not a state dict$"):
        load_torchvision_resnet18(ResNet18Trunk(2), [1, 2])
