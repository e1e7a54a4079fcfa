"""The pipeline stage that pairs the two camera outputs: a host-run ``Sync`` node and its queue.

Shared by the device link and by host-only pipelines (no device), so what runs
in tests is the same code that runs on the rig.
"""
from __future__ import annotations

import datetime

import depthai as dai

from drivers.backends.depthai.convert import LEFT, RIGHT


def build_sync_stage(
    pipeline: dai.Pipeline,
    left: dai.Node.Output,
    right: dai.Node.Output,
    *,
    tolerance_ms: float,
    queue_size: int,
) -> dai.MessageQueue:
    """Link ``left``/``right`` into a Sync node and return the host queue of its groups.

    The node runs on the host (as in depthai's own stereo sync example) and only
    emits groups whose timestamps lie within ``tolerance_ms`` (sync attempts -1).
    The queue is non-blocking: when the reader falls behind the oldest group is
    dropped, so latency stays bounded (the gap shows in frame indices).
    """
    sync = pipeline.create(dai.node.Sync)
    sync.setRunOnHost(True)
    sync.setSyncThreshold(datetime.timedelta(milliseconds=tolerance_ms))
    sync.setSyncAttempts(-1)
    left.link(sync.inputs[LEFT])
    right.link(sync.inputs[RIGHT])
    return sync.out.createOutputQueue(maxSize=queue_size, blocking=False)
