"""The human encoder: its top-down ("fpn") decoder, the train config's model overrides, and the extra
views (novel targets, mirrored images) its auxiliary heatmap head can be supervised on."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from training.model.config import ConfigError  # noqa: E402
from training.model.human_encoder import HumanEncoder, HumanEncoderConfig  # noqa: E402
from training.train import apply_overrides, build_config, load_config_file  # noqa: E402


@pytest.mark.parametrize("scale", [0.5, 1.0])
def test_fpn_output_shape_and_heatmaps(scale):
    enc = HumanEncoder(HumanEncoderConfig(num_layers=3, out_channels=8, out_stride=4, input_scale=scale,
                                          decoder="fpn", aux_heatmaps=True)).eval()
    x = torch.randn(2, 3, 64, 64)
    feat = enc(x)
    assert feat.shape == (2, 8, 16, 16)
    assert torch.all(feat >= 0)  # the last merge ends in a ReLU
    heat = enc.heatmaps(feat)
    assert heat.shape == (2, 25, 16, 16) and torch.all((heat >= 0) & (heat <= 1))


def test_fpn_is_not_linear_in_the_levels():
    """Unlike "sum", the fpn output is not additive over the trunk levels (it mixes them through ReLUs)."""
    torch.manual_seed(0)
    cfg = HumanEncoderConfig(num_layers=2, out_channels=4, decoder="fpn")
    enc = HumanEncoder(cfg).eval()
    feats = enc.trunk(torch.randn(1, 3, 32, 32))
    zero = {k: torch.zeros_like(v) for k, v in feats.items()}
    only = {k: {**zero, k: v} for k, v in feats.items()}
    size = (8, 8)
    full = enc._top_down(feats, size)
    bias = enc._top_down(zero, size)
    parts = sum(enc._top_down(only[k], size) - bias for k in feats) + bias
    assert not torch.allclose(full, parts, atol=1e-4)


def test_sum_decoder_is_default_and_old_state_dicts_load():
    """Models trained before "fpn" existed (no ``smooth`` weights) load into the default config."""
    old = HumanEncoder(HumanEncoderConfig(num_layers=2, out_channels=4)).state_dict()
    assert not any(k.startswith("smooth.") for k in old)
    HumanEncoder(HumanEncoderConfig(num_layers=2, out_channels=4)).load_state_dict(old, strict=True)
    with pytest.raises(RuntimeError, match="smooth"):
        HumanEncoder(HumanEncoderConfig(num_layers=2, out_channels=4, decoder="fpn")).load_state_dict(old)


def test_train_config_model_overrides(tmp_path):
    data = {"preset": "tiny", "data": str(tmp_path)}
    cfg = build_config(apply_overrides(data, ['model.human.decoder="fpn"', "model.human.input_scale=0.5"]))
    mcfg = cfg.model_config()
    assert (mcfg.human.decoder, mcfg.human.input_scale) == ("fpn", 0.5)
    assert mcfg.human.out_channels == 8  # the rest of the preset is kept
    json.dumps(cfg.to_dict())  # the overrides are stored with the run's config
    with pytest.raises(ConfigError, match=r"model\.human\.decodr"):
        build_config(apply_overrides(data, ['model.human.decodr="fpn"']))
    with pytest.raises(ConfigError, match=r"model\.human\.decoder"):
        build_config(apply_overrides(data, ['model.human.decoder="unet"']))
    with pytest.raises(ConfigError, match="model"):
        build_config({**data, "model": 3})


def test_shipped_train_config_builds():
    cfg = build_config(load_config_file(Path(__file__).resolve().parents[2] / "training/train_configs/edge128.json"))
    assert cfg.model_config().human is not None


# ------------------------------------------------------------------ more views for the auxiliary head
def _item(views: int = 4, grid: int = 8, size: int = 32):
    g = torch.Generator().manual_seed(0)
    return {"tgt_images": torch.rand(views, 3, size, size, generator=g),
            "tgt_heatmaps": torch.rand(views, 25, grid, grid, generator=g),
            "tgt_is_source": torch.arange(views) < 2}


def test_aux_encoder_batch_views_and_mirroring(tmp_path):
    from ghnerf_runtime.body25 import JOINT_INDEX
    from training.train import aux_encoder_batch

    item = _item()
    base = {"preset": "tiny", "data": str(tmp_path)}
    assert aux_encoder_batch(item, build_config(base)) == {}
    both = aux_encoder_batch(item, build_config({**base, "encoder_views": "all"}))
    assert torch.equal(both["aux_images"], item["tgt_images"][2:])  # the novel views
    flip = aux_encoder_batch(item, build_config({**base, "encoder_flip": True}))
    assert flip["aux_images"].shape[0] == 2 and flip["aux_heatmaps"].shape == (2, 25, 8, 8)
    # Mirrored: pixel (v, u) -> (v, W-1-u); the right wrist's map is the left wrist's, mirrored.
    assert torch.equal(flip["aux_images"][0, :, 3, 0], item["tgt_images"][0, :, 3, -1])
    r, l_ = JOINT_INDEX["RWrist"], JOINT_INDEX["LWrist"]
    assert torch.equal(flip["aux_heatmaps"][1, r], torch.flip(item["tgt_heatmaps"][1, l_], dims=(-1,)))
    nose = JOINT_INDEX["Nose"]
    assert torch.equal(flip["aux_heatmaps"][1, nose], torch.flip(item["tgt_heatmaps"][1, nose], dims=(-1,)))
    everything = aux_encoder_batch(item, build_config({**base, "encoder_views": "all", "encoder_flip": True}))
    assert everything["aux_images"].shape[0] == 2 + 4


def test_mirroring_keeps_grid_cells_on_cell_centres():
    """Cell j's ray sits at pixel (j + 0.5) * s - 0.5; mirrored it is cell (n - 1 - j)'s ray exactly."""
    from ghnerf_runtime.contract import ray_grid

    n, s = 8, 4
    u = ray_grid(n * s, n * s, s)[:n, 0]  # first row of cell-centre pixels
    np.testing.assert_allclose((n * s - 1) - u, u[::-1])


def test_forward_returns_aux_heatmaps_and_the_loss_uses_them():
    from training.configs import preset
    from training.losses import LossConfig, compute_losses
    from training.model import GHNeRF

    model = GHNeRF(preset("tiny"))
    x = torch.rand(3, 3, 64, 64)
    heat = model.encode_human(x)
    assert heat.shape == (3, 25, 16, 16)
    outputs = {"levels": [], "encoder_heatmaps": heat[:2], "aux_encoder_heatmaps": heat}
    batch = {"rgb": torch.zeros(1, 1, 3), "source_heatmaps": torch.zeros_like(heat[:2]),
             "aux_heatmaps": torch.zeros_like(heat)}
    terms = compute_losses(outputs, batch, LossConfig(encoder_heat_weight=1.0))
    assert set(terms) >= {"enc_heat", "enc_heat_aux"}
    torch.testing.assert_close(terms["loss"], terms["enc_heat"] + terms["enc_heat_aux"])
