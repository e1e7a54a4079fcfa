"""``benchmarks/measure_prior_peak_shape.py``'s ``--cache`` and ``--seed``, without the minutes of collecting and
training a run takes (tests/training/test_skeleton_prior_cli.py runs its feature function)."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks import measure_prior_peak_shape as bench


class _StopWhenSaved:
    """An array element whose pickling is stopped as Ctrl-C stops a run."""

    def __reduce__(self):
        raise KeyboardInterrupt


def test_a_stop_inside_the_cache_write_leaves_no_cache(train_only, tmp_path, monkeypatch):
    """``np.savez`` to the path closed its zip on the arrays written before the stop: a valid file, read by the
    next run as the collection, its later arrays (the held-out split) missing."""
    arrays = {"uv": np.zeros((2, 3)), "stop": np.array([_StopWhenSaved()], dtype=object)}
    monkeypatch.setattr(bench, "collect_all", lambda args: (arrays, arrays))
    monkeypatch.setattr(bench, "check_dataset_split", lambda *args: None)  # train_only has no held-out split
    cache = tmp_path / "collected.npz"
    with pytest.raises(KeyboardInterrupt):
        bench.main(["--data", str(train_only), "--cache", str(cache)])
    assert not cache.exists()
    assert list(tmp_path.iterdir()) == []  # nor a temporary file


def test_a_seed_no_run_can_use_is_a_usage_error_before_the_collection(monkeypatch, capsys):
    """It was torch's "Overflow when unpacking long long" once the scenes were collected."""
    monkeypatch.setattr(bench, "collect_all", lambda args: pytest.fail("the scenes were collected"))
    with pytest.raises(SystemExit) as stopped:
        bench.main(["--data", "no-such-dataset", "--seed", str(2 ** 64)])
    assert stopped.value.code == 2
    assert f"argument --seed: must be an integer in [0, 4294967295], got {2 ** 64}" in capsys.readouterr().err


def test_the_training_split_as_the_held_out_one_is_a_usage_error(monkeypatch, capsys):
    """``--val-split train`` scored the prior on the scenes it was fitted on (``training.skeleton_prior`` refuses
    the same); it was taken, its MPJPE printed as held-out."""
    monkeypatch.setattr(bench, "collect_all", lambda args: pytest.fail("the scenes were collected"))
    monkeypatch.setattr(bench, "check_dataset_split", lambda *args: None)  # the split's own check comes after
    with pytest.raises(SystemExit) as stopped:
        bench.main(["--data", "d", "--val-split", "train"])
    assert stopped.value.code == 2
    assert "argument --val-split: 'train' is the split the prior is fitted on" in capsys.readouterr().err
