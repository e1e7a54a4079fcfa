"""The torch-free model contract: build, metadata round trip, validation errors that name the key,
session I/O checks, and the host-side camera inputs."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_NAMES
from ghnerf_runtime.contract import (
    CONTRACT_VERSION, GRAPH_NAMES, ContractError, LevelSpec, ModelContract, near_far_from_box, ray_grid,
    source_centers, source_projections, target_inputs, target_projections,
)
from ghnerf_runtime.geometry import Camera, intrinsics_from_fov, look_at

CHANNELS = {"feat_s1": 8, "feat_s2": 16, "feat_s4": 32, "human_feat": 16, "volume": 8}
STRIDES = {"feat_s1": 1, "feat_s2": 2, "feat_s4": 4, "human_feat": 4}
LEVELS = (LevelSpec(8, 16, 8, "inverse", "feat_s4"), LevelSpec(4, 4, 4, "linear", "feat_s2", "planes"))


def make(variant: str = "ghnerf", **kw) -> ModelContract:
    channels = dict(CHANNELS)
    strides = dict(STRIDES)
    if variant == "baseline":
        channels.pop("human_feat")
        strides.pop("human_feat")
    return ModelContract.build(height=128, width=128, variant=variant, levels=LEVELS, channels=channels,
                               strides=strides, **kw)


def test_graphs_and_shapes():
    c = make()
    assert tuple(g.name for g in c.graphs) == tuple(g for g in GRAPH_NAMES if g != "human")
    enc = c.graph("encoder")
    assert enc.input_names == ("images",)
    assert enc.tensor("images").shape == (2, 3, 128, 128)
    assert enc.tensor("human_feat").shape == (2, 16, 32, 32)
    vol = c.graph("volume")
    assert vol.tensor("volume").shape == ("B", 8, 4, 32, 32)
    assert vol.tensor("depth_stats").shape == ("B", 4, 32, 32)
    assert "tgt_K_inv" in vol.input_names and "near_far" in vol.input_names
    assert c.graph("render_heat").tensor("heatmaps").shape == ("B", "R", 25)
    assert "human_feat" not in c.graph("render_rgb").input_names
    assert c.graph("query").tensor("joint_heat").shape == ("B", "N", 25)


def test_human_graph_is_the_encoder_heatmaps_alone():
    c = make(encoder_heatmaps=True, human_graph=True)
    assert c.graph_names == GRAPH_NAMES
    human = c.graph("human")
    assert human.input_names == ("images",) and human.output_names == ("encoder_heatmaps",)
    assert human.tensor("encoder_heatmaps").shape == c.graph("encoder").tensor("encoder_heatmaps").shape
    back = ModelContract.from_metadata(c.to_metadata(graph="human"))
    assert back.human_graph and back.same_model(c)
    # 1.1.0 files carry no human_graph key: read as without the graph
    old = {k: v for k, v in make(encoder_heatmaps=True).to_metadata().items() if k != "ghnerf.human_graph"}
    assert not ModelContract.from_metadata(old).human_graph
    with pytest.raises(ContractError, match="human_graph"):
        make(human_graph=True)  # no encoder heatmaps to output


def test_baseline_has_no_human_features():
    c = make("baseline")
    assert not c.has_human
    for g in c.graphs:
        assert "human_feat" not in g.input_names + g.output_names


def test_metadata_round_trip():
    c = make()
    meta = c.to_metadata(graph="volume", precision="int8")
    assert all(isinstance(k, str) and isinstance(v, str) for k, v in meta.items())
    back = ModelContract.from_metadata(meta)
    assert back.same_model(c)
    assert back.to_metadata() == c.to_metadata()
    assert ModelContract.graph_of(meta) == "volume"
    assert meta["ghnerf.precision"] == "int8"
    assert json.loads(meta["ghnerf.joint_names"]) == list(JOINT_NAMES)
    assert meta["ghnerf.resolution"] == "128x128"


@pytest.mark.parametrize("key, value", [
    ("ghnerf.resolution", "128by128"),
    ("ghnerf.levels", "not json"),
    ("ghnerf.channels", "[1, 2]"),
    ("ghnerf.heatmap_stride", "x"),
    ("ghnerf.num_sources", "3"),
    ("ghnerf.joint_names", json.dumps(list(reversed(JOINT_NAMES)))),
    ("ghnerf.variant", "dino"),
    ("ghnerf.contract_version", "9.0.0"),
    ("ghnerf.graphs", json.dumps([{"name": "encoder", "inputs": [], "outputs": []}])),
    # once a ZeroDivisionError out of the session load, or accepted and failing in the estimator
    ("ghnerf.strides", json.dumps({**STRIDES, "human_feat": 0})),
    ("ghnerf.strides", json.dumps({**STRIDES, "feat_s4": 3})),
    ("ghnerf.channels", json.dumps({**CHANNELS, "volume": -3})),
    ("ghnerf.normalisation", json.dumps({**make().normalisation.to_json(), "value_range": [0.5]})),
    ("ghnerf.normalisation", json.dumps({**make().normalisation.to_json(), "value_range": [1.0, 1.0]})),
    ("ghnerf.normalisation", json.dumps({**make().normalisation.to_json(), "mean": [0.5, "nan", 0.5]})),
    ("ghnerf.background", "nan"),
    ("ghnerf.frame_padding", "grey"),  # a fill the training never shows: not taken for "none"
    ("ghnerf.frame_padding", ""),
])
def test_bad_metadata_names_the_key(key, value):
    meta = make().to_metadata()
    meta[key] = value
    with pytest.raises(ContractError) as err:
        ModelContract.from_metadata(meta)
    assert err.value.key == key
    assert key in str(err.value)


def test_frame_padding_round_trips_and_reads_as_none_where_a_file_has_none():
    """``ghnerf.frame_padding`` (contract 1.3.0): what the training crops showed past the frame, for the runtime's
    default ``roi.pad_fill``. A file exported before it (the shipped model's) has no key: its crops never
    reached past the frame ("none"), so it keeps the runtime's fade."""
    black = make(frame_padding="black")
    meta = black.to_metadata(graph="encoder")
    assert meta["ghnerf.frame_padding"] == "black" and make().to_metadata()["ghnerf.frame_padding"] == "none"
    assert ModelContract.from_metadata(meta).frame_padding == "black"
    assert not ModelContract.from_metadata(meta).same_model(make())  # graphs of two trainings are not mixed
    del meta["ghnerf.frame_padding"]
    old = ModelContract.from_metadata(meta)
    assert old.frame_padding == "none" and old.same_model(make())
    with pytest.raises(ContractError) as err:
        make(frame_padding="edge")
    assert err.value.key == "ghnerf.frame_padding" and "'edge'" in str(err.value)


def test_missing_key_is_named():
    meta = make().to_metadata()
    del meta["ghnerf.normalisation"]
    with pytest.raises(ContractError, match="ghnerf.normalisation"):
        ModelContract.from_metadata(meta)
    with pytest.raises(ContractError, match="ghnerf.graph"):
        ModelContract.graph_of(meta)


def test_build_validation():
    with pytest.raises(ContractError, match="resolution"):
        ModelContract.build(height=512, width=512, variant="ghnerf", levels=LEVELS, channels=CHANNELS,
                            strides=STRIDES)
    with pytest.raises(ContractError, match="heatmap_stride"):
        make(heatmap_stride=3)
    assert make().version == CONTRACT_VERSION


def test_check_io():
    c = make()
    spec = c.graph("render_heat")
    inputs = {t.name: [d if isinstance(d, int) else None for d in t.shape] for t in spec.inputs}
    outputs = {t.name: list(t.shape) for t in spec.outputs}
    c.check_io("render_heat", inputs, outputs)
    bad = dict(inputs, volume=[None, 8, 8, 32, 32])
    with pytest.raises(ContractError) as err:
        c.check_io("render_heat", bad, outputs)
    assert err.value.key == "volume"
    with pytest.raises(ContractError, match="lacks input 'ray_uv'"):
        c.check_io("render_heat", {k: v for k, v in inputs.items() if k != "ray_uv"}, outputs)
    with pytest.raises(ContractError, match="unexpected"):
        c.check_io("render_heat", dict(inputs, extra=[1]), outputs)
    # an input the contract fixes but the file leaves symbolic: exported for other shapes -> refused
    fixed = next(t for t in spec.inputs if any(isinstance(d, int) for d in t.shape))
    loose = [None if isinstance(d, int) else d for d in inputs[fixed.name]]
    with pytest.raises(ContractError) as err:
        c.check_io("render_heat", dict(inputs, **{fixed.name: loose}), outputs)
    assert err.value.key == fixed.name
    # outputs may stay symbolic where the exporter's shape inference gave names
    c.check_io("render_heat", inputs, {k: ["n"] * len(v) for k, v in outputs.items()})


def _camera(x: float, size: int = 128) -> Camera:
    R, t = look_at((x, -1.2, 0.0), (0.0, -0.95, 3.0))
    return Camera(f"c{x}", size, size, intrinsics_from_fov(size, size, 45.0), R=R, t=t)


def test_camera_inputs_agree_with_camera_projection():
    cams = [_camera(-0.4), _camera(0.4)]
    P = source_projections(cams, 128, 128)
    X = np.array([[0.1, -1.0, 3.1], [-0.3, -0.2, 2.8]])
    for cam, Pc in zip(cams, P):
        h = np.c_[X, np.ones(2)] @ Pc.T.astype(np.float64)
        uv, _ = cam.project(X)
        np.testing.assert_allclose(h[:, :2] / h[:, 2:], uv, atol=1e-3)
    centres = source_centers(cams)
    np.testing.assert_allclose(centres[0], cams[0].center, atol=1e-6)
    tin = target_inputs(cams, 128, 128)
    # a pixel's ray through K_inv and c2w passes through the projected point
    uv, z = cams[0].project(X[0])
    d = tin["tgt_c2w"][0][:, :3] @ (tin["tgt_K_inv"][0] @ np.r_[uv, 1.0])
    np.testing.assert_allclose(tin["tgt_c2w"][0][:, 3] + z * d, X[0], atol=1e-4)
    np.testing.assert_allclose(target_projections(cams, 128, 128), P)
    with pytest.raises(ContractError, match="resize"):
        source_projections([_camera(0.0, size=64)], 128, 128)


def test_near_far_and_ray_grid():
    cam = _camera(0.0)
    box = np.array([[-0.5, -1.9, 2.6], [0.5, 0.0, 3.4]])
    idx = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])
    corners = np.where(idx == 1, box[1], box[0])
    near, far = near_far_from_box(cam, corners, margin=0.0)
    z = cam.to_camera(corners)[:, 2]
    assert near == pytest.approx(z.min(), abs=1e-5) and far == pytest.approx(z.max(), abs=1e-5)
    near2, far2 = near_far_from_box(cam, corners, margin=0.1)
    assert near2 < near and far2 > far
    uv = ray_grid(8, 8, 4)
    np.testing.assert_allclose(uv, [[1.5, 1.5], [5.5, 1.5], [1.5, 5.5], [5.5, 5.5]])
    assert ray_grid(128, 128, 1).shape == (128 * 128, 2)
    with pytest.raises(ContractError, match="stride"):
        ray_grid(128, 128, 3)


def test_near_far_of_a_box_across_behind_or_not_finite():
    """A box reaching behind the camera clamps near to the near plane; one wholly behind it, or NaN, has no
    range (it was [0.05, 0.051] and [nan, nan], which look like real ones to the graphs)."""
    from ghnerf_runtime.errors import GeometryError

    cam = Camera("c", 128, 128, intrinsics_from_fov(128, 128, 45.0))  # at the origin, looking along +z
    idx = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])

    def corners(lo, hi):
        return np.where(idx == 1, np.asarray(hi, float), np.asarray(lo, float))

    near, far = near_far_from_box(cam, corners([-0.5, -0.5, -1.0], [0.5, 0.5, 2.0]), margin=0.0)
    assert near == pytest.approx(0.05) and far == pytest.approx(2.0)
    with pytest.raises(GeometryError, match="behind"):
        near_far_from_box(cam, corners([-0.5, -0.5, -3.0], [0.5, 0.5, -1.0]), margin=0.1)
    with pytest.raises(GeometryError, match="behind"):  # in front of the camera, not of the near plane
        near_far_from_box(cam, corners([-0.5, -0.5, -0.5], [0.5, 0.5, 0.04]), margin=0.0)
    bad = corners([-0.5, -0.5, 1.0], [0.5, 0.5, 2.0])
    bad[3, 1] = np.nan
    with pytest.raises(GeometryError, match="finite"):
        near_far_from_box(cam, bad)
    with pytest.raises(GeometryError, match="finite"):
        near_far_from_box(cam, corners([-0.5, -0.5, 1.0], [0.5, 0.5, 2.0]), margin=float("inf"))
