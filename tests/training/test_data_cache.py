"""The shard cache on hand-made samples (no rendering): round trip, and errors that name the file."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ghnerf_runtime.preprocess import Roi
from training.data.cache import MANIFEST, ShardedSplit, new_manifest, write_manifest, write_shard
from training.data.errors import DataError, DatasetError
from training.data.sample import FIELDS, Sample, ViewData, arrays_to_sample, field_shape, sample_to_arrays

S, V = 16, 3
NAMES = ("src0", "src1", "novel0")


def _sample(seed: int) -> Sample:
    rng = np.random.default_rng(seed)
    views = []
    for name in NAMES:
        mask = rng.uniform(size=(S, S)) < 0.3
        depth = np.where(mask, rng.uniform(1, 5, (S, S)), 0).astype(np.float16)
        views.append(ViewData(
            name=name, image=rng.integers(0, 256, (S, S, 3), dtype=np.uint8), mask=mask, depth=depth, has_depth=True,
            joints_2d=rng.uniform(0, S, (25, 2)).astype(np.float32), visible=rng.uniform(size=25) < 0.8,
            K=np.array([[20.0, 0, 7.5], [0, 20.0, 7.5], [0, 0, 1]]), R=np.eye(3), t=rng.normal(size=3),
            roi=Roi(int(rng.integers(-5, 50)), 3, 100), roi_from_volume=bool(seed % 2),
            full_K=np.eye(3), full_size=(640, 480)))
    return Sample(tuple(views), rng.normal(size=(25, 3)), np.ones(25, bool), np.array([[-1.0, -2, 2], [1, 0, 4]]),
                  {"seed": seed})


def _dataset(root: Path, count: int = 5, shard_size: int = 2) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    manifest = new_manifest(resolution=S, view_names=NAMES, source="test", source_config={})
    samples = [_sample(i) for i in range(count)]
    for k, i0 in enumerate(range(0, count, shard_size)):
        write_shard(root / "train" / f"shard_{k:06d}", samples[i0:i0 + shard_size], i0)
    manifest["splits"]["train"] = {"count": count, "shard_size": shard_size}
    write_manifest(root, manifest)
    return root


def test_record_round_trip():
    s = _sample(3)
    rec = sample_to_arrays(s)
    for name, (_, dtype) in FIELDS.items():
        assert rec[name].shape == field_shape(name, V, S) and rec[name].dtype == dtype
    back = arrays_to_sample(rec, NAMES, s.metadata)
    for a, b in zip(s.views, back.views):
        for attr in ("image", "mask", "depth", "joints_2d", "visible", "K", "R", "t"):
            assert np.array_equal(getattr(a, attr), getattr(b, attr)), attr
        assert a.roi == b.roi and a.full_size == b.full_size and a.roi_from_volume == b.roi_from_volume
    assert np.array_equal(s.joints_3d, back.joints_3d) and back.metadata == {"seed": 3}


def test_shards_read_back_in_order(tmp_path):
    data = ShardedSplit(_dataset(tmp_path / "ds"), "train", max_open_shards=1)
    assert len(data) == 5
    for i in (4, 0, 3, 1, 2, -1):
        expect = sample_to_arrays(_sample(i % 5))
        got = data.arrays(i)
        assert all(np.array_equal(got[k], expect[k]) for k in FIELDS)
        assert data.metadata(i) == {"seed": i % 5}
    with pytest.raises(IndexError):
        data.arrays(5)


def test_bad_sample_shape_is_refused():
    s = _sample(0)
    bad = Sample(s.views, s.joints_3d[:24], s.joints_3d_valid, s.bbox)
    with pytest.raises(DataError, match="joints_3d"):
        sample_to_arrays(bad)


# ------------------------------------------------------------------ bad dataset folders name the file
def test_missing_manifest_names_it(tmp_path):
    with pytest.raises(DatasetError, match=MANIFEST) as err:
        ShardedSplit(tmp_path, "train")
    assert err.value.path == str(tmp_path / MANIFEST)


def test_corrupt_manifest_names_it(tmp_path):
    (tmp_path / MANIFEST).write_text("{not json")
    with pytest.raises(DatasetError, match="unreadable manifest") as err:
        ShardedSplit(tmp_path, "train")
    assert err.value.path.endswith(MANIFEST)


def test_unknown_split_names_the_manifest(tmp_path):
    root = _dataset(tmp_path / "ds")
    with pytest.raises(DatasetError, match="no split 'val'") as err:
        ShardedSplit(root, "val")
    assert err.value.path.endswith(MANIFEST)


def test_missing_shard_names_its_metadata_file(tmp_path):
    root = _dataset(tmp_path / "ds")
    meta = root / "train" / "shard_000001" / "meta.json"
    meta.unlink()
    with pytest.raises(DatasetError, match="missing") as err:
        ShardedSplit(root, "train")
    assert err.value.path == str(meta)


def test_wrong_array_shape_names_the_array_file(tmp_path):
    root = _dataset(tmp_path / "ds")
    path = root / "train" / "shard_000002" / "depth.npy"
    np.save(path, np.zeros((1, V, S, S + 1), np.float16))
    data = ShardedSplit(root, "train")
    data.arrays(0)  # other shards are fine
    with pytest.raises(DatasetError, match="expected") as err:
        data.arrays(4)
    assert err.value.path == str(path)


def test_truncated_array_names_the_array_file(tmp_path):
    root = _dataset(tmp_path / "ds")
    path = root / "train" / "shard_000000" / "images.npy"
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(DatasetError) as err:
        ShardedSplit(root, "train").arrays(0)
    assert err.value.path == str(path)


def test_schema_version_mismatch_names_the_manifest(tmp_path):
    root = _dataset(tmp_path / "ds")
    manifest = json.loads((root / MANIFEST).read_text())
    manifest["schema_version"] = 99
    (root / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="schema_version") as err:
        ShardedSplit(root, "train")
    assert err.value.path.endswith(MANIFEST)


@pytest.mark.parametrize("edit, match", [
    (lambda m: m["splits"]["train"].pop("count"), "splits.train.count must be an int"),
    (lambda m: m["splits"]["train"].update(shard_size=0), "splits.train.shard_size must be an int >= 1"),
    (lambda m: m["splits"]["train"].update(count="5"), "splits.train.count must be an int"),
    (lambda m: m["splits"].update(train=[5, 2]), "splits.train must be a mapping"),
    (lambda m: m.update(splits=[]), "splits must be a mapping"),
    (lambda m: m.update(resolution="16"), "resolution must be a positive int"),
    (lambda m: m.update(view_names="src0"), "view_names must be a list"),
])
def test_malformed_manifest_fields_name_the_manifest(tmp_path, edit, match):
    root = _dataset(tmp_path / "ds")
    manifest = json.loads((root / MANIFEST).read_text())
    edit(manifest)
    (root / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match=match) as err:
        ShardedSplit(root, "train")
    assert err.value.path == str(root / MANIFEST)


def test_shard_metadata_that_is_not_an_object_names_the_file(tmp_path):
    from training.data.cache import shard_is_complete

    root = _dataset(tmp_path / "ds")
    meta = root / "train" / "shard_000001" / "meta.json"
    meta.write_text("[1, 2]")
    assert not shard_is_complete(meta.parent, 2, 2)  # generate renders it again
    with pytest.raises(DatasetError, match="JSON object") as err:
        ShardedSplit(root, "train")
    assert err.value.path == str(meta)
    meta.write_text(json.dumps({"first_index": 2, "count": 2, "samples": 7}))
    with pytest.raises(DatasetError, match="JSON object") as err:
        ShardedSplit(root, "train")
    assert err.value.path == str(meta)


def test_only_the_last_shard_may_hold_more_than_its_split_reads(tmp_path):
    # a split shrunk by a smaller generate keeps its longer last shard: its first samples are read, no more
    root = _dataset(tmp_path / "ds", count=5, shard_size=2)
    manifest = json.loads((root / MANIFEST).read_text())
    manifest["splits"]["train"]["count"] = 3
    (root / MANIFEST).write_text(json.dumps(manifest))
    data = ShardedSplit(root, "train")
    assert len(data) == 3 and [m["seed"] for m in data.all_metadata()] == [0, 1, 2]
    assert np.array_equal(data.arrays(2)["images"], sample_to_arrays(_sample(2))["images"])
    # a shard holding fewer than its samples, or more than the shard size, is still refused, naming it
    for count, shard_size, expected in ((6, 2, r"4 x 1, expected 4 x 2"), (3, 1, r"0 x 2, expected 0 x 1")):
        manifest["splits"]["train"].update(count=count, shard_size=shard_size)
        (root / MANIFEST).write_text(json.dumps(manifest))
        with pytest.raises(DatasetError, match=rf"shard holds samples from {expected}") as err:
            ShardedSplit(root, "train")
        assert err.value.path.endswith("meta.json")
