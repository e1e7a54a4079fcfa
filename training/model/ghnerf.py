"""GHNeRF on an ENeRF-style backbone, sized for the edge: assembly and the root config.

Pipeline (one scene = ``S`` source images, ``B`` target cameras)::

    images (S,3,H,W) RGB [0,1]
      -> encode: normalise; FeatureNet -> feat_s1/s2/s4; ResNet18 human encoder -> human_feat
      -> volumes: per cascade level, plane-sweep cost volume in each target frustum
         (level 0: planes uniform in 1/z over the subject box's near..far; level l>0: planes in
         mean +- k std of level l-1), 3D U-Net -> f_voxel volume + depth logits -> mean, std
      -> render(level, rays): samples in mean +- k std of the level; per sample: pixel-aligned
         source features + RGB (f_img), human features (f_h), f_voxel (tent-interpolated ray column);
         heads g_NeRF -> V; g_sigma, g_c (blend source colours), g_h (25 sigmoid heatmaps), [g_co];
         composite colour, heatmaps and depth with shared weights.
      -> query(points): the same heads at arbitrary rig points (volumetric heatmaps).

Targets may be source cameras (heatmaps in each source view) or novel cameras.
All camera matrices come from the host (``ghnerf_runtime.contract`` helpers).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from ghnerf_runtime.body25 import NUM_JOINTS
from ghnerf_runtime.contract import IMAGENET_MEAN, IMAGENET_STD, LevelSpec, ModelContract
from training.model.config import Config, ConfigError
from training.model.cost_volume import CostVolumeConfig, build_cost_volume
from training.model.features import FeatureNet, FeatureNetConfig
from training.model.heads import Heads, HeadsConfig, unit
from training.model.human_encoder import HumanEncoder, HumanEncoderConfig
from training.model.projection import MIN_DEPTH, grid_sample, planar_to_grid, project_planar, ray_directions, to_grid
from training.model.regularizer import Regularizer, RegularizerConfig
from training.model.rendering import render_rays
from training.model.sampling import (
    DEFAULT_MIN_RANGE, depth_distribution, interpolate_planes, inverse_depth_planes, linear_planes, plane_index,
    ray_depths, refine_interval,
)

FeatureName = Literal["feat_s1", "feat_s2", "feat_s4"]
FEATURE_STRIDES = {"feat_s1": 1, "feat_s2": 2, "feat_s4": 4}


@dataclass
class LevelConfig(Config):
    """One level of the coarse-to-fine cascade."""

    volume_stride: int = 8
    """Cost volume resolution is H / volume_stride (ENeRF: 8 coarse, 2 fine)."""
    planes: int = 32
    """Depth planes of the cost volume."""
    samples: int = 8
    """Samples per ray when this level is rendered (must equal ``planes`` with ``sampling="planes"``)."""
    sampling: Literal["interval", "planes"] = "interval"
    """``"interval"``: ``samples`` stratified samples in mean +- range_scale * std of this level's depth
    distribution, reading the volume by linear interpolation over planes (ENeRF). ``"planes"``: the ray
    samples are this level's planes themselves (which already span the previous level's interval), so
    the voxel features need no interpolation over depth and the level needs no depth head: the cheap
    choice for the last level on the edge."""
    feature: FeatureName = "feat_s4"
    """Encoder output the cost volume is built from."""
    range_scale: float = 1.0
    """The level's interval of interest is mean +- range_scale * std: rays are sampled in it and the next
    level's planes span it."""
    regularizer: RegularizerConfig = field(default_factory=RegularizerConfig)
    """3D network of this level."""


@dataclass
class ModelConfig(Config):
    """Root config of the model."""

    height: int = 128
    """Input (and contract) height, 64..256."""
    width: int = 128
    """Input (and contract) width, 64..256."""
    use_human_encoder: bool = True
    """False gives the "ENeRF + heatmap" baseline (g_h reads V_NeRF only)."""
    features: FeatureNetConfig = field(default_factory=FeatureNetConfig)
    human: HumanEncoderConfig = field(default_factory=HumanEncoderConfig)
    cost_volume: CostVolumeConfig = field(default_factory=CostVolumeConfig)
    levels: tuple[LevelConfig, ...] = field(default_factory=lambda: (
        LevelConfig(),
        LevelConfig(volume_stride=4, planes=8, samples=4, feature="feat_s2",
                    regularizer=RegularizerConfig(channels=8, stages=1)),
    ))
    """Cascade levels, coarse to fine; the last one is rendered at inference."""
    heads: HeadsConfig = field(default_factory=HeadsConfig)
    render_feature: FeatureName = "feat_s1"
    """Encoder output sampled per point for f_img (with the source RGB)."""
    human_sampling: Literal["ray", "sample"] = "ray"
    """Sample the human features once per ray at its expected depth ("ray", cheap) or at every sample."""
    heatmap_stride: int = 4
    """Recommended ray stride for heatmap rendering (H/stride x W/stride rays, upsampled on the host)."""
    min_depth_range: float = DEFAULT_MIN_RANGE
    """Floor of every depth interval (metres)."""
    background: float = 0.0
    """Colour behind the subject (the subject is rendered over black)."""
    model_version: str = "0.1.0"
    """Version stamped into the contract."""

    def validate(self) -> None:
        """Raise :class:`ConfigError` naming the field when the sizes do not fit together."""
        H, W = self.height, self.width
        if not (64 <= H <= 256 and 64 <= W <= 256):
            raise ConfigError(f"height/width: must be within 64..256, got {W}x{H}")
        if not self.levels:
            raise ConfigError("levels: at least one level is required")
        self._check_positive()  # before any ``%`` below: a 0 there is a ZeroDivisionError, not a named key
        chans = dict(zip(("feat_s1", "feat_s2", "feat_s4"), self.features.channels))
        for i, lv in enumerate(self.levels):
            m = lv.volume_stride * 2 ** lv.regularizer.stages
            if H % m or W % m:
                raise ConfigError(f"levels[{i}].volume_stride: {W}x{H} must be divisible by volume_stride * "
                                  f"2**regularizer.stages = {m}")
            if lv.planes % 2 ** lv.regularizer.stages or lv.planes < 2:
                raise ConfigError(f"levels[{i}].planes: {lv.planes} must be >= 2 and divisible by "
                                  f"2**regularizer.stages = {2 ** lv.regularizer.stages}")
            if chans[lv.feature] % self.cost_volume.groups:
                raise ConfigError(f"cost_volume.groups: {self.cost_volume.groups} must divide the "
                                  f"{chans[lv.feature]} channels of levels[{i}].feature {lv.feature}")
            if lv.samples < 1:
                raise ConfigError(f"levels[{i}].samples: must be >= 1")
            if lv.sampling == "planes" and (lv.samples != lv.planes or i == 0):
                raise ConfigError(f"levels[{i}].sampling: 'planes' needs samples == planes and a previous level "
                                  f"(got samples {lv.samples}, planes {lv.planes}, level {i})")
        if H % self.heatmap_stride or W % self.heatmap_stride:
            raise ConfigError(f"heatmap_stride: {self.heatmap_stride} must divide {W}x{H}")
        if self.use_human_encoder and (H % self.human.out_stride or W % self.human.out_stride):
            raise ConfigError(f"human.out_stride: {self.human.out_stride} must divide {W}x{H}")
        if self.use_human_encoder:
            s = self.human.input_scale
            if not (0 < s <= 1) or (H * s) % 16 or (W * s) % 16:
                raise ConfigError(f"human.input_scale: {s} must be in (0, 1] and give a trunk input divisible by "
                                  f"16 (got {W * s}x{H * s})")
        if self.heads.num_joints != NUM_JOINTS:
            raise ConfigError(f"heads.num_joints: BODY_25 has {NUM_JOINTS} joints, got {self.heads.num_joints}")

    def _check_positive(self) -> None:
        """Strides, group counts and stage counts the size checks divide by must be >= 1 (stages >= 0)."""
        ones = {"heatmap_stride": self.heatmap_stride, "cost_volume.groups": self.cost_volume.groups,
                "human.out_stride": self.human.out_stride}
        for i, lv in enumerate(self.levels):
            ones[f"levels[{i}].volume_stride"] = lv.volume_stride
        for key, v in ones.items():
            if v < 1:
                raise ConfigError(f"{key}: must be >= 1, got {v}")
        for i, lv in enumerate(self.levels):
            if lv.regularizer.stages < 0:
                raise ConfigError(f"levels[{i}].regularizer.stages: must be >= 0, got {lv.regularizer.stages}")


class GHNeRF(nn.Module):
    """The model. See the module docstring for the data flow; shapes in each method."""

    def __init__(self, config: ModelConfig, read_init: bool = True):
        """``read_init`` False builds the human encoder without reading ``human.init`` (the weights come from a
        checkpoint next); ``config`` still names it, so the checkpoints saved keep the run's model config."""
        super().__init__()
        config.validate()
        self.config = config
        self.H, self.W = config.height, config.width
        self.feature_net = FeatureNet(config.features)
        self.human = HumanEncoder(config.human, read_init) if config.use_human_encoder else None
        chans = self.feature_net.out_channels
        self.regularizers = nn.ModuleList(
            Regularizer(lv.regularizer, config.cost_volume.groups, with_logits=lv.sampling == "interval")
            for lv in config.levels
        )
        self.heads = nn.ModuleList(
            Heads(config.heads, chans[config.render_feature] + 3, lv.regularizer.channels,
                  self.human.out_channels if self.human is not None else None)
            for lv in config.levels
        )
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1), persistent=False)

    # ------------------------------------------------------------------ encode
    def encode(self, images: Tensor) -> dict[str, Tensor]:
        """``images`` ``(S, 3, H, W)`` RGB in [0, 1] -> images, feat_s1/s2/s4 [, human_feat [, encoder_heatmaps]]."""
        x = (images - self.mean) / self.std
        out = {"images": images, **self.feature_net(x)}
        if self.human is not None:
            out["human_feat"] = self.human(x)
            if self.human.heat_head is not None:
                out["encoder_heatmaps"] = self.human.heatmaps(out["human_feat"])
        return out

    def encode_human(self, images: Tensor) -> Tensor:
        """``images`` ``(S, 3, H, W)`` RGB in [0, 1] -> the human encoder's heatmaps alone (the ``human`` graph)."""
        if self.human is None or self.human.heat_head is None:
            raise RuntimeError("the model has no encoder heatmaps (no human encoder or no auxiliary head)")
        return self.human.heatmaps(self.human((images - self.mean) / self.std))

    # ----------------------------------------------------------------- volumes
    def volumes(self, enc: dict[str, Tensor], src_P: Tensor, tgt_K_inv: Tensor, tgt_c2w: Tensor,
                near_far: Tensor, upto: int | None = None) -> list[dict[str, Tensor]]:
        """Cost volumes of each level in each target frustum.

        Args:
            src_P: ``(S, 3, 4)``; tgt_K_inv: ``(B, 3, 3)``; tgt_c2w: ``(B, 3, 4)``; near_far: ``(B, 2)``.
            upto: build levels ``0..upto`` (default all).

        Returns:
            Per level: ``volume`` ``(B, Cv, D, h, w)``, ``stats`` ``(B, 4, h, w)`` (depth mean, std of the
            distribution that places this level's samples, and the plane span lo, hi), ``depths``
            ``(B, D, h, w)`` and, for ``"interval"`` levels, ``logits`` ``(B, D, h, w)``.
        """
        cfg = self.config
        B = tgt_K_inv.shape[0]
        near = near_far[:, 0].reshape(B, 1, 1, 1)
        far = near_far[:, 1].reshape(B, 1, 1, 1)
        out: list[dict[str, Tensor]] = []
        last = len(cfg.levels) - 1 if upto is None else upto
        for i, lv in enumerate(cfg.levels[: last + 1]):
            h, w = self.H // lv.volume_stride, self.W // lv.volume_stride
            if i == 0:
                depths = inverse_depth_planes(near_far, lv.planes, h, w)
                lo, hi = near.expand(B, 1, h, w), far.expand(B, 1, h, w)
            else:
                prev = F.interpolate(out[-1]["stats"][:, :2], size=(h, w), mode="bilinear", align_corners=False)
                lo, hi = refine_interval(prev[:, :1], prev[:, 1:2], near, far, cfg.levels[i - 1].range_scale,
                                         cfg.min_depth_range)
                depths = linear_planes(lo, hi, lv.planes)
            cost = build_cost_volume(enc[lv.feature], src_P, tgt_K_inv, tgt_c2w, depths, lv.volume_stride,
                                     self.H, self.W, cfg.cost_volume.groups)
            volume, logits = self.regularizers[i](cost)
            level = {"volume": volume, "depths": depths}
            if logits is not None:
                mean, std = depth_distribution(logits, depths)
                level["logits"] = logits
            else:  # "planes": the samples are the planes; keep the distribution that placed them
                mean, std = prev[:, :1], prev[:, 1:2]
            level["stats"] = torch.cat([mean, std, lo, hi], dim=1)
            out.append(level)
        return out

    @staticmethod
    def spacing(level: int) -> str:
        return "inverse" if level == 0 else "linear"

    # -------------------------------------------------------------- per point
    def _sample_views(self, maps: Tensor, grid: Tensor) -> list[Tensor]:
        """``maps`` ``(S, C, h, w)`` at ``grid`` ``(S, Q, M, 2)`` -> per view ``(1, C, Q, M)``."""
        return [grid_sample(maps[s:s + 1], grid[s:s + 1]) for s in range(maps.shape[0])]

    def _sample_images(self, enc: dict[str, Tensor], grid: Tensor) -> list[Tensor]:
        """Source features + RGB at ``grid`` ``(S, Q, M, 2)`` -> ``f_img`` per view ``(1, Ci, Q, M)``, RGB last."""
        feat = enc[self.config.render_feature]
        if feat.shape[-2:] == enc["images"].shape[-2:]:
            return self._sample_views(torch.cat([feat, enc["images"]], dim=1), grid)
        return [torch.cat([f, c], dim=1) for f, c in zip(self._sample_views(feat, grid),
                                                           self._sample_views(enc["images"], grid))]

    def _point_outputs(self, level: int, enc: dict[str, Tensor], points: Tensor, f_voxel: Tensor, src_P: Tensor,
                       *, heat: bool = True, human_points: Tensor | None = None,
                       colour: tuple[Tensor, Tensor] | None = None, coord: bool = False) -> dict[str, Tensor]:
        """Heads at planar ``points`` ``(3, B, N, M)`` with voxel features ``f_voxel`` ``(1, Cv, B*N, M)``.

        ``human_points`` ``(3, B, 1, M)``: sample the human features there once per ray instead of at every
        sample. ``colour`` is ``(src_centers (S, 3), d_target (B, 3, M) unit)`` to evaluate g_c.
        Returns sigma ``(B, N, M)`` [, heat ``(J, B, N, M)``, rgb ``(3, B, N, M)``, coord ``(3, B, N, M)``].
        """
        heads = self.heads[level]
        _, B, N, M = points.shape
        S = src_P.shape[0]
        flat = points.reshape(3, B * N * M)
        grid, visible = project_planar(src_P, flat, self.H, self.W)  # (S, 2, L), (S, 1, L)
        grid = planar_to_grid(grid, B * N)  # (S, B*N, M, 2)
        f_img = self._sample_images(enc, grid)  # per view (1, Ci, B*N, M)
        V = heads.nerf_feature(f_img, f_voxel)
        out = {"sigma": heads.density(V).reshape(B, N, M)}
        if heat:
            f_h = None
            if self.human is not None:
                if human_points is not None:
                    hgrid, _ = project_planar(src_P, human_points.reshape(3, B * M), self.H, self.W)
                    f_h = self._sample_views(enc["human_feat"], planar_to_grid(hgrid, B))  # (1, Ch, B, M)
                else:
                    f_h = self._sample_views(enc["human_feat"], grid)  # (1, Ch, B*N, M)
            out["heat"] = heads.heat(V, f_h, B).reshape(-1, B, N, M)
        if colour is not None:
            centers, d_target = colour
            d_t = d_target.transpose(0, 1).unsqueeze(0).unsqueeze(3)  # (1, 3, B, 1, M)
            d_source = [unit(flat - centers[s].reshape(3, 1), dim=0).reshape(1, 3, B, N, M) for s in range(S)]
            vis = [visible[s:s + 1].reshape(1, 1, B * N, M) for s in range(S)]
            out["rgb"] = heads.colour(V, f_img, d_t, d_source, vis).reshape(3, B, N, M)
        if coord:
            out["coord"] = heads.coord(V).reshape(3, B, N, M)
        return out

    @staticmethod
    def _volume_column(volume: Tensor, grid: Tensor) -> Tensor:
        """``volume`` ``(B, Cv, D, h, w)`` at ``grid`` ``(B, 1, M, 2)`` -> ``(B, Cv, D, M)`` (bilinear in x, y)."""
        B, Cv, D, h, w = volume.shape
        col = grid_sample(volume.reshape(B, Cv * D, h, w), grid, padding="border")  # (B, Cv*D, 1, M)
        return col.reshape(B, Cv, D, grid.shape[2])

    # ------------------------------------------------------------------ render
    def render(self, level: int, enc: dict[str, Tensor], volume: Tensor, stats: Tensor, src_P: Tensor,
               tgt_K_inv: Tensor, tgt_c2w: Tensor, ray_uv: Tensor, *, src_centers: Tensor | None = None,
               heat: bool = True, perturb: bool = False, coord: bool = False) -> dict[str, Tensor]:
        """Render rays ``ray_uv`` ``(B, M, 2)`` (model pixels) of each target at ``level``.

        Colour is rendered when ``src_centers`` ``(S, 3)`` is given, heatmaps when ``heat``.

        Returns:
            ``depth``, ``acc`` ``(B, M)``; ``weights``, ``z`` ``(B, N, M)``; ``heatmaps`` ``(B, M, J)``;
            ``rgb`` ``(B, M, 3)``; with ``coord``: ``coord`` and ``points`` ``(3, B, N, M)``.
        """
        lv = self.config.levels[level]
        B, M = ray_uv.shape[:2]
        uv = ray_uv.transpose(1, 2)  # (B, 2, M) planar
        grid = to_grid(uv, self.H, self.W, axis=1).transpose(1, 2).unsqueeze(1)  # (B, 1, M, 2)
        st = grid_sample(stats, grid, padding="border")[:, :, 0]  # (B, 4, M)
        mean, std, lo, hi = st[:, 0:1], st[:, 1:2], st[:, 2:3], st[:, 3:4]  # (B, 1, M)
        column = self._volume_column(volume, grid)  # (B, Cv, D, M)
        if lv.sampling == "planes":
            t = torch.linspace(0.0, 1.0, lv.planes, device=ray_uv.device, dtype=ray_uv.dtype).reshape(1, -1, 1)
            z = lo + (hi - lo) * t  # (B, D, M)
            f_voxel = column
        else:
            a, b = refine_interval(mean, std, lo, hi, lv.range_scale, self.config.min_depth_range)
            z = ray_depths(a, b, lv.samples, perturb)  # (B, N, M)
            f_voxel = interpolate_planes(column, plane_index(z, lo, hi, lv.planes, self.spacing(level)))
        N = z.shape[1]
        Cv = column.shape[1]
        f_voxel = f_voxel.transpose(0, 1).reshape(1, Cv, B * N, M)
        origin, direction = ray_directions(tgt_K_inv, tgt_c2w, uv)  # (B, 3, 1), (B, 3, M)
        points = (origin.unsqueeze(3) + z.unsqueeze(1) * direction.unsqueeze(2)).transpose(0, 1)  # (3, B, N, M)
        human_points = None
        if heat and self.human is not None and self.config.human_sampling == "ray":
            human_points = (origin + mean * direction).transpose(0, 1).unsqueeze(2)  # (3, B, 1, M)
        colour = None if src_centers is None else (src_centers, unit(direction, dim=1))
        pts = self._point_outputs(level, enc, points, f_voxel, src_P, heat=heat, human_points=human_points,
                                  colour=colour, coord=coord)
        r = render_rays(pts["sigma"], z, pts.get("rgb"), pts.get("heat"), self.config.background, dim=-2)
        out = {"depth": r["depth"], "acc": r["acc"], "weights": r["weights"], "z": z, "sigma": pts["sigma"]}
        for key in ("rgb", "heatmaps"):
            if key in r:
                out[key] = r[key].permute(1, 2, 0)  # (C, B, M) -> (B, M, C)
        if coord:
            out["coord"], out["points"] = pts["coord"], points
        return out

    # ------------------------------------------------------------------- query
    def query(self, enc: dict[str, Tensor], volume: Tensor, stats: Tensor, src_P: Tensor, tgt_P: Tensor,
              points: Tensor, level: int = -1) -> dict[str, Tensor]:
        """Heads at rig points ``(B, Np, 3)`` using the volume of target ``b`` (projection ``tgt_P[b]``).

        Returns ``joint_heat`` ``(B, Np, J)`` and ``density`` ``(B, Np)``. Points outside the volume's depth
        span get zero voxel features (their values are then less reliable).
        """
        level = level % len(self.config.levels)
        lv = self.config.levels[level]
        B, Np = points.shape[:2]
        pts = points.transpose(1, 2)  # (B, 3, Np)
        h = torch.matmul(tgt_P, torch.cat([pts, torch.ones_like(pts[:, :1])], dim=1))  # (B, 3, Np)
        z = h[:, 2:3]
        uv = h[:, :2] / torch.where(z > MIN_DEPTH, z, torch.ones_like(z))
        grid = to_grid(uv, self.H, self.W, axis=1).transpose(1, 2).unsqueeze(1)  # (B, 1, Np, 2)
        st = grid_sample(stats, grid, padding="border")[:, :, 0]  # (B, 4, Np)
        lo, hi = st[:, 2:3], st[:, 3:4]
        column = self._volume_column(volume, grid)  # (B, Cv, D, Np)
        f_voxel = interpolate_planes(column, plane_index(z, lo, hi, lv.planes, self.spacing(level)))  # (B,Cv,1,Np)
        f_voxel = f_voxel.transpose(0, 1).reshape(1, -1, B, Np)
        out = self._point_outputs(level, enc, pts.transpose(0, 1).unsqueeze(2), f_voxel, src_P)
        return {"joint_heat": out["heat"][:, :, 0].permute(1, 2, 0), "density": out["sigma"][:, 0]}

    # ----------------------------------------------------------------- training
    def forward(self, images: Tensor, src_P: Tensor, src_centers: Tensor, tgt_K_inv: Tensor, tgt_c2w: Tensor,
                near_far: Tensor, ray_uv: Tensor, perturb: bool = True, colour: bool = True,
                aux_images: Tensor | None = None) -> dict:
        """Training forward: render ``ray_uv`` ``(B, R, 2)`` at every level.

        Returns ``{"levels": [render outputs per level, coarse to fine], "volumes": [...]}`` and, with
        ``human.aux_heatmaps``, ``encoder_heatmaps`` ``(S, J, H / out_stride, W / out_stride)`` of the sources
        and, given ``aux_images`` ``(A, 3, H, W)`` (more views for that head only, in the same forward so
        DDP sees one graph), their ``aux_encoder_heatmaps``.
        """
        enc = self.encode(images)
        vols = self.volumes(enc, src_P, tgt_K_inv, tgt_c2w, near_far)
        coord = self.config.heads.coord_head
        levels = [
            self.render(i, enc, v["volume"], v["stats"], src_P, tgt_K_inv, tgt_c2w, ray_uv,
                        src_centers=src_centers if colour else None, perturb=perturb, coord=coord)
            for i, v in enumerate(vols)
        ]
        out = {"levels": levels, "volumes": vols}
        if "encoder_heatmaps" in enc:
            out["encoder_heatmaps"] = enc["encoder_heatmaps"]  # (S, J, h, w), sources only
            if aux_images is not None:
                out["aux_encoder_heatmaps"] = self.encode_human(aux_images)
        return out

    # -------------------------------------------------------------------- misc
    def parameter_counts(self) -> dict[str, int]:
        def n(m: nn.Module | None) -> int:
            return sum(p.numel() for p in m.parameters()) if m is not None else 0

        counts = {"feature_net": n(self.feature_net), "human_encoder": n(self.human),
                  "regularizers": n(self.regularizers), "heads": n(self.heads),
                  "heads_last_level": n(self.heads[-1])}
        counts["total"] = n(self)
        return counts

    def channels(self) -> dict[str, int]:
        c = dict(self.feature_net.out_channels)
        c["volume"] = self.config.levels[-1].regularizer.channels
        if self.human is not None:
            c["human_feat"] = self.human.out_channels
        return c

    def contract(self, opset: int = 17, frame_padding: str = "none") -> ModelContract:
        """The runtime contract of this model (``ghnerf_runtime.contract``). ``frame_padding``: what its training
        crops showed past a camera's frame (``ModelContract.frame_padding``; the weights do not say, the
        checkpoint's train config does: ``training.export.export.trained_frame_padding``)."""
        cfg = self.config
        strides = dict(FEATURE_STRIDES)
        if self.human is not None:
            strides["human_feat"] = cfg.human.out_stride
        levels = [LevelSpec(lv.volume_stride, lv.planes, lv.samples, self.spacing(i), lv.feature, lv.sampling)
                  for i, lv in enumerate(cfg.levels)]
        return ModelContract.build(
            height=cfg.height, width=cfg.width, variant="ghnerf" if self.human is not None else "baseline",
            levels=levels, channels=self.channels(), strides=strides, render_feature=cfg.render_feature,
            heatmap_stride=cfg.heatmap_stride, background=cfg.background, opset=opset,
            model_version=cfg.model_version,
            encoder_heatmaps=self.human is not None and self.human.heat_head is not None,
            human_graph=self.human is not None and self.human.heat_head is not None,
            frame_padding=frame_padding,
        )


ModelConfig._target = GHNeRF

__all__ = ["ModelConfig", "LevelConfig", "GHNeRF", "FEATURE_STRIDES"]
