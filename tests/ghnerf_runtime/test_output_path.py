"""``ready_output``: an output path is settled before the work that fills it."""
from __future__ import annotations

import os

import pytest

from ghnerf_runtime.cli.output_path import OutputPathError, output_clash, ready_output, same_file


def test_a_missing_folder_is_made_and_the_path_returned(tmp_path):
    p = ready_output(tmp_path / "a" / "b" / "r.json", "--out")
    assert p == tmp_path / "a" / "b" / "r.json" and p.parent.is_dir() and not p.exists()
    f = ready_output(tmp_path / "runs" / "net", "--out", kind="folder")
    assert f.is_dir()
    assert ready_output(tmp_path / "runs" / "net", "--out", kind="folder") == f  # an existing folder is fine


def test_the_suffix_numpy_would_add_is_added_first(tmp_path):
    assert ready_output(tmp_path / "cache", "--cache", suffix=".npz") == tmp_path / "cache.npz"
    assert ready_output(tmp_path / "cache.npz", "--cache", suffix=".npz") == tmp_path / "cache.npz"


@pytest.mark.parametrize("make, kind, says", [
    (lambda t: (t / "d").mkdir(), "file", "is a folder"),
    (lambda t: (t / "d").write_text(""), "folder", "is a file"),
])
def test_a_path_of_the_wrong_kind_is_refused_with_flag_and_path(tmp_path, make, kind, says):
    make(tmp_path)
    with pytest.raises(OutputPathError, match=f"--out {tmp_path / 'd'}: {says}"):
        ready_output(tmp_path / "d", "--out", kind=kind)


def test_a_folder_that_cannot_be_made_is_refused(tmp_path):
    (tmp_path / "plain").write_text("")
    with pytest.raises(OutputPathError, match="--json .*cannot make the folder"):
        ready_output(tmp_path / "plain" / "sub" / "r.json", "--json")


def test_a_folder_or_file_without_write_permission_is_refused(tmp_path, monkeypatch):
    import ghnerf_runtime.cli.output_path as op

    (tmp_path / "r.json").write_text("{}")
    # what a read-only mount says (root ignores chmod, so the folder is tried by making a file in it)
    monkeypatch.setattr(op, "unwritable_reason", lambda folder: "Read-only file system")
    with pytest.raises(OutputPathError, match=f"--out {tmp_path / 'r.json'}: the folder {tmp_path} is not writable"):
        ready_output(tmp_path / "r.json", "--out")
    monkeypatch.undo()
    monkeypatch.setattr(op.os, "access", lambda path, mode: str(path) == str(tmp_path))
    with pytest.raises(OutputPathError, match="the file exists and is not writable"):
        ready_output(tmp_path / "r.json", "--out")


def test_output_clash_sees_one_file_however_it_is_spelled(tmp_path):
    (tmp_path / "rig.json").write_text("{}")
    (tmp_path / "link.json").symlink_to(tmp_path / "rig.json")
    inputs = {"--rig": str(tmp_path / "rig.json"), "--config": None}
    assert output_clash({"--out": str(tmp_path / "link.json")}, inputs).startswith(
        f"--out {tmp_path / 'link.json'} is the file --rig reads")
    assert output_clash({"--out": str(tmp_path / "sub" / ".." / "rig.json")}, inputs) is not None
    assert output_clash({"--out": str(tmp_path / "a.json"), "--overlay": None,
                         "--novel-view": str(tmp_path / "a.json")}, inputs).startswith(
        f"--novel-view {tmp_path / 'a.json'} is where --out writes too")
    assert output_clash({"--out": str(tmp_path / "a.json"), "--overlay": str(tmp_path / "a.png")}, inputs) is None


def test_output_clash_sees_a_hard_link_to_an_input(tmp_path):
    # a hard link is a path of its own (realpath keeps it): until session 74 it passed, and a tool that writes its
    # output in place (ghnerf-run's --out) truncated the input it reads
    (tmp_path / "rig.json").write_text("{}")
    os.link(tmp_path / "rig.json", tmp_path / "hard.json")
    inputs = {"--rig": str(tmp_path / "rig.json")}
    assert output_clash({"--out": str(tmp_path / "hard.json")}, inputs).startswith(
        f"--out {tmp_path / 'hard.json'} is the file --rig reads")
    assert same_file(tmp_path / "hard.json", tmp_path / "rig.json")
    # a copy is another file, and a path not there yet is no file's
    (tmp_path / "copy.json").write_text("{}")
    assert not same_file(tmp_path / "copy.json", tmp_path / "rig.json")
    assert not same_file(tmp_path / "new.json", tmp_path / "rig.json")
