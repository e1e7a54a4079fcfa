"""A run folder's ``train.pid`` (``training.run_lock``): a stale file whose number another live process has since
been given is not a run in use, for the trainer, the pretraining and the pipeline alike; a live holder is."""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from training.train import RunFolderInUse, refuse_live_lock, take_lock

linux_proc = pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="the record needs Linux /proc")


def _boot_id() -> str:
    return Path("/proc/sys/kernel/random/boot_id").read_text().strip()


@linux_proc
def test_a_stale_lock_whose_number_another_live_process_has_now_is_not_in_use(tmp_path, other_process):
    """The holder was killed with -9; its number went to another process: the folder was refused ("another
    training process ... is using this run folder") until the file was deleted by hand."""
    from training.pipeline import PipelineConfig, _check_run_folder

    lock = tmp_path / "train.pid"
    take_lock(lock)  # as the holder (this process) writes it ...
    lines = lock.read_text().split("\n")
    lock.write_text("\n".join([str(other_process), *lines[1:]]))  # ... its number now another process's
    refuse_live_lock(lock)  # no RunFolderInUse
    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    run = cfg.runs / "edge128_baseline"
    run.mkdir(parents=True)
    (run / "train.pid").write_text(lock.read_text())
    _check_run_folder(cfg, "baseline")  # the pipeline reads it the same way (it said "in progress")
    # so is a lock written in another boot, whatever the start
    lock.write_text(f"{other_process}\nstart=1@not-{_boot_id()}\n")
    refuse_live_lock(lock)


@linux_proc
def test_a_live_holder_is_refused_naming_its_number(tmp_path, other_process):
    from training.run_lock import lock_text

    lock = tmp_path / "train.pid"
    lock.write_text(lock_text(other_process))  # as the holder wrote it
    with pytest.raises(RunFolderInUse, match=rf"{tmp_path}: another training process \({other_process}\) is using"):
        refuse_live_lock(lock)


def test_a_lock_without_a_record_falls_back_to_the_number_alone(tmp_path, other_process):
    """A file written before the record existed (or where /proc is not read): a live number is in use, as before."""
    lock = tmp_path / "train.pid"
    lock.write_text(str(other_process))
    with pytest.raises(RunFolderInUse, match=f"another training process \\({other_process}\\)"):
        refuse_live_lock(lock)


@linux_proc
def test_the_holder_writes_its_number_alone_on_the_first_line_then_one_word_that_is_no_number(tmp_path):
    """``kill $(cat train.pid)`` must stop the holder and nothing else: the record is not a number."""
    take_lock(tmp_path / "train.pid")
    first, record = (tmp_path / "train.pid").read_text().split("\n")[:2]
    assert first == str(os.getpid())
    assert record.startswith("start=") and record.endswith(f"@{_boot_id()}") and " " not in record
    with pytest.raises(ValueError):
        int(record)


@linux_proc
def test_a_command_name_with_spaces_and_a_parenthesis_is_read(tmp_path):
    """``/proc/<pid>/stat`` puts the command name in parentheses; one holding ") " must not shift the fields."""
    from training.run_lock import lock_holder, lock_text, process_identity

    odd = tmp_path / "x) y (z"
    shutil.copy(shutil.which("sleep"), odd)
    proc = subprocess.Popen([str(odd), "60"])
    try:
        identity = process_identity(proc.pid)
        assert identity is not None and identity.split("@")[0][len("start="):].isdigit()
        (tmp_path / "train.pid").write_text(lock_text(proc.pid))
        assert lock_holder(tmp_path / "train.pid") == proc.pid
    finally:
        proc.kill()
        proc.wait()
