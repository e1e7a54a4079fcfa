"""The assembled model on the tiny preset: shapes, variants, consistency between render and query."""
from __future__ import annotations

from dataclasses import replace

import pytest

torch = pytest.importorskip("torch")

from ghnerf_runtime.contract import ray_grid  # noqa: E402
from training.configs import PRESETS, preset  # noqa: E402
from training.model import GHNeRF, ModelConfig  # noqa: E402
from training.model.camera_inputs import (  # noqa: E402
    box_corners, orbit_camera, scene_inputs, synthetic_rig, to_torch,
)
from training.model.config import ConfigError  # noqa: E402


def inputs(cfg, stride=4, novel=True):
    H, W = cfg.height, cfg.width
    src = synthetic_rig(H, W)
    tgt = src + ([orbit_camera(H, W, 30.0)] if novel else [])
    cam = to_torch(scene_inputs(src, tgt, box_corners(), H, W))
    uv = torch.from_numpy(ray_grid(H, W, stride)).unsqueeze(0).expand(len(tgt), -1, -1).contiguous()
    images = torch.rand(2, 3, H, W, generator=torch.Generator().manual_seed(0))
    return images, cam, uv


@pytest.fixture(scope="module")
def tiny():
    torch.manual_seed(0)
    return GHNeRF(preset("tiny")).eval()


def test_presets_build_and_validate():
    for name in PRESETS:
        preset(name).validate()
    base = preset("edge128_baseline")
    assert not base.use_human_encoder and preset("edge128").use_human_encoder


def test_forward_shapes_and_ranges(tiny):
    images, cam, uv = inputs(tiny.config)
    out = tiny(images, cam["src_P"], cam["src_centers"], cam["tgt_K_inv"], cam["tgt_c2w"], cam["near_far"], uv,
               perturb=True)
    assert len(out["levels"]) == len(tiny.config.levels)
    B, R = uv.shape[:2]
    for lv_cfg, lv in zip(tiny.config.levels, out["levels"]):
        assert lv["rgb"].shape == (B, R, 3)
        assert lv["heatmaps"].shape == (B, R, 25)
        assert lv["depth"].shape == lv["acc"].shape == (B, R)
        assert lv["z"].shape == (B, lv_cfg.samples, R)
        assert torch.all((lv["heatmaps"] >= 0) & (lv["heatmaps"] <= 1))
        assert torch.all((lv["rgb"] >= 0) & (lv["rgb"] <= 1 + 1e-5))
        nf = cam["near_far"]
        assert torch.all(lv["z"] >= nf[:, :1, None] - 1e-4) and torch.all(lv["z"] <= nf[:, 1:, None] + 1e-4)
    vol = out["volumes"][-1]
    last = tiny.config.levels[-1]
    assert vol["volume"].shape == (B, last.regularizer.channels, last.planes, 64 // last.volume_stride,
                                   64 // last.volume_stride)


def test_baseline_variant_has_no_human_encoder():
    cfg = replace(preset("tiny"), use_human_encoder=False)
    m = GHNeRF(cfg).eval()
    assert m.human is None and m.parameter_counts()["human_encoder"] == 0
    assert m.contract().variant == "baseline"
    images, cam, uv = inputs(cfg, novel=False)
    with torch.no_grad():
        out = m(images, cam["src_P"], cam["src_centers"], cam["tgt_K_inv"], cam["tgt_c2w"], cam["near_far"], uv)
    assert out["levels"][-1]["heatmaps"].shape == (2, uv.shape[1], 25)


def test_query_reproduces_render_samples():
    """query() at the render's sample points gives the render's per-sample densities (planes level)."""
    cfg = replace(preset("tiny"), human_sampling="sample")
    torch.manual_seed(1)
    m = GHNeRF(cfg).eval()
    images, cam, uv = inputs(cfg)
    with torch.no_grad():
        enc = m.encode(images)
        vol = m.volumes(enc, cam["src_P"], cam["tgt_K_inv"], cam["tgt_c2w"], cam["near_far"])[-1]
        r = m.render(len(cfg.levels) - 1, enc, vol["volume"], vol["stats"], cam["src_P"], cam["tgt_K_inv"],
                     cam["tgt_c2w"], uv, coord=False)
        # rebuild the sample points: origin + z * direction
        from training.model.projection import ray_directions
        o, d = ray_directions(cam["tgt_K_inv"], cam["tgt_c2w"], uv.transpose(1, 2))
        pts = o.unsqueeze(3) + r["z"].unsqueeze(1) * d.unsqueeze(2)  # (B, 3, N, M)
        B, _, N, M = pts.shape
        q = m.query(enc, vol["volume"], vol["stats"], cam["src_P"], cam["tgt_P"],
                    pts.permute(0, 2, 3, 1).reshape(B, N * M, 3))
    torch.testing.assert_close(q["density"].reshape(B, N, M), r["sigma"], rtol=1e-3, atol=1e-4)


def test_colour_and_heat_toggles(tiny):
    images, cam, uv = inputs(tiny.config)
    with torch.no_grad():
        enc = tiny.encode(images)
        vol = tiny.volumes(enc, cam["src_P"], cam["tgt_K_inv"], cam["tgt_c2w"], cam["near_far"])[-1]
        args = (len(tiny.config.levels) - 1, enc, vol["volume"], vol["stats"], cam["src_P"], cam["tgt_K_inv"],
                cam["tgt_c2w"], uv)
        heat_only = tiny.render(*args)
        rgb_only = tiny.render(*args, src_centers=cam["src_centers"], heat=False)
        both = tiny.render(*args, src_centers=cam["src_centers"])
    assert "rgb" not in heat_only and "heatmaps" not in rgb_only
    torch.testing.assert_close(heat_only["heatmaps"], both["heatmaps"])
    torch.testing.assert_close(rgb_only["rgb"], both["rgb"])


def test_config_errors_name_the_field():
    with pytest.raises(ConfigError, match="levels\\[0\\].bogus"):
        ModelConfig.from_dict({"levels": [{"bogus": 1}]})
    with pytest.raises(ConfigError, match="heads.feature_dim"):
        ModelConfig.from_dict({"heads": {"feature_dim": "wide"}})
    with pytest.raises(ConfigError, match="levels\\[0\\].sampling"):
        ModelConfig.from_dict({"levels": [{"sampling": "random"}]})
    cfg = ModelConfig.from_dict({"height": 96, "width": 96, "levels": [{"volume_stride": 8, "planes": 8}]})
    assert cfg.levels[0].planes == 8 and cfg.height == 96
    with pytest.raises(ConfigError, match="height/width"):
        replace(preset("tiny"), height=300).validate()
    with pytest.raises(ConfigError, match="levels\\[1\\].sampling"):
        bad = preset("tiny")
        bad.levels = (bad.levels[0], replace(bad.levels[1], samples=3))
        bad.validate()


@pytest.mark.parametrize("size", [96, 256])
def test_other_resolutions(size):
    cfg = replace(preset("tiny"), height=size, width=size)
    m = GHNeRF(cfg).eval()
    images, cam, uv = inputs(cfg, stride=16, novel=False)
    with torch.no_grad():
        out = m(images, cam["src_P"], cam["src_centers"], cam["tgt_K_inv"], cam["tgt_c2w"], cam["near_far"], uv)
    assert out["levels"][-1]["heatmaps"].shape == (2, (size // 16) ** 2, 25)
    assert m.contract().graph("encoder").tensor("images").shape == (2, 3, size, size)
