"""Joint-stream outputs chosen by URL: serial, usb, udp, vmc, file, memory.

    sink = open_sink("serial:///dev/ttyACM0?baud=921600")
    sink.send(frame)          # never blocks
    sink.stats()              # every frame is sent, decimated, dropped or queued
    sink.close()
"""
from firmware_host.sinks.backoff import BackoffPolicy
from firmware_host.sinks.base import Sink, SinkStats
from firmware_host.sinks.options import SinkOptions
from firmware_host.sinks.registry import BACKENDS, check_sink_url, open_sink, sink_class

__all__ = ["BACKENDS", "BackoffPolicy", "Sink", "SinkOptions", "SinkStats", "check_sink_url", "open_sink", "sink_class"]
