"""bench_graph_threads' schedule, with fake sessions and a fake clock whose calls grow slower as time goes on
(load drifting up on a shared host): identical graph files must time alike, whatever their order.

The bench timed each graph file's rounds in a block, fp32 then int8, after three warm-up calls: on the shipped
model the two byte-identical ``volume`` files came 1.5x apart in one run (session 68). It now runs every graph
file at both thread counts in each round, in an order turned (and reversed) from round to round, after whole
warm-up rounds.
"""
from __future__ import annotations

import itertools
import re
from types import SimpleNamespace

import pytest

import benchmarks.bench_graph_threads as bench

#: ms per call of each fake graph file at the start (the volume pair: identical files).
BASE_MS = {"volume.onnx": 1.0, "volume.int8.onnx": 1.0, "human.onnx": 1.0, "human.int8.onnx": 0.5}
CALLS = {"volume": 5, "human": 3}
GRAPH_OF = {name: name.split(".")[0] for name in BASE_MS}


class _Clock:
    """Seconds; each run costs its base time, stretched as time passes (the whole bench about 2-3x slower by
    its end)."""

    def __init__(self):
        self.t = 0.0

    def perf_counter(self) -> float:
        return self.t

    def spend(self, ms: float) -> None:
        self.t += 1e-3 * ms * (1.0 + self.t / 0.4)


class _FakeSession:
    def __init__(self, name: str, threads: int, clock: _Clock):
        self.key, self.clock = (name, threads), clock

    def run(self, outputs, feeds):
        self.clock.spend(BASE_MS[self.key[0]] / self.key[1] ** 0.1)


@pytest.fixture
def fake_bench(tmp_path, monkeypatch):
    """The bench's ``main`` on fake sessions and clock: the log of its passes through a graph's calls, in order,
    as ``((file name, threads), number of calls)``."""
    for name in BASE_MS:  # the volume pair byte-identical, the human pair not
        (tmp_path / name).write_bytes(b"human-int8" if name == "human.int8.onnx" else b"same graph")
    clock, passes = _Clock(), []
    replay = bench._replay_ms

    def logged_replay(sess, calls):
        passes.append((sess.key, len(calls)))
        return replay(sess, calls)

    monkeypatch.setattr(bench, "resolve_model_dir", lambda model_dir: tmp_path)
    monkeypatch.setattr(bench, "load_sequences", lambda *a, **k: [])
    monkeypatch.setattr(bench, "capture", lambda *a: {g: [{}] * n for g, n in CALLS.items()})
    monkeypatch.setattr(bench, "_open", lambda path, threads: _FakeSession(path.name, threads, clock))
    monkeypatch.setattr(bench, "_replay_ms", logged_replay)
    monkeypatch.setattr(bench, "time", SimpleNamespace(perf_counter=clock.perf_counter))
    return passes


def _row(out: str, name: str) -> list[float]:
    m = re.search(rf"^{re.escape(name)} +\d+ +([\d.]+) +([\d.]+)", out, re.M)
    assert m, out
    return [float(x) for x in m.groups()]


def test_identical_graph_files_time_alike_under_drifting_load(fake_bench, capsys):
    assert bench.main(["--graphs", "volume,human", "--rounds", "15"]) == 0
    out = capsys.readouterr().out
    fp32, int8 = _row(out, "volume.onnx"), _row(out, "volume.int8.onnx")
    for a, b in zip(fp32, int8):  # the old blocks: int8 about 1.4x fp32 at both thread counts
        assert b / a == pytest.approx(1.0, abs=0.05), out
    control = re.search(r"^volume +([\d.]+) +[\d.-]+ +([\d.]+) +[\d.-]+ +control: identical files", out, re.M)
    assert control, out
    assert [float(x) for x in control.groups()] == pytest.approx([1.0, 1.0], abs=0.03), out
    assert not re.search(r"^human .*control", out, re.M), out  # different files: no control
    human = re.search(r"^human +([\d.]+)", out, re.M)
    assert human and float(human.group(1)) == pytest.approx(0.5, abs=0.05), out


def test_every_round_runs_every_session_in_a_turned_order(fake_bench, capsys):
    assert bench.main(["--graphs", "volume,human", "--rounds", "8", "--warmup", "2"]) == 0
    passes = [key for key, _ in fake_bench]
    sessions = set(passes)
    assert len(sessions) == 8 and len(passes) == 8 * 10  # 2 warm-up rounds + 8 timed, every session in each
    rounds = [passes[i:i + 8] for i in range(0, len(passes), 8)]
    assert all(set(r) == sessions for r in rounds), rounds
    for key in sessions:  # every place among its graph's four, over the eight timed rounds
        places = {[k for k in r if GRAPH_OF[k[0]] == GRAPH_OF[key[0]]].index(key) for r in rounds[2:]}
        assert places == {0, 1, 2, 3}, (key, rounds)
    assert {GRAPH_OF[r[0][0]] for r in rounds[2:]} == set(CALLS), rounds  # each graph opens a round
    for a, b in itertools.combinations(sessions, 2):  # each two sessions in both orders, as often
        firsts = [r.index(a) < r.index(b) for r in rounds]
        assert firsts.count(True) == firsts.count(False), (a, b, rounds)


def test_every_session_warms_up_on_every_call_alike(fake_bench, capsys):
    assert bench.main(["--graphs", "volume,human", "--rounds", "3", "--warmup", "2"]) == 0
    warm = {}
    for key, n in fake_bench[:8 * 2]:  # the passes before the first timed round
        warm[key] = warm.get(key, 0) + n
    assert warm == {key: 2 * CALLS[GRAPH_OF[key[0]]] for key in warm} and len(warm) == 8, warm


def test_round_order_turns_and_reverses():
    variants = {"a": [("a", "a.onnx", 1), ("a", "a.onnx", 2)], "b": [("b", "b.onnx", 1), ("b", "b.onnx", 2)]}
    orders = [bench.round_order(variants, turn) for turn in range(10)]
    assert all(orders[t + 1] == orders[t][::-1] for t in range(0, 10, 2))  # each two rounds: both orders
    assert orders[2] == [("a", "a.onnx", 2), ("a", "a.onnx", 1), ("b", "b.onnx", 2), ("b", "b.onnx", 1)]
    # the graphs turn every two variant turns (two variants a graph), so the two turns do not move in step
    assert orders[4] == [("b", "b.onnx", 1), ("b", "b.onnx", 2), ("a", "a.onnx", 1), ("a", "a.onnx", 2)]


def test_no_graph_the_estimator_ran_is_named_not_timed(fake_bench, capsys):
    assert bench.main(["--graphs", "render_rgb"]) == 0  # the fake capture has no render_rgb calls
    assert "render_rgb               (not run by the estimator with this model)" in capsys.readouterr().out
    assert fake_bench == []
