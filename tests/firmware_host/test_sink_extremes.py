"""Sinks at the extremes (session 72): keyword objects of the wrong kind, descriptors past select()'s range, a
close() that lands while the link is still being opened, capture stamps near the top of the u64 range."""
from __future__ import annotations

import pytest

from firmware_host.errors import SinkConfigError
from firmware_host.sinks import open_sink
from firmware_host.sinks.backoff import BackoffPolicy
from firmware_host.sinks.options import monotonic_us


@pytest.mark.parametrize("key, value", [("backoff", "fast"), ("backoff", 0.1), ("clock_us", 5), ("clock_us", "now")])
def test_a_backoff_or_clock_keyword_of_the_wrong_kind_is_refused_naming_it(key: str, value: object) -> None:
    # before: taken as given; a backoff the worker's first line died on, a clock that failed every connect
    with pytest.raises(SinkConfigError) as e:
        open_sink("memory://", **{key: value})
    assert (e.value.field, e.value.value) == (key, value)
    assert f"invalid {key}={value!r}" in str(e.value)


def test_backoff_and_clock_keywords_given_none_take_their_defaults() -> None:
    # None counts as not given, as for every other keyword (SinkUrl.take); backoff=None killed the worker
    sink = open_sink("memory://", backoff=None, clock_us=None)
    try:
        assert sink.wait_connected(5.0), sink.stats()
        assert sink.options.backoff == BackoffPolicy()
        assert sink.options.clock_us is monotonic_us
    finally:
        sink.close()
