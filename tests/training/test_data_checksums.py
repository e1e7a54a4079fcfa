"""Checksums of the stored arrays: a flipped byte inside an array of the right length is named when its sample is
read and by ``python -m training.data.verify``; a dataset written before them still opens, with one note."""
from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest

from training.data.cache import SHARD_META, ShardedSplit, shard_is_complete
from training.data.errors import DatasetError

CHECKSUMS = "crc32"  # (spelt out, not imported: this file must run against the code from before, and fail)


def verify(argv: list[str]) -> int:
    """``python -m training.data.verify ARGV``'s exit status."""
    from training.data.verify import main

    return main(argv)


@pytest.fixture
def data(data64, tmp_path) -> Path:
    """A private copy of the session's tiny generated dataset (3 train scenes in one shard, 2 val), to damage."""
    return Path(shutil.copytree(data64, tmp_path / "data"))


def _flip_byte(array_file: Path, row: int, at: int = 7) -> None:
    """Invert byte ``at`` of sample ``row``'s slice of a stored array: its length and header stay as they were."""
    mapped = np.load(array_file, mmap_mode="r")
    offset = mapped.offset + row * mapped[0].nbytes + at
    del mapped
    with open(array_file, "r+b") as fh:
        fh.seek(offset)
        byte = fh.read(1)[0]
        fh.seek(offset)
        fh.write(bytes([byte ^ 0xFF]))


def _strip_checksums(root: Path) -> None:
    """Make ``root`` as the code before checksums wrote it: no ``crc32`` entry in any shard's metadata."""
    for meta_path in root.glob(f"*/shard_*/{SHARD_META}"):
        meta = json.loads(meta_path.read_text())
        meta.pop(CHECKSUMS, None)
        meta_path.write_text(json.dumps(meta))


def test_a_flipped_byte_is_named_when_its_sample_is_read(data):
    _flip_byte(data / "train" / "shard_000000" / "images.npy", row=1)
    split = ShardedSplit(data, "train")  # the file's length is right: opening cannot tell
    split.arrays(0)
    split.arrays(2)  # the other samples of the shard read as before
    with pytest.raises(DatasetError) as e:
        split.arrays(1)
    assert e.value.path == str(data / "train" / "shard_000000" / "images.npy")
    message = e.value.message
    assert "sample 1 " in message and "does not match its checksum" in message
    recorded = json.loads((data / "train" / "shard_000000" / SHARD_META).read_text())[CHECKSUMS]["images"][1]
    assert f"recorded {recorded:08x}" in message
    assert f"delete {data / 'train' / 'shard_000000'}" in message and "training.data.generate" in message
    with pytest.raises(DatasetError, match="sample 1 "):
        split[1]  # the Sample path reads through the same check


def test_verify_exits_1_and_prints_every_damaged_shard(data, capsys):
    assert verify([str(data)]) == 0
    assert capsys.readouterr().out == ""
    _flip_byte(data / "train" / "shard_000000" / "depth.npy", row=2)
    _flip_byte(data / "val" / "shard_000000" / "joints_2d.npy", row=0, at=0)
    assert verify([str(data)]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2, lines
    assert lines[0].startswith(f"{data / 'train' / 'shard_000000'}: does not match its checksums")
    assert "depth.npy samples 2" in lines[0] and "training.data.generate" in lines[0]
    assert lines[1].startswith(f"{data / 'val' / 'shard_000000'}:") and "joints_2d.npy samples 0" in lines[1]
    assert verify([str(data), "--split", "val"]) == 1  # one split only: the val shard alone
    assert len(capsys.readouterr().out.splitlines()) == 1


def test_verify_names_a_cut_shard_and_goes_on_to_the_next(data, capsys):
    images = data / "train" / "shard_000000" / "images.npy"
    images.write_bytes(images.read_bytes()[:-10])
    _flip_byte(data / "val" / "shard_000000" / "masks.npy", row=1, at=0)
    assert verify([str(data)]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and lines[0].startswith(str(images)) and "cut short" in lines[0]
    assert "masks.npy samples 1" in lines[1]


def test_verify_of_a_folder_that_is_no_dataset_exits_2(tmp_path, data):
    assert verify([str(tmp_path / "nothing")]) == 2
    assert verify([str(data), "--split", "test"]) == 2


def test_a_dataset_without_checksums_opens_reads_and_says_so_once(data, caplog, capsys):
    _strip_checksums(data)
    _flip_byte(data / "train" / "shard_000000" / "images.npy", row=1)  # undetectable without checksums
    with caplog.at_level(logging.WARNING, logger="training.data.cache"):
        split = ShardedSplit(data, "train")
        for i in range(len(split)):
            split.arrays(i)
    notes = [r.getMessage() for r in caplog.records]
    assert len(notes) == 1 and "1 of its 1 shards carry no checksums" in notes[0], notes
    assert verify([str(data)]) == 0  # nothing to check against: listed, not failed
    assert capsys.readouterr().out == ""


def test_record_missing_gives_old_shards_checksums_that_later_reads_check(data):
    _strip_checksums(data)
    assert verify([str(data), "--record-missing"]) == 0
    assert all(CHECKSUMS in json.loads(p.read_text()) for p in data.glob(f"*/shard_*/{SHARD_META}"))
    _flip_byte(data / "train" / "shard_000000" / "K.npy", row=0, at=3)
    with pytest.raises(DatasetError, match="sample 0 "):
        ShardedSplit(data, "train").arrays(0)
    assert verify([str(data)]) == 1


def test_malformed_checksums_are_refused_at_open_and_rendered_again_by_generate(data):
    meta_path = data / "train" / "shard_000000" / SHARD_META
    meta = json.loads(meta_path.read_text())
    meta[CHECKSUMS]["images"] = meta[CHECKSUMS]["images"][:-1]  # one sample short
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match=r"crc32\.images must be 3 CRC-32 values") as e:
        ShardedSplit(data, "train")
    assert e.value.path == str(meta_path)
    assert not shard_is_complete(meta_path.parent, 0, 3)  # generate's resume renders it again
    del meta[CHECKSUMS]
    meta_path.write_text(json.dumps(meta))
    assert shard_is_complete(meta_path.parent, 0, 3)  # a shard of older code is kept as it is


def test_generate_resumes_an_old_dataset_keeping_its_whole_shards_and_checksumming_what_it_renders(data, caplog):
    from training.data.generate import main as generate

    _strip_checksums(data)  # as the code before checksums left it
    args = ["--out", str(data), "--train", "3", "--val", "3", "--val-seen-motions", "0", "--res", "64", "--workers", "1"]
    assert generate(args) == 0  # val grows from 2 to 3: its shard is rendered again; train's is whole, kept
    train_meta = json.loads((data / "train" / "shard_000000" / SHARD_META).read_text())
    val_meta = json.loads((data / "val" / "shard_000000" / SHARD_META).read_text())
    assert CHECKSUMS not in train_meta and len(val_meta[CHECKSUMS]["images"]) == 3
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="training.data.cache"):
        ShardedSplit(data, "val")
        assert not caplog.records  # all checked: no note
        ShardedSplit(data, "train")
    assert len(caplog.records) == 1 and "carry no checksums" in caplog.records[0].getMessage()
    _flip_byte(data / "val" / "shard_000000" / "images.npy", row=2)
    assert verify([str(data)]) == 1


def test_the_trainer_stops_on_a_damaged_sample_with_one_line_naming_it(data, tmp_path, capsys):
    pytest.importorskip("torch")
    from training.train import main as train_main

    for row in range(3):  # every train scene: whichever the trainer reads first
        _flip_byte(data / "train" / "shard_000000" / "images.npy", row=row)
    config = {"preset": "tiny", "data": str(data), "iterations": 1, "targets_per_iter": 2, "heat_rays": 32,
              "patch_size": 8, "threads": 2}
    (tmp_path / "c.json").write_text(json.dumps(config))
    assert train_main(["--config", str(tmp_path / "c.json"), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"ghnerf-train: data error: {data / 'train' / 'shard_000000' / 'images.npy'}: sample " in err
    assert "does not match its checksum" in err and "Traceback" not in err


@pytest.mark.parametrize("workers", [0, 1])
def test_pretraining_stops_on_a_damaged_sample_with_one_line_naming_it_with_or_without_loader_workers(
        data, tmp_path, capsys, workers):
    """A sample read in a DataLoader worker (``loader_workers``) is reported as one read in-process: torch's own
    re-raise turned the DatasetError into a RuntimeError holding the worker's traceback (exit 1, many lines)."""
    pytest.importorskip("torch")
    from training.pretrain_human import main as pretrain_main

    for row in range(3):
        _flip_byte(data / "train" / "shard_000000" / "images.npy", row=row)
    argv = ["--out", str(tmp_path / "run"), "--data", str(data), "--iterations", "1", "--threads", "1", "--quiet",
            "--set", 'preset="tiny"', "--set", "scenes_per_step=1", "--set", "eval_every=0",
            "--set", f"loader_workers={workers}"]
    assert pretrain_main(argv) == 2
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"error: {data / 'train' / 'shard_000000' / 'images.npy'}: sample ")
    assert "does not match its checksum" in lines[0] and "Traceback" not in err
