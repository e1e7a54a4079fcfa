from training.run_clock import RunClock


def test_a_resumed_run_sums_its_segments_and_lists_each():
    fresh = RunClock.resumed(None, step=0, threads=2)
    fresh.t0 -= 10.0  # ten seconds in
    ck = {"segments": fresh.segments(12000)}
    assert ck["segments"] == [{"steps": 12000, "wall_s": 10.0, "threads": 2}]
    assert fresh.summary(12000) == {"wall_s": 10.0}  # one invocation: no segment list

    resumed = RunClock.resumed(ck, step=12000, threads=1)
    resumed.t0 -= 5.0
    summary = resumed.summary(24000)
    assert summary["wall_s"] == 15.0
    assert summary["segments"] == [{"steps": 12000, "wall_s": 10.0, "threads": 2},
                                   {"steps": 12000, "wall_s": 5.0, "threads": 1}]
    # a checkpoint made before segments were kept: this invocation alone
    assert RunClock.resumed({"step": 5}, step=5, threads=1).summary(6)["wall_s"] < 1.0
