"""The benchmarks that read a cached dataset refuse a ``--data`` (or ``--extra-data``) that is no dataset, or lacks
the split they read, as a usage error naming the option and the file (exit 2), before a model is loaded or
trained: it was the reader's DatasetError traceback, in some scripts after the model was loaded. The scripts that
score a torch checkpoint on the dataset refuse a ``--model`` they cannot read alike."""
from __future__ import annotations

import argparse

import pytest

from tests.benchmarks.test_count_arguments import usage_error
from training.cli.dataset_split import check_dataset_split

NO_DATA = "no-such-dataset"
#: script -> its arguments, --data (or --extra-data) naming what no run can read
CASES = {
    "bench_runtime_vs_eval": ("--data", NO_DATA),
    "measure_novel_ceiling": ("--data", NO_DATA),
    "measure_prior_outliers": ("--data", NO_DATA),
    "measure_prior_peak_shape": ("--data", NO_DATA),
    "time_pretrain_step": ("--data", NO_DATA),
    "time_train_step": ("--data", NO_DATA),
    "measure_body_proxy": ("--data", NO_DATA, "--model", "m.pt", "--joints", "j.npz"),
    "tune_proxy_matte": ("--data", NO_DATA, "--model", "m.pt", "--joints", "j.npz"),
}


@pytest.mark.parametrize("script", sorted(CASES))
def test_a_folder_that_is_no_dataset_is_a_usage_error(script, monkeypatch, capsys):
    err = usage_error(monkeypatch, capsys, script, *CASES[script])
    assert f"argument --data: {NO_DATA}/dataset.json: no dataset manifest here" in err, err


@pytest.mark.parametrize("script, args, option", [
    ("bench_runtime_vs_eval", ("--split", "val"), "--data"),  # its default split
    ("measure_prior_peak_shape", ("--val-split", "val"), "--data"),
    ("measure_prior_peak_shape", ("--extra-data", NO_DATA), "--extra-data"),  # before --data's held-out split
    ("time_train_step", ("--variants", "ghnerf", "--set", 'split="val"'), "--data"),  # the split --set leaves
])
def test_a_split_the_script_reads_is_checked(script, args, option, train_only, monkeypatch, capsys):
    err = usage_error(monkeypatch, capsys, script, "--data", str(train_only), *args)
    assert f"argument {option}: " in err and ("has no split 'val'" in err or NO_DATA in err), err


def test_a_dataset_with_the_split_gets_through(train_only):
    check_dataset_split(argparse.ArgumentParser(), train_only, "train")


@pytest.mark.parametrize("script, args", [
    ("measure_body_proxy", ("--model", "no-such.pt", "--joints", "j.npz")),
    ("tune_proxy_matte", ("--model", "no-such.pt", "--joints", "j.npz")),
    ("measure_novel_ceiling", ("--model", "a=no-such.pt")),
])
def test_a_checkpoint_that_cannot_be_read_is_a_usage_error(script, args, train_only, monkeypatch, capsys):
    """``--model`` naming no checkpoint was load_model's ConfigError traceback."""
    err = usage_error(monkeypatch, capsys, script, "--data", str(train_only), "--split", "train", *args)
    assert "argument --model: no-such.pt: unreadable checkpoint (FileNotFoundError" in err, err
