"""The shard cache on hand-made samples (no rendering): round trip, and errors that name the file."""
from __future__ import annotations

import json
import os
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


def test_reads_keep_the_files_of_max_open_shards_open_and_match_without_preadv(tmp_path, monkeypatch):
    """The shards are read through open files (no maps): the LRU bound closes the files of the shards it drops,
    and a platform without ``os.preadv`` reads the same bytes (as arrays the caller may write to)."""
    if not Path("/proc/self/fd").is_dir():
        pytest.skip("counts the open files in /proc/self/fd")
    root = _dataset(tmp_path / "ds")  # 3 shards

    def open_files() -> int:
        return sum(str(root) in os.path.realpath(fd) for fd in Path("/proc/self/fd").iterdir())

    data = ShardedSplit(root, "train", max_open_shards=1)
    for i in range(len(data)):  # every shard in turn
        data.arrays(i)
    assert open_files() == len(FIELDS)  # the last shard's files alone
    del data
    assert open_files() == 0
    monkeypatch.delattr("os.preadv")
    data = ShardedSplit(root, "train", max_open_shards=0)  # (0: the shard being read stays open all the same)
    for i in (4, 0, 3):
        got, expect = data.arrays(i), sample_to_arrays(_sample(i))
        assert all(np.array_equal(got[k], expect[k]) and got[k].flags.writeable for k in FIELDS)
    assert open_files() == len(FIELDS)


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
    # found when the split opens (headers only), not when a DataLoader worker first reads the shard
    root = _dataset(tmp_path / "ds")
    path = root / "train" / "shard_000002" / "depth.npy"
    np.save(path, np.zeros((1, V, S, S + 1), np.float16))
    with pytest.raises(DatasetError, match="expected") as err:
        ShardedSplit(root, "train")
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


# ------------------------------------------------------------------ damage found at open, writes that fail
@pytest.mark.parametrize("cut", [0, 100, -1])
def test_a_cut_array_of_any_shard_is_named_when_the_split_opens(tmp_path, cut):
    # a shard cut by a power cut (or a bad copy) used to open fine and fail only when a sample of it was read:
    # inside a DataLoader worker, an hour into training; -1: one byte short, header whole
    root = _dataset(tmp_path / "ds")
    path = root / "train" / "shard_000002" / "images.npy"
    data = path.read_bytes()
    path.write_bytes(data[:cut] if cut >= 0 else data[:-1])
    with pytest.raises(DatasetError, match="unreadable array|cut short") as err:
        ShardedSplit(root, "train")
    assert err.value.path == str(path)


def test_a_missing_array_file_is_named_when_the_split_opens(tmp_path):
    root = _dataset(tmp_path / "ds")
    path = root / "train" / "shard_000001" / "K.npy"
    path.unlink()
    with pytest.raises(DatasetError, match="missing") as err:
        ShardedSplit(root, "train")
    assert err.value.path == str(path)


def test_an_empty_split_is_refused_naming_the_manifest(tmp_path):
    # readers would see no scene: training, the prior's collection and evaluation would run on nothing
    root = _dataset(tmp_path / "ds")
    manifest = json.loads((root / MANIFEST).read_text())
    manifest["splits"]["val"] = {"count": 0, "shard_size": 2}
    (root / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="'val' holds no samples") as err:
        ShardedSplit(root, "val")
    assert err.value.path == str(root / MANIFEST)
    assert len(ShardedSplit(root, "train")) == 5


def test_a_newer_schema_version_says_the_code_is_older(tmp_path):
    root = _dataset(tmp_path / "ds")
    manifest = json.loads((root / MANIFEST).read_text())
    manifest["schema_version"] = 2
    (root / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="written by a newer version of this code") as err:
        ShardedSplit(root, "train")
    assert err.value.path == str(root / MANIFEST)


def _fail_on_save(monkeypatch, errno_: int, after: int = 1):
    # np.save writes the shard's arrays: the second one hits a full disk halfway
    import os

    real, calls = np.save, []

    def save(file, arr, *args, **kwargs):
        calls.append(file)
        if len(calls) > after:
            if hasattr(file, "write"):
                file.write(b"\x93NUMPY")
            else:  # (a path: how the writer called it before)
                Path(file).write_bytes(b"\x93NUMPY")
            raise OSError(errno_, os.strerror(errno_))
        return real(file, arr, *args, **kwargs)

    monkeypatch.setattr(np, "save", save)


def test_a_full_disk_during_a_shard_write_says_so_and_leaves_no_partial_shard(tmp_path, monkeypatch):
    import errno

    root = _dataset(tmp_path / "ds")
    folder = root / "train" / "shard_000003"
    _fail_on_save(monkeypatch, errno.ENOSPC)
    with pytest.raises(DatasetError, match="no space left on the device") as err:
        write_shard(folder, [_sample(7)], 6)
    assert err.value.path == str(folder) and str(root) in str(err.value)
    assert sorted(p.name for p in (root / "train").iterdir()) == ["shard_000000", "shard_000001", "shard_000002"]
    # the shard it would have replaced is kept whole
    with pytest.raises(DatasetError, match="no space"):
        write_shard(root / "train" / "shard_000001", [_sample(2), _sample(3)], 2)
    assert len(ShardedSplit(root, "train")) == 5 and ShardedSplit(root, "train").metadata(3) == {"seed": 3}


def test_a_full_disk_writing_the_manifest_keeps_the_old_one(tmp_path, monkeypatch):
    import builtins
    import errno

    root = _dataset(tmp_path / "ds")
    before = (root / MANIFEST).read_text()
    real_open = builtins.open

    class _Full:
        def __init__(self, fh):
            self.fh = fh

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def write(self, text):
            self.fh.write(text[:10])
            raise OSError(errno.ENOSPC, "No space left on device")

    def opening(file, mode="r", *args, **kwargs):
        fh = real_open(file, mode, *args, **kwargs)
        return _Full(fh) if str(file).endswith(".json.tmp") else fh

    monkeypatch.setattr(builtins, "open", opening)
    manifest = json.loads(before)
    manifest["splits"]["val"] = {"count": 1, "shard_size": 1}
    with pytest.raises(DatasetError, match="no space left on the device") as err:
        write_manifest(root, manifest)
    monkeypatch.undo()
    assert err.value.path == str(root / MANIFEST)
    assert (root / MANIFEST).read_text() == before and not list(root.glob("*.tmp"))


def test_a_shard_and_its_rename_are_flushed_to_disk_before_and_after_the_rename(tmp_path, monkeypatch):
    # without fsync a power cut after the rename can leave shard_* folders of empty or short files (ext4's delayed
    # allocation), which a resume would have to find; with it the rename only ever shows whole files
    import os

    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        return real_fsync(fd)

    def replace(src, dst):
        events.append(("replace", str(dst)))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    folder = tmp_path / "train" / "shard_000000"
    write_shard(folder, [_sample(0)], 0)
    at = events.index(("replace", str(folder)))
    synced_before = {Path(p).name for kind, p in events[:at] if kind == "fsync"}
    assert synced_before >= {f"{name}.npy" for name in FIELDS} | {"meta.json", f"shard_000000.tmp-{os.getpid()}"}
    assert ("fsync", str(folder.parent)) in events[at:]


def test_dataset_errors_survive_the_trip_from_a_generate_worker():
    # the pool pickles a worker's exception to its parent; unpickling called __init__(message) and failed in the
    # pool's result thread, which then waited forever for that shard
    import pickle

    from training.data.errors import DataConfigError

    err = pickle.loads(pickle.dumps(DatasetError("/data/ds/train/shard_000003", "no space left")))
    assert isinstance(err, DatasetError) and err.path == "/data/ds/train/shard_000003"
    assert str(err) == "/data/ds/train/shard_000003: no space left"
    cfg = pickle.loads(pickle.dumps(DataConfigError("SyntheticConfig.resolution", "must be a multiple of 8")))
    assert cfg.field == "SyntheticConfig.resolution" and str(cfg).endswith("multiple of 8")


# ------------------------------------------------------------------ the writer's lock names its holder
def _hold(root: Path, line: str | None):
    """Hold ``root``'s writer lock on a separate open file (as another process would), with ``line`` in it."""
    import fcntl

    fh = open(root / "dataset.lock", "a+")
    fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    if line is not None:
        fh.truncate(0)
        fh.write(line)
        fh.flush()
    return fh


def test_a_held_lock_names_the_folder_the_live_holder_and_how_to_clear_it(tmp_path):
    import os

    from training.data.cache import writer_lock

    root = tmp_path / "ds"
    root.mkdir()
    with writer_lock(root):
        line = (root / "dataset.lock").read_text().split()
        assert line[0] == str(os.getpid())
        with pytest.raises(DatasetError) as err:
            with writer_lock(root):
                pass
    msg = str(err.value)
    assert err.value.path == str(root / "dataset.lock")
    assert f"writing dataset {root}" in msg and f"pid {os.getpid()}" in msg and f"kill {os.getpid()}" in msg
    assert (root / "dataset.lock").read_text() == ""  # emptied on the way out: folders made alike stay identical
    with writer_lock(root):  # and free again
        pass


def test_a_lock_held_from_another_host_or_by_a_dead_pids_child_says_so(tmp_path):
    import socket
    import subprocess
    import sys

    from training.data.cache import writer_lock

    root = tmp_path / "ds"
    root.mkdir()
    fh = _hold(root, "4242 render-box-7 2026-12-05T00:00:00+0000\n")
    try:
        with pytest.raises(DatasetError, match="pid 4242 on host render-box-7.*file server when render-box-7 is down"):
            with writer_lock(root):
                pass
    finally:
        fh.close()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    fh = _hold(root, f"{int(dead.stdout)} {socket.gethostname()} 2026-12-05T00:00:00+0000\n")
    try:
        with pytest.raises(DatasetError, match=f"pid {int(dead.stdout)} .*has ended.*fuser -v"):
            with writer_lock(root):
                pass
    finally:
        fh.close()
    # a killed holder's line stays, but its lock went with it: the next writer just takes the folder
    with writer_lock(root):
        pass


def _holder_lines(root: Path) -> list[str]:
    """The lines this process writes into ``root``'s lock while it holds it."""
    from training.data.cache import writer_lock

    with writer_lock(root):
        return (root / "dataset.lock").read_text().splitlines()


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="the holder's identity needs Linux /proc")
def test_a_lock_line_whose_number_another_live_process_has_now_is_not_named_as_the_holder(tmp_path, other_process):
    """The holder was killed with -9 while a child it started kept the lock; its number went to another process.
    The message said that process was the holder, to be stopped (``kill <its number>``): the wrong process."""
    from training.data.cache import writer_lock

    root = tmp_path / "ds"
    root.mkdir()
    first, *rest = _holder_lines(root)  # as the holder (this process) writes it ...
    stale = "\n".join([" ".join([str(other_process), *first.split()[1:]]), *rest, ""])  # ... its number now another's
    fh = _hold(root, stale)
    try:
        with pytest.raises(DatasetError) as err:
            with writer_lock(root):
                pass
    finally:
        fh.close()
    assert f"kill {other_process}" not in str(err.value)  # not the holder: not one to stop
    assert f"pid {other_process} " in str(err.value) and "has ended" in str(err.value)


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="the holder's identity needs Linux /proc")
def test_a_live_holder_with_its_identity_or_an_older_one_line_lock_is_named(tmp_path, other_process):
    """The identity written by the holder itself matches; a line of the older one-line form (no identity) is
    judged by its number alone, as before."""
    import socket

    from training.data.cache import writer_lock
    from training.run_lock import process_identity

    root = tmp_path / "ds"
    root.mkdir()
    first, identity = _holder_lines(root)
    assert first.split()[0] == str(os.getpid()) and identity == process_identity(os.getpid())  # who it is
    line = f"{other_process} {socket.gethostname()} 2026-12-05T00:00:00+0000\n"
    for text in (f"{line}{process_identity(other_process)}\n", line):
        fh = _hold(root, text)
        try:
            with pytest.raises(DatasetError, match=f"pid {other_process}, since .*kill {other_process}"):
                with writer_lock(root):
                    pass
        finally:
            fh.close()
