"""Named presets (nerfstudio's ``method_configs`` pattern): plain trees of config dataclasses.

* ``tiny``: 64x64, minimal widths; for tests (two CPU iterations, export round trips).
* ``edge128``: the shipped model, 128x128 on a 2-core CPU through onnxruntime (int8 where it pays).
* ``edge128_baseline``: ``edge128`` without the human encoder ("ENeRF + heatmap").

Each call returns a fresh config; nothing is global. Importing this module does not import torch (the
model's modules load when a preset is built): the command lines list the presets in ``--help`` without it.
"""
from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from training.model.ghnerf import ModelConfig


def tiny() -> ModelConfig:
    # the model's modules import torch: loaded here, so the tools' --help (preset choices) runs without it
    from training.model.cost_volume import CostVolumeConfig  # noqa: PLC0415
    from training.model.features import FeatureNetConfig  # noqa: PLC0415
    from training.model.ghnerf import LevelConfig, ModelConfig  # noqa: PLC0415
    from training.model.heads import HeadsConfig  # noqa: PLC0415
    from training.model.human_encoder import HumanEncoderConfig  # noqa: PLC0415
    from training.model.regularizer import RegularizerConfig  # noqa: PLC0415

    return ModelConfig(
        height=64, width=64,
        features=FeatureNetConfig(channels=(4, 8, 8)),
        human=HumanEncoderConfig(num_layers=2, out_channels=8, out_stride=4, aux_heatmaps=True),
        cost_volume=CostVolumeConfig(groups=4),
        levels=(
            LevelConfig(volume_stride=8, planes=8, samples=4, feature="feat_s4",
                        regularizer=RegularizerConfig(channels=4, stages=1)),
            LevelConfig(volume_stride=4, planes=4, samples=4, sampling="planes", feature="feat_s2",
                        regularizer=RegularizerConfig(channels=4, stages=1)),
        ),
        heads=HeadsConfig(feature_dim=16, nerf_hidden=16, colour_hidden=8, heat_hidden=16, coord_head=True),
        heatmap_stride=4,
    )


def edge128() -> ModelConfig:
    from training.model.cost_volume import CostVolumeConfig  # noqa: PLC0415
    from training.model.features import FeatureNetConfig  # noqa: PLC0415
    from training.model.ghnerf import LevelConfig, ModelConfig  # noqa: PLC0415
    from training.model.heads import HeadsConfig  # noqa: PLC0415
    from training.model.human_encoder import HumanEncoderConfig  # noqa: PLC0415
    from training.model.regularizer import RegularizerConfig  # noqa: PLC0415

    return ModelConfig(
        height=128, width=128,
        features=FeatureNetConfig(channels=(8, 16, 16), full_res_convs=1, full_res_smooth=False, norm="scene"),
        human=HumanEncoderConfig(num_layers=3, out_channels=32, out_stride=4, input_scale=0.5, aux_heatmaps=True),
        cost_volume=CostVolumeConfig(groups=8),
        levels=(
            LevelConfig(volume_stride=8, planes=16, samples=8, feature="feat_s4", range_scale=1.5,
                        regularizer=RegularizerConfig(channels=8, stages=1, head_kernel=1)),
            LevelConfig(volume_stride=4, planes=4, samples=4, sampling="planes", feature="feat_s2",
                        regularizer=RegularizerConfig(channels=8, stages=1)),
        ),
        heads=HeadsConfig(feature_dim=32, nerf_hidden=32, colour_hidden=16, heat_hidden=32),
        heatmap_stride=4,
    )


def edge128_baseline() -> ModelConfig:
    return replace(edge128(), use_human_encoder=False)


PRESETS: dict[str, Callable[[], ModelConfig]] = {
    "tiny": tiny,
    "edge128": edge128,
    "edge128_baseline": edge128_baseline,
}


def preset(name: str) -> ModelConfig:
    """A fresh config of the preset ``name``."""
    if name not in PRESETS:
        raise KeyError(f"unknown preset {name!r}; presets: {sorted(PRESETS)}")
    return PRESETS[name]()


__all__ = ["PRESETS", "preset", "tiny", "edge128", "edge128_baseline"]
