"""``training.data.torch_dataset.load_in_workers``: a data error raised in a DataLoader worker reaches the loop as
itself (type, fields, message), as it would in-process; any other error keeps torch's report."""
from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from training.data.errors import DataConfigError, DataError, DatasetError  # noqa: E402
from training.data.torch_dataset import load_in_workers  # noqa: E402


class Failing(torch.utils.data.Dataset):
    """Items 0, 1, ... as tensors; item ``at`` raises ``error``."""

    def __init__(self, at: int, error: Exception) -> None:
        self.at, self.error = at, error

    def __len__(self) -> int:
        return 4

    def __getitem__(self, i):
        if i == self.at:
            raise self.error
        return torch.tensor(i)


class Unpicklable(DataError):
    """A data error whose (cls, args) pickle cannot be rebuilt (two required arguments, no __reduce__)."""

    def __init__(self, a: str, b: str) -> None:
        super().__init__(f"{a}: {b}")


@pytest.mark.parametrize("error, fields", [
    (DatasetError("/d/train/shard_000000/images.npy", "sample 2 does not match its checksum"),
     {"path": "/d/train/shard_000000/images.npy", "message": "sample 2 does not match its checksum"}),
    (DataConfigError("SyntheticConfig.resolution", "must be a multiple of 16, got 60"),
     {"field": "SyntheticConfig.resolution", "message": "must be a multiple of 16, got 60"}),
])
def test_a_data_error_in_a_worker_is_raised_as_itself_after_the_items_before_it(error, fields):
    got = []
    with pytest.raises(type(error)) as e:
        for item in load_in_workers(Failing(2, error), batch_size=None, num_workers=1):
            got.append(int(item))
    assert got == [0, 1]  # in order, as the in-process loop: the items before the bad one are used
    assert str(e.value) == str(error) and "Traceback" not in str(e.value)
    for name, value in fields.items():
        assert getattr(e.value, name) == value


def test_other_errors_keep_torchs_report():
    with pytest.raises(Exception, match="Traceback") as e:  # noqa: PT011 - torch picks the type
        list(load_in_workers(Failing(1, ZeroDivisionError("a bug")), batch_size=None, num_workers=1))
    assert "a bug" in str(e.value)
    with pytest.raises(RuntimeError, match="Caught Unpicklable"):  # would not survive the trip: torch's report
        list(load_in_workers(Failing(0, Unpicklable("x", "y")), batch_size=None, num_workers=1))


def test_without_workers_the_items_come_as_from_the_loader():
    assert [int(t) for t in load_in_workers(Failing(-1, ValueError()), batch_size=None)] == [0, 1, 2, 3]

