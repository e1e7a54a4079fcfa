"""Two CPU processes with the gloo backend (torch.distributed + DistributedDataParallel, as torchrun runs
``training.train``): after 2 iterations on ``tiny`` both ranks hold identical parameters."""
from __future__ import annotations

import socket

import pytest

torch = pytest.importorskip("torch")
import torch.distributed as dist  # noqa: E402
import torch.multiprocessing as mp  # noqa: E402

from tests.training.test_trainer import tiny_cfg  # noqa: E402  (data64: conftest)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _worker(rank: int, world: int, port: int, data: str, out: str, loss: dict | None = None) -> None:
    import os

    os.environ.update({"MASTER_ADDR": "127.0.0.1", "MASTER_PORT": str(port), "RANK": str(rank),
                       "WORLD_SIZE": str(world), "LOCAL_RANK": str(rank)})
    from training.train import train

    cfg = tiny_cfg(data, threads=1, pck_every=0, device="cpu", **({"loss": loss} if loss else {}))
    summary, model = train(cfg, out, quiet=True)
    assert summary["world_size"] == world and summary["steps"] == 2
    # parameters only: BatchNorm running stats are local between DDP's per-forward buffer broadcasts
    torch.save({k: v.detach().clone() for k, v in model.named_parameters()}, f"{out}/rank{rank}.pt")
    dist.destroy_process_group()


def _run_two_ranks(data64, tmp_path, loss: dict | None = None) -> None:
    import time

    port = _free_port()
    ctx = mp.spawn(_worker, args=(2, port, str(data64), str(tmp_path), loss), nprocs=2, join=False)
    deadline = time.monotonic() + 180  # a hung collective must fail the test, not hang it
    while not ctx.join(timeout=2):
        if time.monotonic() > deadline:
            for p in ctx.processes:
                p.kill()
            pytest.fail("DDP workers did not finish in 180 s")


def test_two_gloo_ranks_end_identical(data64, tmp_path):
    _run_two_ranks(data64, tmp_path)
    a = torch.load(tmp_path / "rank0.pt")
    b = torch.load(tmp_path / "rank1.pt")
    init = torch.load(tmp_path / "ckpt_0000001.pt", weights_only=False)["model"]
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k
    assert any(not torch.equal(init[k], a[k]) for k in a)
    ck = torch.load(tmp_path / "last.pt", weights_only=False)
    assert ck["step"] == 2 and len(ck["extra"]["rng_ranks"]) == 2 and ck["extra"]["world_size"] == 2


def test_a_head_without_loss_weight_trains_under_ddp(data64, tmp_path):
    """``loss.heat_weight`` 0 leaves g_h without gradients: DDP must be told (``find_unused_parameters``), or
    its reducer stops the second step ("Expected to have finished reduction in the prior iteration")."""
    _run_two_ranks(data64, tmp_path, {"heat_weight": 0.0, "coord_weight": 0.01, "encoder_heat_weight": 0.5})
    assert torch.load(tmp_path / "last.pt", weights_only=False)["step"] == 2
