"""The learnt painter of the unseen surfaces: its feature caches (``training.fill_features``) and its
network, trainer and score (``training.learnt_fill``)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from ghnerf_runtime.body25 import JOINT_INDEX  # noqa: E402
from training.blend_ceiling import blend_sources  # noqa: E402
from training.fill_features import (FIELDS, MASK_BIT, SEEN_BIT, TRUTH_BIT, cache_split, load_cache,  # noqa: E402
                                    relit_in)
from training.learnt_fill import (FillNet, FillNetConfig, FillTrainConfig, _parse_sets, flip_views,  # noqa: E402
                                  joint_maps, load_net, main, masked_mse, net_inputs, paint, paintings, repainted,
                                  score_rows, table, to_device, train_fill)


@pytest.fixture(scope="module")
def truth_cache(data64, tmp_path_factory):
    return cache_split(data64, "val", tmp_path_factory.mktemp("fill") / "val.npz", workers=1, log=lambda *_: None)


@pytest.fixture(scope="module")
def train_cache(data64, tmp_path_factory):
    return cache_split(data64, "train", tmp_path_factory.mktemp("fill") / "train.npz", limit=1, workers=1,
                       log=lambda *_: None)


@pytest.fixture(scope="module")
def model_cache(data64, tmp_path_factory):
    from training.configs import preset
    from training.model import GHNeRF

    model = GHNeRF(preset("tiny"))
    folder = tmp_path_factory.mktemp("fill_model")
    torch.save({"model": model.state_dict(), "model_config": model.config.to_dict()}, folder / "tiny.pt")
    return cache_split(data64, "val", folder / "val.npz", workers=1, model=folder / "tiny.pt", log=lambda *_: None)


def test_a_true_geometry_cache_holds_every_novel_view_with_the_blend_and_the_target(truth_cache, data64):
    from training.data.torch_dataset import MultiViewDataset

    a = load_cache(truth_cache)
    assert set(FIELDS) <= set(a)
    n = len(a["angle"])
    assert n >= 2 and all(len(a[k]) == n for k in FIELDS)
    assert (a["geometry"] == "truth").all() and (a["angle"] > 0).all()
    flags = a["flags"]
    mask = (flags & MASK_BIT) > 0
    assert np.array_equal(mask, (flags & TRUTH_BIT) > 0)  # the geometry's mask is the truth's
    assert not ((flags & SEEN_BIT) > 0)[~mask].any()
    assert np.array_equal(a["shown"], a["relit"])
    # the first view: its target is the dataset's image over black, its blend the two-camera blend
    scene = {k: v.numpy() for k, v in MultiViewDataset(data64, "val")[int(a["scene"][0])].items()}
    t = int(a["view"][0])
    assert not scene["tgt_is_source"][t]
    truth = scene["tgt_images"][t].transpose(1, 2, 0) * scene["tgt_masks"][t][..., None]
    assert np.abs(a["truth"][0] / 255.0 - truth).max() <= 0.5 / 255 + 1e-6
    blend, seen = blend_sources(scene, t, scene["tgt_depth"][t])
    assert np.array_equal((flags[0] & SEEN_BIT) > 0, seen & mask[0])
    assert np.abs(a["blend"][0] / 255.0 - np.clip(blend, 0, 1)).max() <= 0.5 / 255 + 1e-6
    # the relit fill repaints only what no source sees
    assert np.array_equal(a["relit"][0][seen & mask[0]], a["blend"][0][seen & mask[0]])
    normals = a["normals"][0].astype(float) / 127
    assert np.allclose(np.linalg.norm(normals[mask[0]], axis=-1), 1.0, atol=0.02)
    assert not normals[~mask[0]].any()
    j = a["joints"][0]
    assert set(np.unique(j[:, 2])) <= {0.0, 1.0}
    assert np.allclose(j[j[:, 2] > 0, :2], scene["tgt_joints_2d"][t][j[:, 2] > 0], atol=1e-3)


def test_a_depth_beyond_float16_is_cached_at_its_largest_as_on_the_device_not_inf(data64):
    """Review 51: the runtime's painter clips its float16 depth plane (a surface over 65 km from the median became
    inf, and the painter NaN); the training cache cast it unclipped, so the net could train on inf."""
    from ghnerf_runtime.novel_painter import F16_MAX
    from training.data.torch_dataset import MultiViewDataset
    from training.fill_features import view_features

    scene = {k: v.numpy() for k, v in MultiViewDataset(data64, "val")[0].items()}
    t = next(i for i in range(len(scene["tgt_masks"]))
             if not scene["tgt_is_source"][i] and scene["tgt_masks"][i].sum() > 1)
    depth = np.array(scene["tgt_depth"], np.float64)
    ys, xs = np.nonzero(scene["tgt_masks"][t])
    depth[t, ys[0], xs[0]] = 7e4  # a wild surface 70 km away
    scene["tgt_depth"] = depth
    f = view_features(scene, t, None, 30.0, relight=False)
    assert f["depth"].dtype == np.float16 and np.isfinite(f["depth"]).all()
    assert float(f["depth"][ys[0], xs[0]]) == F16_MAX
    assert np.abs(f["depth"][ys[1:], xs[1:]].astype(float)).max() < 10.0  # the rest keeps its depth about the median


def test_a_nan_depth_inside_the_subject_leaves_the_rest_of_the_cached_depth_plane_about_its_median(data64):
    """Review 52: the cache's median over the subject mask took a NaN depth in (NaN), so the whole subject's depth
    plane became 0; the median is over the finite depths now, as on the device (novel_painter.depth_about_median)."""
    from training.data.torch_dataset import MultiViewDataset
    from training.fill_features import view_features

    scene = {k: v.numpy() for k, v in MultiViewDataset(data64, "val")[0].items()}
    t = next(i for i in range(len(scene["tgt_masks"]))
             if not scene["tgt_is_source"][i] and scene["tgt_masks"][i].sum() > 3)
    depth = np.array(scene["tgt_depth"], np.float64)
    mask = np.asarray(scene["tgt_masks"][t], bool)
    ys, xs = np.nonzero(mask)
    depth[t, ys[0], xs[0]] = np.nan  # no depth known at one pixel of the subject
    scene["tgt_depth"] = depth
    f = view_features(scene, t, None, 30.0, relight=False)
    rest = mask.copy()
    rest[ys[0], xs[0]] = False
    expect = (depth[t][rest] - np.median(depth[t][rest])).astype(np.float16)
    assert float(f["depth"][ys[0], xs[0]]) == 0.0  # the NaN pixel: no depth, as off the subject
    np.testing.assert_array_equal(f["depth"][rest], expect)
    assert np.abs(expect.astype(float)).max() > 0  # a plane with depth in it, not all 0


def test_a_nan_depth_inside_the_subject_has_no_normal_and_its_cached_view_is_defined_without_a_warning(data64):
    """Review 52: a NaN depth made a NaN normal, cast to int8 (undefined, a numpy RuntimeWarning), turned its
    neighbours' normals to face the camera, made the blend NaN there (cast to uint8 too), and crashed the relit
    fill (a NaN bin cast to int). Its normal is now the zero vector ("no normal", as off the subject), its
    neighbours difference across it as across the silhouette, and no source colours it, as on the device."""
    import warnings

    from training.data.torch_dataset import MultiViewDataset
    from training.fill_features import view_features
    from training.unseen_fill import fit_lighting, seen_surface, surface_normals

    scene = {k: v.numpy() for k, v in MultiViewDataset(data64, "val")[0].items()}
    t = next(i for i in range(len(scene["tgt_masks"]))
             if not scene["tgt_is_source"][i] and scene["tgt_masks"][i].sum() > 30)
    mask = np.asarray(scene["tgt_masks"][t], bool)
    inner = np.zeros_like(mask)
    inner[1:-1, 1:-1] = mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:] & mask[1:-1, 1:-1]
    ys, xs = np.nonzero(inner[1:-1, 1:-1])
    y, x = ys[len(ys) // 2] + 1, xs[len(xs) // 2] + 1  # a pixel inside the subject, its four neighbours too
    depth = np.array(scene["tgt_depth"], np.float64)
    depth[t, y, x] = np.nan
    scene["tgt_depth"] = depth
    lighting = fit_lighting(seen_surface(scene))
    assert lighting is not None  # the relit fill runs, as the caches' default does
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        f = view_features(scene, t, lighting, 30.0)
    normals = f["normals"].astype(float) / 127
    assert not normals[y, x].any()  # no normal: the zero vector
    rest = mask.copy()
    rest[y, x] = False
    assert np.allclose(np.linalg.norm(normals[rest], axis=-1), 1.0, atol=0.02)  # the neighbours keep unit normals
    # every other normal is the one with that pixel off the subject: its neighbours difference on their own side
    # (they faced the camera, the stand-in for a pixel with no neighbour)
    c2w = np.asarray(scene["tgt_c2w"][t], np.float64)
    off = surface_normals(np.nan_to_num(depth[t]), rest, scene["tgt_K_inv"][t], c2w) @ c2w[:, :3]
    assert np.array_equal(f["normals"][rest], np.round(off[rest] * 127.0).astype(np.int8))
    assert f["blend"][y, x].tolist() == [0, 0, 0] and not f["flags"][y, x] & SEEN_BIT  # no source colours it
    assert float(f["depth"][y, x]) == 0.0


def test_a_model_geometry_cache_takes_the_mask_and_picture_from_the_model_and_the_target_from_the_truth(
        model_cache, truth_cache):
    m, t = load_cache(model_cache), load_cache(truth_cache)
    assert (m["geometry"] == "model").all()
    assert np.array_equal(m["truth"], t["truth"])
    assert np.array_equal(m["flags"] & TRUTH_BIT, t["flags"] & TRUTH_BIT)
    assert not np.array_equal(m["flags"] & MASK_BIT, t["flags"] & MASK_BIT)  # an untrained model's opacity
    rows = score_rows(m, m["shown"] / 255.0)
    assert {"blend", "shown", "fill:relit"} <= set(rows["novel, all"]) and "ceiling" not in rows["novel, all"]
    assert rows["novel, all"]["shown"] == pytest.approx(rows["novel, all"]["fill:learnt"])


def test_a_cache_without_the_light_fit_holds_the_same_painter_inputs_and_no_relit_fill(model_cache, data64,
                                                                                       tmp_path):
    """``cache --no-relit`` (make painter's caches) skips the light fit: every plane the runtime's painter
    reads is the same, ``relit`` is the picture, and a net that reads the relit fill refuses to train on it."""
    m = load_cache(model_cache)
    assert relit_in(m)  # the fixture's cache was made with the light fit
    lightless = load_cache(cache_split(data64, "val", tmp_path / "val.npz", workers=1,
                                       model=Path(model_cache).parent / "tiny.pt", relight=False,
                                       log=lambda *_: None))
    for k in FIELDS:
        if k not in ("relit", "light"):
            assert np.array_equal(lightless[k], m[k]), k
    assert np.array_equal(lightless["relit"], lightless["shown"]) and not lightless["light"].any()
    assert not relit_in(lightless)
    rows = score_rows(lightless, lightless["shown"] / 255.0)["novel, all"]
    assert "fill:relit" not in rows and "relit:unseen" not in rows and "shown" in rows
    with pytest.raises(ValueError, match="without the light fit.*relit_input=false"):
        train_fill(lightless, FillTrainConfig(steps=1, batch=2, device="cpu", net=FillNetConfig(width=8)))
    net = train_fill(lightless, FillTrainConfig(steps=1, batch=2, device="cpu", log_every=10 ** 6,
                                                net=FillNetConfig(width=8, relit_input=False, shown_input=True)),
                     log=lambda *_: None)
    assert net.steps_trained == 1


def test_a_proxy_cache_leaves_out_the_joints_the_runtime_leaves_out(model_cache, data64, tmp_path):
    """The runtime drops a joint whose expected error is past its gate (``joints3d.max_prior_error_m``)
    from the body proxy and the painter's joint maps: the caches the painter trains on must too."""
    from ghnerf_runtime.config import Joints3DConfig
    from training.data.torch_dataset import MultiViewDataset

    n = len(MultiViewDataset(data64, split="val"))
    truth = np.stack([MultiViewDataset(data64, split="val")[i]["joints_3d"].numpy() for i in range(n)])
    errors = np.full((n, 25), 0.01, np.float32)
    wrist = JOINT_INDEX["RWrist"]
    errors[:, wrist] = Joints3DConfig().max_prior_error_m + 0.05
    np.savez(tmp_path / "joints.npz", joints=truth.astype(np.float32), expected_error_m=errors,
             index=np.arange(n, dtype=np.int32))
    c = load_cache(cache_split(data64, "val", tmp_path / "val.npz", limit=1, workers=1, relight=False,
                               model=Path(model_cache).parent / "tiny.pt", joints=tmp_path / "joints.npz",
                               log=lambda *_: None))
    assert (c["geometry"] == "proxy").all()
    assert not c["joints"][:, wrist, 2].any()  # as the runtime's painter_planes gives it
    assert c["joints"][:, JOINT_INDEX["LWrist"], 2].any()


def test_the_around_term_teaches_the_painter_to_paint_the_fog_as_background(model_cache):
    """``around_weight``: the runtime's painter changes the proxy's pixels and those the model's picture
    shows (:func:`repainted`), the fog included; with the term the net learns the background there and
    the whole view as the runtime shows it (``paint(as_runtime=True)``) gets nearer the truth."""
    a = load_cache(model_cache)
    b = to_device(a, torch.device("cpu"))
    domain = repainted(b)[:, 0].numpy() > 0
    subject = (a["flags"] & TRUTH_BIT) > 0
    assert (domain & ~subject).sum() > 0.2 * subject.sum()  # an untrained model's picture: fog to learn
    rows = {}
    for weight in (0.0, 1.0):
        cfg = FillTrainConfig(steps=40, batch=4, lr=3e-3, device="cpu", log_every=10 ** 6, around_weight=weight,
                              net=FillNetConfig(width=8, relit_input=False, shown_input=True))
        net = train_fill(a, cfg, log=lambda *_: None)
        whole = paint(net, a, as_runtime=True)
        assert np.array_equal(whole[~domain], a["shown"][~domain] / 255.0)  # the picture where it does not paint
        rows[weight] = score_rows(a, paint(net, a), whole)["novel, all"]
    assert rows[1.0]["learnt:whole"] > rows[0.0]["learnt:whole"] + 1.0, rows
    assert rows[0.0]["shown:whole"] == rows[1.0]["shown:whole"]


def test_a_broken_cache_is_named_with_what_is_wrong(truth_cache, tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="bad.npz: not a fill-feature cache"):
        load_cache(bad)
    a = load_cache(truth_cache)
    np.savez(tmp_path / "short.npz", **{k: v for k, v in a.items() if k != "normals"})
    with pytest.raises(ValueError, match="lacks normals"):
        load_cache(tmp_path / "short.npz")
    np.savez(tmp_path / "ragged.npz", **{**a, "angle": a["angle"][:1]})
    with pytest.raises(ValueError, match="disagree"):
        load_cache(tmp_path / "ragged.npz")
    np.savez(tmp_path / "none.npz", **{k: v[:0] for k, v in a.items()})  # train failed in torch.randint
    with pytest.raises(ValueError, match="none.npz: fill-feature cache holds no views"):
        load_cache(tmp_path / "none.npz")


def test_the_net_starts_as_its_base_and_paints_only_the_subject(truth_cache):
    a = load_cache(truth_cache)
    net = FillNet(FillNetConfig(width=8))
    painted = paint(net, a)
    mask = (a["flags"] & TRUTH_BIT) > 0
    assert np.allclose(painted[mask], a["relit"][mask] / 255.0, atol=1e-6)
    assert not painted[~mask].any()
    shown_net = FillNet(FillNetConfig(width=8, shown_input=True))
    assert shown_net.stem[0].in_channels == net.stem[0].in_channels + 3
    assert np.allclose(paint(shown_net, a)[mask], a["shown"][mask] / 255.0, atol=1e-6)
    lightless = FillNet(FillNetConfig(width=8, relit_input=False))  # no relit fill, no light: from the blend
    assert lightless.stem[0].in_channels == net.stem[0].in_channels - 7
    assert np.allclose(paint(lightless, a)[mask], a["blend"][mask] / 255.0, atol=1e-6)
    x, base, _, _ = net_inputs(to_device(a, torch.device("cpu")), FillNetConfig(relit_input=False, shown_input=True))
    assert x.shape[1] == net.stem[0].in_channels - 4 and torch.equal(base, x[:, -3:])


def test_joint_maps_peak_at_valid_joints_and_vanish_for_invalid_ones():
    joints = torch.zeros(1, 25, 3)
    joints[0, 0] = torch.tensor([5.0, 7.0, 1.0])
    joints[0, 1] = torch.tensor([3.0, 3.0, 0.0])
    maps = joint_maps(joints, 16, 12, sigma=2.0)
    assert maps.shape == (1, 25, 16, 12)
    assert maps[0, 0, 7, 5] == pytest.approx(1.0) and maps[0, 0].argmax().item() == 7 * 12 + 5
    assert maps[0, 0, 7, 7] == pytest.approx(np.exp(-4 / 8))
    assert not maps[0, 1:].any()


def test_a_mirrored_batch_swaps_left_and_right_and_mirroring_twice_gives_it_back(truth_cache):
    b = to_device({k: v[:2] for k, v in load_cache(truth_cache).items()}, torch.device("cpu"))
    f = flip_views(b)
    W = b["flags"].shape[-1]
    assert torch.equal(f["blend"][:, :, 0], b["blend"][:, :, W - 1])
    r, l_ = JOINT_INDEX["RWrist"], JOINT_INDEX["LWrist"]
    if b["joints"][0, r, 2] > 0:
        assert f["joints"][0, l_, 0] == pytest.approx(W - 1 - b["joints"][0, r, 0].item())
        assert f["joints"][0, l_, 1] == b["joints"][0, r, 1]
    assert torch.equal(f["normals"][..., 0], -b["normals"].flip(2)[..., 0])
    assert f["light"][0, 0] == -b["light"][0, 0] and f["light"][0, 3] == b["light"][0, 3]
    back = flip_views(f)
    for k in b:
        assert torch.allclose(back[k].float(), b[k].float(), atol=1e-5), k


def _painting_net(seed: int) -> FillNet:
    torch.manual_seed(seed)
    net = FillNet(FillNetConfig(width=8, relit_input=False, shown_input=True))
    with torch.no_grad():
        for p in net.parameters():  # a net that paints something other than its base
            p.add_(0.05 * torch.randn_like(p))
    return net


def test_the_flip_test_paints_a_mirrored_view_as_the_mirror_of_the_view_and_an_ensemble_averages(truth_cache):
    a = {k: v[:3] for k, v in load_cache(truth_cache).items()}
    mirrored = {**a, **{k: v.numpy() for k, v in flip_views(to_device(a, torch.device("cpu"))).items()}}
    one, two = _painting_net(0), _painting_net(1)
    plain, plain_of_mirror = paint(one, a), paint(one, mirrored)
    assert not np.allclose(plain_of_mirror, plain[:, :, ::-1], atol=1e-3)  # the net alone is not symmetric
    tested = paintings(one, a, flip_test=True)[0]
    assert np.allclose(paintings(one, mirrored, flip_test=True)[0], tested[:, :, ::-1], atol=1e-5)
    assert np.allclose(tested, 0.5 * (plain + plain_of_mirror[:, :, ::-1]), atol=1e-5)
    both = paintings([one, two], a)
    assert np.allclose(both[0], 0.5 * (plain + paint(two, a)), atol=1e-6)
    assert both[1].shape == plain.shape


def test_masked_mse_averages_each_image_over_its_mask_then_over_the_batch():
    pred, truth = torch.zeros(2, 3, 2, 2), torch.zeros(2, 3, 2, 2)
    pred[0, :, 0, 0] = 0.3  # image 0: one masked pixel off by 0.3 in every channel
    pred[1, 0, 1, 1] = 0.6  # image 1: one channel of one masked pixel off by 0.6
    pred[1, :, 0, 0] = 9.0  # outside image 1's mask: ignored
    mask = torch.ones(2, 1, 2, 2)
    mask[1, :, 0, 0] = 0
    expected = (3 * 0.09 / 12 + 0.36 / 9) / 2
    assert masked_mse(pred, truth, mask).item() == pytest.approx(expected)


def test_training_fits_the_training_views_better_than_the_relit_fill(truth_cache):
    a = load_cache(truth_cache)
    cfg = FillTrainConfig(steps=60, batch=4, lr=3e-3, log_every=1000, device="cpu", net=FillNetConfig(width=8))
    net = train_fill(a, cfg, log=lambda *_: None)
    assert net.steps_trained == 60
    rows = score_rows(a, paint(net, a))["novel, all"]
    assert rows["fill:learnt"] > rows["fill:relit"] + 0.3
    x, base, truth, mask = net_inputs(to_device(a, torch.device("cpu")), net.cfg)
    assert x.shape[1] == net.stem[0].in_channels and base.shape == truth.shape


def test_a_time_budget_ends_training_early(truth_cache):
    """A million steps (hours here) under a 0.5 s budget: training stops once the budget is spent, not
    before (after a step or two, say) and not long after: within 10 s of the clock's start (the "fill net:
    ..." line; building the net before it takes a second on a first call). The limit is loose on purpose:
    a loaded CI machine must not fail it, and an ignored budget runs for hours. That case fails fast: the
    log, called every step, gives up at the limit instead of running on."""
    import time

    a = load_cache(truth_cache)
    budget = 0.5
    limit = 10.0
    cfg = FillTrainConfig(steps=10 ** 6, batch=2, max_seconds=budget, log_every=1, device="cpu",
                          net=FillNetConfig(width=8))
    lines, start = [], []

    def log(line):
        now = time.perf_counter()
        start[:] = start or [now]  # the first line is logged as the budget's clock starts
        lines.append(line)
        if now - start[0] > limit:
            raise AssertionError(f"still training {limit} s into a {budget} s budget: {line}")

    called = time.perf_counter()
    steps = train_fill(a, cfg, log=log).steps_trained
    ended = time.perf_counter()
    assert lines[0].startswith("fill net: ") and lines[-1].startswith(f"  {steps} steps in "), (lines[0], lines[-1])
    # the budget's clock starts just before the first line; a pause between them must not fail the test
    assert ended - called >= budget and ended - start[0] <= limit, (ended - called, ended - start[0], steps)
    assert ended - called <= limit + 5.0  # the net's construction included
    assert 1 <= steps < 10 ** 6 and sum(" step " in ln for ln in lines) == steps


def test_the_cli_trains_saves_and_scores_the_same_table(train_cache, truth_cache, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--train-cache", str(train_cache), "--val-cache", str(truth_cache), "--out", str(out),
                 "--device", "cpu", "--set", "steps=3", "--set", "batch=2", "--set", "net.width=8"]) == 0
    report = (out / "score.md").read_text()
    assert "3 steps of 2" in report and "| novel, all |" in report
    capsys.readouterr()
    assert main(["score", "--val-cache", str(truth_cache), "--net", str(out / "fill_net.pt"), "--device", "cpu"]) == 0
    assert capsys.readouterr().out.strip() in report
    net = str(out / "fill_net.pt")  # an ensemble of one net twice is that net; the flip test scores too
    assert main(["score", "--val-cache", str(truth_cache), "--net", net, "--net", net, "--device", "cpu"]) == 0
    assert capsys.readouterr().out.strip() in report
    assert main(["score", "--val-cache", str(truth_cache), "--net", net, "--flip-test", "--device", "cpu"]) == 0
    assert "| novel, all |" in capsys.readouterr().out
    (tmp_path / "broken.pt").write_bytes(b"x")
    with pytest.raises(ValueError, match="broken.pt: not a fill-net checkpoint"):
        load_net(tmp_path / "broken.pt")


def test_overrides_reach_the_net_and_unknown_keys_are_refused():
    cfg = _parse_sets(FillTrainConfig(), ["steps=7", "net.width=16", "flip=false", "net.shown_input=true"])
    assert (cfg.steps, cfg.net.width, cfg.flip, cfg.net.shown_input) == (7, 16, False, True)
    with pytest.raises(ValueError, match="stepz"):
        _parse_sets(FillTrainConfig(), ["stepz=1"])
    with pytest.raises(ValueError, match="net.depth"):
        _parse_sets(FillTrainConfig(), ["net.depth=3"])


def test_a_cut_or_empty_cache_is_named_and_a_stopped_write_keeps_the_previous_cache(truth_cache, data64, tmp_path,
                                                                                     monkeypatch):
    whole = truth_cache.read_bytes()
    for name, data in (("cut.npz", whole[: len(whole) // 2]), ("empty.npz", b"")):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(ValueError, match=f"{name}: not a fill-feature cache, or a damaged one"):
            load_cache(tmp_path / name)
    # a stop (Ctrl-C, a kill) while savez writes the second array: the cache made before stays whole and readable
    out = tmp_path / "val.npz"
    out.write_bytes(whole)
    import numpy.lib.format as fmt

    real, calls = fmt.write_array, []

    def stopped(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(fmt, "write_array", stopped)
    with pytest.raises(KeyboardInterrupt):
        cache_split(data64, "val", out, limit=1, workers=1, relight=False, log=lambda *_: None)
    monkeypatch.setattr(fmt, "write_array", real)
    assert len(calls) == 2 and out.read_bytes() == whole
    assert sorted(load_cache(out)) == sorted(FIELDS) and [p.name for p in tmp_path.iterdir() if "val" in p.name] == \
        ["val.npz"]  # no temporary left beside it


# ------------------------------------------------------------------ what the caches record, and the CLI's refusals
def test_a_cache_records_its_split_dataset_geometry_and_model(truth_cache, model_cache, data64):
    from training.fill_features import cache_source
    from training.model_card import sha256

    assert cache_source(truth_cache) == {"split": "val", "dataset_sha256": sha256(data64 / "dataset.json"),
                                         "geometry": "truth", "model_sha256": "", "relight": True}
    made = cache_source(model_cache)
    assert made["geometry"] == "model" and made["model_sha256"] == sha256(Path(model_cache).parent / "tiny.pt")
    assert "source" not in load_cache(truth_cache)  # the per-view arrays only: they are sliced by view


def _train(train, val, out):
    return main(["train", "--train-cache", str(train), "--val-cache", str(val), "--out", str(out), "--device", "cpu",
                 "--set", "steps=1", "--set", "batch=2", "--set", "net.width=8"])


def test_train_refuses_caches_that_do_not_hold_out_the_training_views(train_cache, truth_cache, model_cache,
                                                                      tmp_path, capsys):
    """The same cache twice, swapped caches, two of one split, or caches of another geometry: the held-out table
    was printed from them without a word."""
    same_split = tmp_path / "val_again.npz"
    same_split.write_bytes(Path(truth_cache).read_bytes())
    cases = (
        (truth_cache, truth_cache, "are the same file"),
        (truth_cache, train_cache, "holds the training split 'train'"),  # swapped
        (truth_cache, same_split, "both hold split 'val'"),
        (train_cache, model_cache, "differ in geometry ('truth' vs 'model')"),
    )
    for train, val, words in cases:
        assert _train(train, val, tmp_path / "run") == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and words in err and err.count("\n") == 1, err
        assert not (tmp_path / "run" / "fill_net.pt").exists()  # refused before the training


def test_train_views_beyond_the_cache_are_refused_before_the_training(train_cache, truth_cache, tmp_path, capsys):
    """``--train-views N`` (painter_gpu.sh's VIEWS) past the cache's views trained on all of them, and the run was
    reported as N views' worth."""
    from training.fill_features import load_cache

    held = len(load_cache(train_cache)["flags"])
    argv = ["train", "--train-cache", str(train_cache), "--val-cache", str(truth_cache), "--out",
            str(tmp_path / "run"), "--device", "cpu", "--set", "steps=1", "--set", "batch=2", "--set", "net.width=8"]
    assert main([*argv, "--train-views", str(held + 1)]) == 2
    assert f"--train-views {held + 1}: {train_cache} holds {held} training views" in capsys.readouterr().err
    assert not (tmp_path / "run" / "fill_net.pt").exists()
    assert main([*argv, "--train-views", str(held)]) == 0  # all of them, asked for by number


def test_train_refuses_a_cache_without_the_relit_fill_the_net_reads(train_cache, data64, tmp_path, capsys):
    lightless = cache_split(data64, "val", tmp_path / "val.npz", limit=1, workers=1, relight=False,
                            log=lambda *_: None)
    assert _train(train_cache, lightless, tmp_path / "run") == 2  # the net read its picture as the relit fill
    assert f"--val-cache {lightless}: made without the light fit" in capsys.readouterr().err


def test_a_truth_value_override_is_one_of_its_words_or_refused():
    # any other word was False without a word: --set flip=on trained without the mirrored batches
    sets = ["flip=No", "net.shown_input=YES", "net.relit_input=0", "around_weight=0"]
    cfg = _parse_sets(FillTrainConfig(), sets)
    assert (cfg.flip, cfg.net.shown_input, cfg.net.relit_input) == (False, True, False)
    for word in ("on", "ture", ""):
        with pytest.raises(ValueError, match=f"--set flip={word}: flip takes true or false .*, got '{word}'"):
            _parse_sets(FillTrainConfig(), [f"flip={word}"])


def test_a_seed_torch_cannot_take_is_refused_before_the_caches_load(tmp_path, capsys):
    """--set seed=2**64 was torch's 'Overflow when unpacking long long' traceback after the caches loaded; the
    bound is training.run_limits' (the trainers'), so a negative seed is refused too."""
    from training.run_limits import MAX_SEED

    assert _parse_sets(FillTrainConfig(), [f"seed={MAX_SEED}"]).seed == MAX_SEED
    for seed in (2 ** 64, MAX_SEED + 1, -1):
        with pytest.raises(ValueError, match=rf"--set seed: must be an integer in \[0, {MAX_SEED}\], got {seed}$"):
            _parse_sets(FillTrainConfig(), [f"seed={seed}"])
    with pytest.raises(SystemExit) as e:  # no cache read: these do not exist
        main(["train", "--train-cache", str(tmp_path / "t.npz"), "--val-cache", str(tmp_path / "v.npz"), "--out",
              str(tmp_path / "run"), "--set", f"seed={2 ** 64}"])
    assert e.value.code == 2 and f"--set seed: must be an integer in [0, {MAX_SEED}], got {2 ** 64}" in \
        capsys.readouterr().err


def test_bad_training_values_are_usage_errors(train_cache, truth_cache, tmp_path, capsys):
    for sets, words in ((["batch=0"], "batch: must be at least 1, got 0"), (["lr=0"], "lr: must be a positive number"),
                        (["log_every=0"], "log_every: must be at least 1"), (["net.width=12"], "multiple of 8"),
                        (["steps=many"], "steps takes a int, got 'many'")):
        with pytest.raises(ValueError, match=words):
            _parse_sets(FillTrainConfig(), sets)
    with pytest.raises(SystemExit) as e:  # was a traceback from _parse_sets (or ZeroDivisionError mid-run)
        main(["train", "--train-cache", str(train_cache), "--val-cache", str(truth_cache), "--out",
              str(tmp_path / "run"), "--set", "log_every=0"])
    assert e.value.code == 2 and "--set log_every: must be at least 1, got 0" in capsys.readouterr().err
    for argv, words in ((["--workers", "0"], "--workers: must be at least 1, got 0"),
                        (["--limit", "-1"], "--limit: must be at least 0, got -1"),
                        (["--joints", "j.npz"], "--joints: takes --model too")):
        with pytest.raises(SystemExit) as e:
            main(["cache", "--data", "d", "--out", str(tmp_path / "c.npz"), *argv])
        assert e.value.code == 2 and words in capsys.readouterr().err


def test_the_cache_command_names_a_bad_joints_cache_in_one_line(model_cache, data64, tmp_path, capsys):
    """A JointsCacheError escaped ``cache`` as a traceback (and a short cache failed in a worker)."""
    from training.data.torch_dataset import MultiViewDataset

    n = len(MultiViewDataset(data64, split="val"))
    joints = np.zeros((n - 1, 25, 3), np.float32)  # one scene short
    (tmp_path / "short.npz").write_bytes(b"")
    np.savez(tmp_path / "short.npz", joints=joints, expected_error_m=np.zeros((n - 1, 25), np.float32))
    np.savez(tmp_path / "other.npz", joints=joints, split=np.str_("train"))
    np.savez(tmp_path / "nojoints.npz", index=np.arange(n))
    (tmp_path / "cut.npz").write_bytes(b"PK\x03\x04")
    ckpt = str(Path(model_cache).parent / "tiny.pt")
    for name, words in (("short.npz", f"holds {n - 1} scenes, {n} asked for"), ("other.npz", "split 'train'"),
                        ("nojoints.npz", "not a joints cache"), ("cut.npz", "not a joints cache"),
                        ("missing.npz", "not a joints cache")):
        out = tmp_path / "c.npz"
        assert main(["cache", "--data", str(data64), "--split", "val", "--workers", "1", "--model", ckpt,
                     "--joints", str(tmp_path / name), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err == f"error: {tmp_path / name}: " + err.split(": ", 2)[2] and words in err and not out.exists(), err
    assert main(["cache", "--data", str(tmp_path / "nodata"), "--split", "val", "--out", str(tmp_path / "c.npz")]) == 2
    assert "nodata" in capsys.readouterr().err


def test_a_checkpoint_the_workers_cannot_load_is_named_not_a_hang(data64, tmp_path):
    """With --workers 2 the checkpoint was first loaded in the pool's initializer, which respawned the failing
    workers for ever."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    try:
        r = subprocess.run([sys.executable, "-m", "training.learnt_fill", "cache", "--data", str(data64), "--split",
                            "val", "--workers", "2", "--model", str(tmp_path / "missing.pt"), "--out",
                            str(tmp_path / "c.npz")], capture_output=True, text=True, timeout=120, env=env)
    except subprocess.TimeoutExpired:
        pytest.fail("cache --workers 2 with an unreadable checkpoint hung")
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith(f"error: {tmp_path / 'missing.pt'}: unreadable checkpoint"), r.stderr


def test_the_train_commands_score_json_is_strict_json(train_cache, truth_cache, tmp_path, monkeypatch):
    # Review 51: a held-out bin without views scores NaN; json.dumps wrote score.json with a bare NaN (not JSON)
    import training.learnt_fill as lf

    def with_an_empty_bin(*args, **kw):
        return {"novel, all": {"n": 3, "shown": 19.0, "fill:learnt": 20.0},
                "novel, 150-180": {"n": 0, "shown": float("nan"), "fill:learnt": float("-inf")}}

    monkeypatch.setattr(lf, "score_rows", with_an_empty_bin)
    out = tmp_path / "run"
    assert main(["train", "--train-cache", str(train_cache), "--val-cache", str(truth_cache), "--out", str(out),
                 "--device", "cpu", "--set", "steps=1", "--set", "batch=2", "--set", "net.width=8"]) == 0

    def refuse(word):
        raise ValueError(f"not JSON: {word}")

    score = json.loads((out / "score.json").read_text(), parse_constant=refuse)
    assert score["rows"]["novel, 150-180"] == {"n": 0, "shown": None, "fill:learnt": None}
    assert score["steps"] == 1 and score["config"]["net"]["width"] == 8


@pytest.mark.parametrize("name", ["fill_net.pt", "score.md", "score.json"])
def test_a_write_cut_short_leaves_the_previous_file_not_half_of_one(name, train_cache, truth_cache, tmp_path,
                                                                      disk_full_at, monkeypatch):
    """train wrote fill_net.pt, score.md and score.json in place: a full disk or a crash left half a file under
    its name, which export reads next (a cut checkpoint, a score.json that is not JSON)."""
    out = tmp_path / "run"
    assert _train(train_cache, truth_cache, out) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(before) == {"fill_net.pt", "score.md", "score.json"}
    disk_full_at(out, name)
    with pytest.raises(OSError, match="No space left"):
        _train(train_cache, truth_cache, out)
    monkeypatch.undo()
    after = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(after) == set(before)  # no temporary file left beside them
    assert after[name] == before[name]  # the files written before the cut one are the new run's, whole
    load_net(out / "fill_net.pt")
    json.loads((out / "score.json").read_text())


def _poisoned_mse(monkeypatch, from_call: int, grad_only: bool = False) -> None:
    """``masked_mse`` whose value (or, ``grad_only``, only its gradient) turns NaN from its ``from_call``-th call."""
    import training.learnt_fill as lf

    real, calls = lf.masked_mse, []

    def mse(pred, truth, mask):
        calls.append(1)
        value = real(pred, truth, mask)
        if len(calls) < from_call:
            return value
        if grad_only:  # sqrt's slope at 0 is inf, times 0 is NaN: a finite loss with a NaN gradient
            return value + 0.0 * torch.sqrt(pred.float() * 0.0).sum()
        return value * float("nan")

    monkeypatch.setattr(lf, "masked_mse", mse)


@pytest.mark.parametrize("grad_only, says", [(False, "step 2: non-finite loss"),
                                             (True, "step 2: non-finite gradient of a finite loss")])
def test_a_non_finite_step_stops_the_training_before_the_update(truth_cache, monkeypatch, grad_only, says):
    """AdamW used to apply the NaN to every weight and train on: the painter painted NaN, the table dropped those
    views and the CLI saved the NaN weights, exit 0."""
    _poisoned_mse(monkeypatch, from_call=2, grad_only=grad_only)  # around_weight 0: one call per step
    cfg = FillTrainConfig(steps=4, batch=2, log_every=10 ** 6, device="cpu", net=FillNetConfig(width=8))
    with pytest.raises(FloatingPointError, match=says):
        train_fill(load_cache(truth_cache), cfg, log=lambda *_: None)


def test_the_cli_names_a_diverged_training_and_saves_no_net(train_cache, truth_cache, tmp_path, monkeypatch, capsys):
    _poisoned_mse(monkeypatch, from_call=1)
    out = tmp_path / "run"
    assert _train(train_cache, truth_cache, out) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == "error: training diverged: step 1: non-finite loss (nan); the weights were not updated"
    assert not (out / "fill_net.pt").exists() and not (out / "score.md").exists()


def _scored_views(angles):
    """A true-geometry cache of ``len(angles)`` 8x8 views (the subject a 4x4 block, its left half seen) at the
    given angles from the nearest source, and the painter's pictures as noisy copies of the truth."""
    rng = np.random.default_rng(5)
    n = len(angles)
    flags = np.zeros((n, 8, 8), np.uint8)
    flags[:, 2:6, 2:6] = TRUTH_BIT | MASK_BIT
    flags[:, 2:6, 2:4] |= SEEN_BIT
    truth = rng.integers(0, 256, (n, 8, 8, 3)).astype(np.uint8) * (flags[..., None] > 0)
    arrays = {"truth": truth, "flags": flags, "geometry": np.full(n, "truth"), "angle": np.asarray(angles, np.float32),
              "blend": rng.integers(0, 256, (n, 8, 8, 3)).astype(np.uint8),
              "relit": rng.integers(0, 256, (n, 8, 8, 3)).astype(np.uint8), "light": np.ones((n, 4), np.float32)}
    learnt = np.clip(truth / 255.0 + rng.normal(0.0, 0.05, truth.shape), 0, 1) * (flags[..., None] > 0)
    return arrays, learnt


def _view_psnr(arrays, learnt, views):
    from ghnerf_runtime.metrics import masked_psnr

    mask = (arrays["flags"][views] & TRUTH_BIT) > 0
    return masked_psnr(learnt[views], arrays["truth"][views] / 255.0, mask).per_image


def test_the_painters_table_caps_an_identical_view_and_counts_a_non_finite_one_as_ghnerf_eval_does():
    """An identical view made the mean +inf (ghnerf-eval counts it as 100 dB); a NaN painting vanished from the
    means as if its mask were empty and an infinite pixel was clipped and scored (ghnerf-eval leaves both out
    and counts them, a pixel off the subject too)."""
    from ghnerf_runtime.metrics import PSNR_CAP_DB

    arrays, learnt = _scored_views([5.0, 45.0, 20.0, 120.0, 100.0])
    learnt[0] = arrays["truth"][0] / 255.0  # identical: +inf dB
    learnt[1, 3, 3, 0] = np.nan  # on the subject
    learnt[3, 0, 0, 1] = np.inf  # off the subject: still a broken render
    rows = score_rows(arrays, learnt)
    scored = [PSNR_CAP_DB, *_view_psnr(arrays, learnt, [2, 4])]
    assert rows["novel 0-15 deg"]["fill:learnt"] == PSNR_CAP_DB
    assert rows["novel, all"]["fill:learnt"] == pytest.approx(np.mean(scored))
    assert (rows["novel, all"]["n"], rows["novel, all"]["nonfinite"]) == (5, 2)
    assert [rows[k]["nonfinite"] for k in ("novel 0-15 deg", "novel 15-30 deg", "novel 30-60 deg",
                                           "novel 90-180 deg")] == [0, 0, 1, 1]
    assert "novel 30-60 deg" in rows and np.isnan(rows["novel 30-60 deg"]["fill:learnt"])  # its only view broken
    assert np.isfinite(rows["novel 30-60 deg"]["ceiling"])  # the cache's own pictures are still scored
    assert "| views | n | nonfinite |" in table(rows)
    assert "nonfinite" not in table(score_rows(arrays, _scored_views([5.0] * 5)[1]))  # a sound run reads as before


def test_the_painters_angle_bins_are_ghnerf_evals_and_hold_a_view_at_180_degrees():
    """A novel view straight behind a source camera (180 degrees) was in no bin of the table (only in "novel,
    all"), where ghnerf-eval's last bin holds it."""
    from training.evaluate import psnr_by_angle

    angles = [0.0, 14.9, 15.0, 89.9, 90.0, 180.0, 180.0]
    arrays, learnt = _scored_views(angles)
    rows = score_rows(arrays, learnt)
    ours = [rows[k]["n"] if k in rows else 0 for k in ("novel 0-15 deg", "novel 15-30 deg", "novel 30-60 deg",
                                                        "novel 60-90 deg", "novel 90-180 deg")]
    assert ours == [b["views"] for b in psnr_by_angle([20.0] * len(angles), angles)] == [2, 1, 0, 1, 3]
    assert sum(ours) == rows["novel, all"]["n"]
