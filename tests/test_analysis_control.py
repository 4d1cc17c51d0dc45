"""A streamed replay goes on past H/G/D/K/R/J: window by window it gives what the motion
executor gives over the whole session.

``queue.StreamReplay`` runs the compiled scan up to an H, G, D, K, R or J, hands the
scan's state to a ``MotionExecutor`` there and takes it back at a later vector, any number
of times, a window at a time. The reference is ``queue.replay(..., compiled=False)``: the
executor over the whole table, fed row by row.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_analysis_replay import _Cmd, same
from test_analysis_replay import session as plain_session
from test_analysis_stream import BAUD, T0, outcome

from conform.families.gve.analysis import analyze, queue
from conform.families.gve.analysis.queue import StreamReplay, replay
from conform.families.gve.spec import load_spec

# what a sender does with the control commands: halt and go on, halt and delete, halt,
# park, a few L moves, restore and go on, a reset; refused ones (D while running) too
PATTERNS = (("H", "G"), ("H", "D"), ("H", "K", "L", "L", "R", "G"), ("J",), ("D",),
            ("K", "L", "R"), ("H", "H", "G", "G"), ("R",))


def session(seed: int, n: int) -> tuple[pd.DataFrame, np.ndarray, dict]:
    """``test_analysis_replay.session`` with control patterns put in after the first 300
    rows (so that the compiled scan runs first), every 20 to 80 rows."""
    ex, _acc, parsed = plain_session(seed, n)
    rng = np.random.default_rng(seed + 100)
    names = ex["name"].to_numpy().copy()
    vec = ex[["dx", "dy", "dz", "da"]].to_numpy().copy()
    t = ex["t_cmd_last"].to_numpy().copy()
    r = 300
    while r < n - 10:
        for k, name in enumerate(PATTERNS[int(rng.integers(len(PATTERNS)))]):
            names[r + k] = name
            parsed.pop(r + k, None)
            vec[r + k] = rng.integers(-500, 500, 4) if name == "L" else 0
            if name in "HR" and rng.random() < 0.7:  # mostly the sender waits for the
                t[r + k + (name == "H") :] += 3.0  # stop after H, the L moves before R
        r += int(rng.integers(20, 80))
    ex = ex.assign(name=names, dx=vec[:, 0], dy=vec[:, 1], dz=vec[:, 2], da=vec[:, 3],
                   t_cmd_last=t)
    code = ex["code"].to_numpy()
    ex = ex.assign(packet=-1, cmd_bytes=12, unit_time=3e-4, host_time=2e-4,
                   t_cmd_first=t - 1e-3)
    acc = np.isin(names, ("C", "L")) & (code == 0)
    return ex, acc, parsed


def streamed(ex: pd.DataFrame, acc: np.ndarray, parsed: dict, var: object, window: int,
             keep: bool = True) -> StreamReplay:
    s = StreamReplay(var, keep=keep)
    for lo in range(0, len(ex), window):
        s.feed(ex, acc, parsed.get, lo, min(len(ex), lo + window), 0)
    s.finish()
    return s


def test_sessions_with_control_exercise_it() -> None:
    """The generated sessions halt, delete, park and reset a moving queue, not only
    commands the executor refuses."""
    var = load_spec().variant("gve64-v19")
    ex, acc, parsed = session(0, 3000)
    ref = replay(ex, acc, parsed.get, var, compiled=False)
    ctrl = int(np.isin(ex["name"].to_numpy(), list("HGDKRJ")).sum())
    refused = [m for m in ref.notes if m.split()[1] in tuple("HGDKRJ")]
    assert ctrl > 60 and 0 < len(refused) < ctrl / 2
    assert len(ref.removals) > 50 and len(ref.ends) > 1000
    assert not np.all(np.diff(ref.done_rows) > 0)  # K/R: finished out of push order
    assert np.array_equal(np.sort(ref.done_rows), np.unique(ref.done_rows))


# a window of one row hands back at every row: seconds a case, so the quick run (-m 'not slow')
# takes it for one seed, the full run for all six
@pytest.mark.parametrize("seed, window", [
    pytest.param(seed, window, marks=pytest.mark.slow if window == 1 and seed else ())
    for seed in range(6) for window in (1, 7, 450, 10**9)])
@pytest.mark.parametrize("compiled_rows", [1, queue.COMPILED_ROWS])
def test_stream_equals_executor(seed: int, window: int, compiled_rows: int,
                                monkeypatch: pytest.MonkeyPatch) -> None:
    """With ``compiled_rows`` 1 the scan takes the executor's state back at every vector
    where it can (tens of times a session), with the default only where the control rows
    leave room."""
    monkeypatch.setattr(queue, "COMPILED_ROWS", compiled_rows)
    spec = load_spec()
    var = spec.variant(("gve64-v19", "gve124", "gve64-v10")[seed % 3])
    ex, acc, parsed = session(seed, 1500)
    ref = replay(ex, acc, parsed.get, var, compiled=False)
    assert replay(ex, acc, parsed.get, var).notes == ref.notes  # the default takes Python
    s = streamed(ex, acc, parsed, var, window)
    assert s.control_row == int(np.flatnonzero(np.isin(ex["name"].to_numpy(),
                                                        list("HGDKRJ")))[0])
    if compiled_rows == 1:
        assert s.hand_backs > 3
    same(s.result(), ref)


def test_summaries_not_kept_equal_executor() -> None:
    """Not kept (a long capture): the counts and the depth summary of the whole replay."""
    from conform.families.gve.analysis.analyze import _queue_metrics

    var = load_spec().variant("gve64-v19")
    ex, acc, parsed = session(4, 3000)
    ref = _queue_metrics(replay(ex, acc, parsed.get, var, compiled=False), 0.0)
    for window in (13, 500):
        got = streamed(ex, acc, parsed, var, window, keep=False).metrics(0.0, [])
        for k in ("vectors_replayed", "vectors_completed", "max_depth", "starvations"):
            assert got[k] == ref[k], k
        for k in ("mean_depth", "starved_s", "standstill_s", "median_vector_s",
                  "motion_end_s"):
            assert got[k] == pytest.approx(ref[k], rel=1e-9, abs=1e-12), k


def test_no_control_stays_compiled() -> None:
    var = load_spec().variant("gve64-v19")
    ex, acc, parsed = plain_session(2, 1000)
    ex = ex.assign(packet=-1, cmd_bytes=12, unit_time=3e-4, host_time=2e-4,
                   t_cmd_first=ex["t_cmd_last"])
    s = streamed(ex, acc, parsed, var, 97)
    assert s.exe is None and s.control_row == -1
    same(s.result(), replay(ex, acc, parsed.get, var, compiled=False))


def test_first_row_control_and_modal_after() -> None:
    """A session that opens with H and changes its parameters after the hand-over."""
    var = load_spec().variant("gve64-v19")
    n = 400
    names = np.array(["C"] * n, object)
    names[0], names[100], names[101], names[150], names[151] = "H", "G", "V", "H", "G"
    names[200] = "VK"
    parsed = {101: _Cmd((4000,))}
    t = T0 + np.cumsum(np.full(n, 2e-3))
    ex = pd.DataFrame({"name": names, "code": 0, "status": "answered", "t_cmd_last": t,
                       "dx": 120, "dy": -80, "dz": 0, "da": 0, "packet": -1,
                       "cmd_bytes": 12, "unit_time": 3e-4, "host_time": 2e-4,
                       "t_cmd_first": t})
    acc = names == "C"
    for window in (1, 33, n):
        same(streamed(ex, acc, parsed, var, window).result(),
             replay(ex, acc, parsed.get, var, compiled=False))


def write_control_capture(path: Path, n: int, seed: int = 5) -> None:
    """A format-2 capture of ``n`` exchanges: C vectors answered ``0`` with H/G/D/K/R/J
    patterns among them (answered ``0``), no checksums."""
    from conform.capture.batch import raw_batch
    from conform.capture.sink import McapSink

    rng = np.random.default_rng(seed)
    byte_t = 10.0 / BAUD
    with open(path, "wb") as f:
        sink = McapSink(f)
        sink.metadata("conform.session", {"variant": "gve64-v19", "baud": BAUD,
                                          "capture_method": "test", "format_version": "2"})
        offset = {"host": 0, "unit": 0}
        order = 0
        t = T0

        def read(d: str, data: bytes, t_first: float, t_read: float) -> None:
            nonlocal order
            sink.write(raw_batch(d, offset[d], bytearray(data), [len(data)], [t_read],
                                 [t_first], [order]))
            offset[d] += len(data)
            order += 1

        def exchange(cmd: bytes) -> None:
            nonlocal t
            end = t + len(cmd) * byte_t
            read("host", cmd, t, end)
            a0 = end + 3e-4
            read("unit", b"0\r", a0, a0 + 2 * byte_t)
            t = a0 + 2 * byte_t + float(rng.choice([2e-3, 0.02, 0.06], p=[0.5, 0.4, 0.1]))

        exchange(b"!0V20000\r")
        exchange(b"!0A400\r")
        done = 2
        while done < n:
            if done > 100 and rng.random() < 0.03:
                for name in PATTERNS[int(rng.integers(len(PATTERNS)))]:
                    if name == "R":  # the L moves done
                        t += 3.0
                    if name == "L":
                        exchange(b"!0L%d,%d,0\r" % tuple(rng.integers(-300, 300, 2)))
                    else:
                        exchange(b"!0" + name.encode() + b"\r")
                    if name == "H":  # the stop awaited
                        t += 3.0
                    if name == "J":  # the parameters again after the reset
                        exchange(b"!0V20000\r")
                        exchange(b"!0A400\r")
                    done += 1
                continue
            exchange(b"!0C%d,%d,0\r" % tuple(rng.integers(-400, 400, 2)))
            done += 1
        sink.finish()


def test_streamed_analysis_with_control(tmp_path: Path) -> None:
    """The whole analysis (tables kept: the executor over the whole table) and the streamed
    one (nothing kept, windows of a few lines, the hand-over inside them) find the same
    and measure the same; the replay went on to the end of the capture."""
    path = tmp_path / "control.mcap"
    write_control_capture(path, 2500)
    whole = analyze(path, whatif_replays=False)
    q = whole.metrics["queue"]
    assert whole.queue is not None and len(whole.queue.removals) > 0
    assert q["vectors_completed"] > 2000 and q["starvations"] > 50
    assert not any("stopped" in n for n in whole.notes)
    found, metrics = outcome(path, whatif_replays=False)
    for kw in ({"window_lines": 37, "reads_per_part": 5}, {"window_lines": 400}):
        got, got_metrics = outcome(path, whatif_replays=False, keep_rows=0, **kw)
        assert got == found
        gq, mq = got_metrics.pop("queue"), metrics["queue"]
        rest = {k: v for k, v in metrics.items() if k != "queue"}
        assert json.dumps(got_metrics, sort_keys=True) == json.dumps(rest, sort_keys=True)
        for k, v in mq.items():
            assert gq[k] == (pytest.approx(v, rel=1e-9) if isinstance(v, float) else v), k
