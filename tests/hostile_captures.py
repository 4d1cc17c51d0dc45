"""A generated corpus of damaged and hostile capture files, and a runner that feeds them to
``capture info``, ``capture recover`` and ``analyze`` in one worker process.

Used by tests/test_capture_hostile.py (a sample of the corpus) and
bench/bench_hostile_captures.py (all of it, bigger bombs). Every file is made here from
the sample captures and a small format-2 recording; nothing is downloaded.
"""

from __future__ import annotations

import base64
import io
import json
import random
import struct
from collections.abc import Callable
from pathlib import Path

from mcap.records import Chunk, DataEnd, Footer, Header
from mcap.writer import CompressionType, Writer

from conform.capture.sink import default_layout

MAGIC = b"\x89MCAP0\r\n"
HERE = Path(__file__).resolve().parent
SAMPLE = HERE.parent / "captures" / "good-rs232.mcap"


def _records(data: bytes) -> list[tuple[int, int, int]]:
    """(position, opcode, length) of every top-level record."""
    out, pos = [], len(MAGIC)
    while pos + 9 <= len(data):
        op = data[pos]
        (n,) = struct.unpack_from("<Q", data, pos + 1)
        out.append((pos, op, n))
        if op == 0x02:
            break
        pos += 9 + n
    return out


def format2_base() -> bytes:
    """A small format-2 recording made with the recorder (explicit times)."""
    import tempfile

    from conform.capture.recorder import Recorder

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "b.mcap"
        rec = Recorder(p, {"capture_method": "test", "baud": 115200, "variant": "gve64-v19"},
                       clock=lambda: 1.75e9)
        t = 1.75e9
        for i in range(40):
            rec.chunk("host", b"!0C%d,%d,0\r" % (i, 2 * i), t)
            rec.chunk("unit", b"0\r" if i % 7 else b"1\r", t + 0.002)
            t += 0.004
        rec.chunk("host", b"!0PF\r", t)
        rec.chunk("unit", b"0,1,2,3\r", t + 0.003)
        rec.close()
        return p.read_bytes()


def base_files() -> dict[str, bytes]:
    """The intact files the mutants are made from: a format-1 sample and a format-2 recording."""
    return {"v1": SAMPLE.read_bytes(), "v2": format2_base()}


def written(messages: list[tuple[str, bytes, int]], *, metadata: dict[str, str] | None = None,
            compression: CompressionType = CompressionType.ZSTD, library: str = "conform test",
            schema_data: bytes | None = None) -> bytes:
    """A valid MCAP with conform's channels holding the given (topic, payload, log_time)."""
    schemas, channels = default_layout()
    f = io.BytesIO()
    w = Writer(f, compression=compression, enable_data_crcs=True)
    w.start(library=library)
    sid = {s.id: w.register_schema(s.name, s.encoding, schema_data or s.data)
           for s in schemas.values()}
    cid = {c.topic: w.register_channel(c.topic, c.message_encoding, sid[c.schema_id])
           for c in channels.values()}
    w.add_metadata("conform.session", metadata or {"baud": "115200", "variant": "gve64-v19",
                                                   "format_version": "2"})
    for i, (topic, payload, t) in enumerate(messages):
        w.add_message(cid[topic], t, payload, t, i)
    w.finish()
    return f.getvalue()


def _batch(direction: str, chunks: list[bytes], times: list, **over: object) -> bytes:
    from conform.capture.batch import raw_batch
    from conform.capture.sink import encode_payload

    off = int(over.pop("offset", 0))  # type: ignore[call-overload]
    rec = raw_batch(direction, max(off, 0), b"".join(chunks), [len(r) for r in chunks],
                    [float(t) for t in times], [float(t) for t in times],
                    list(range(len(chunks))))
    p = dict(rec.payload)
    if off < 0:
        p["offset"] = off
    p.update(over)
    return encode_payload(p)


def _v1(direction: str, data: bytes, offset: int, t: object) -> bytes:
    return json.dumps({"direction": direction, "data": base64.b64encode(data).decode(),
                       "hex": "", "text": "", "length": len(data), "offset": offset,
                       "t_read": t, "t_first": t, "seq": 1}).encode()


def _session(n: int = 30, *, t0: float = 1.75e9, times: Callable[[int], object] | None = None,
             v1: bool = False) -> list[tuple[str, bytes, int]]:
    """n command/answer pairs as raw messages (format 1 or 2), times from ``times(i)``."""
    msgs = []
    ho = uo = 0
    for i in range(n):
        t = times(i) if times else t0 + i * 0.004
        tn = int(t * 1e9) if isinstance(t, float) and t == t and 0 <= t < 1e10 else i
        cmd, ans = b"!0C%d,0,0\r" % i, b"0\r"
        if v1:
            msgs.append(("/serial/host", _v1("host", cmd, ho, t), tn))
            msgs.append(("/serial/unit", _v1("unit", ans, uo, t), tn))
        else:
            msgs.append(("/serial/host", _batch("host", [cmd], [t], offset=ho), tn))
            msgs.append(("/serial/unit", _batch("unit", [ans], [t], offset=uo), tn))
        ho += len(cmd)
        uo += len(ans)
    return msgs


def _bomb_chunk(compression: str, inflated: int, claimed: int) -> bytes:
    """A file whose one chunk inflates to ``inflated`` zero bytes but claims ``claimed``."""
    step = 1 << 24
    zeros = bytes(step)
    if compression == "zstd":
        import zstandard

        cobj = zstandard.ZstdCompressor(level=1).compressobj()  # no content size
        parts = [cobj.compress(zeros[: min(step, inflated - k)]) for k in range(0, inflated, step)]
        raw = b"".join(parts) + cobj.flush()
    elif compression == "lz4":
        import lz4.frame

        comp = lz4.frame.LZ4FrameCompressor()
        parts = [comp.begin()]
        parts += [comp.compress(zeros[: min(step, inflated - k)]) for k in range(0, inflated, step)]
        raw = b"".join(parts) + comp.flush()
    else:
        raw = bytes(min(inflated, 1 << 20))
    f = io.BytesIO()
    f.write(MAGIC)
    from mcap.data_stream import RecordBuilder

    b = RecordBuilder()
    Header("", "conform test").write(b)
    Chunk(message_start_time=0, message_end_time=0, uncompressed_size=claimed,
          uncompressed_crc=0, compression=compression, data=raw).write(b)
    DataEnd(0).write(b)
    Footer(0, 0, 0).write(b)
    f.write(b.end())
    f.write(MAGIC)
    return f.getvalue()


def corpus(dest: Path, *, seed: int = 7, bomb_bytes: int = 1 << 30, count: int = 12) -> list[Path]:
    """Write the corpus into ``dest``; returns the paths (directories included)."""
    rng = random.Random(seed)
    dest.mkdir(parents=True, exist_ok=True)
    files: dict[str, bytes] = {}
    bases = base_files()
    for bname, base in bases.items():
        recs = _records(base)
        cuts = sorted({rng.randrange(len(MAGIC), len(base)) for _ in range(count)}
                      | {p for p, _, _ in recs[1:4]} | {p + 5 for p, _, _ in recs[1:3]})
        for c in cuts:
            files[f"{bname}-trunc-{c}"] = base[:c]
        for k in range(count):
            b = bytearray(base)
            for _ in range(rng.randint(1, 8)):
                b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
            files[f"{bname}-flip-{k}"] = bytes(b)
        for k in range(count // 2):
            b = bytearray(base)
            a = rng.randrange(len(b))
            n = rng.choice((1, 16, 300, 4096))
            b[a : a + n] = bytes(len(b[a : a + n]))
            files[f"{bname}-zero-{k}"] = bytes(b)
        first_chunk = next(p for p, op, _ in recs if op == 0x06)
        b = bytearray(base)
        b[first_chunk] = 0
        files[f"{bname}-zero-first-chunk-opcode"] = bytes(b)
        for pos, op, _n in recs[1:6]:
            for huge in (2**63 - 1, 2**40, 2**28 + 1):
                b = bytearray(base)
                struct.pack_into("<Q", b, pos + 1, huge)
                files[f"{bname}-huge-len-op{op}-{pos}-{huge}"] = bytes(b)
        b = bytearray(base)  # a chunk that claims to inflate to a terabyte
        struct.pack_into("<Q", b, first_chunk + 9 + 16, 2**40)
        files[f"{bname}-chunk-claims-tb"] = bytes(b)
    for comp in ("zstd", "lz4", "", "bz2"):
        name = comp or "none"
        files[f"bomb-{name}-small-claim"] = _bomb_chunk(comp, bomb_bytes, 1000)
        files[f"bomb-{name}-max-claim"] = _bomb_chunk(comp, bomb_bytes, 200 * 1024 * 1024)
        files[f"bomb-{name}-huge-claim"] = _bomb_chunk(comp, min(bomb_bytes, 1 << 26), 2**40)
    # schema and JSON garbage in a well-formed file
    good = _session()
    for label, payload in {
        "null": b"null", "list": b"[]", "empty-object": b"{}", "not-utf8": b"\xff\xfe\x00",
        "deep": b"[" * 100_000, "number": b"5", "string": b'"x"', "truncated-json": b'{"dir',
        "data-not-b64": _batch("host", [b"ab"], [1.0], data="!!!!"),
        "reads-not-b64": _batch("host", [b"ab"], [1.0], reads="!!!!"),
        "reads-number": _batch("host", [b"ab"], [1.0], reads=5),
        "reads-partial": _batch("host", [b"ab"], [1.0], reads="AAAA"),
        "reads-zero-lengths": _batch("host", [b"ab"], [1.0],
                                     reads=base64.b64encode(bytes(28)).decode()),
        "count-wrong": _batch("host", [b"ab", b"c"], [1.0, 2.0], count=7),
        "offset-huge": _batch("host", [b"ab"], [1.0], offset=2**70),
        "offset-negative": _batch("host", [b"ab"], [1.0], offset=-5),
        "data-short": _batch("host", [b"ab", b"c"], [1.0, 2.0], data="YWI="),
        "v1-data-number": b'{"direction":"host","data":5,"length":1,"offset":0,"t_read":1}',
        "v1-null-fields": b'{"direction":null,"data":null,"length":null,"offset":null}',
    }.items():
        files[f"json-{label}"] = written([("/serial/host", payload, 1)] + good)
        files[f"json-all-{label}"] = written([("/serial/host", payload, i) for i in range(50)])
    files["json-frames-garbage"] = written(good + [("/frames", b'{"count":3,"kind":[1]}', 5),
                                                   ("/exchanges", b"null", 6),
                                                   ("/link", b'{"kind":null,"t":"x"}', 7)])
    files["schema-not-json"] = written(good, schema_data=b"\x00not json")
    # NaN, inf and huge numbers; times in any order
    for label, meta in {"baud-1e400": "1e400", "baud-nan": "nan", "baud-neg": "-9600",
                        "baud-tiny": "1e-300", "baud-huge": "1e300", "baud-text": "fast"}.items():
        files[f"meta-{label}"] = written(good, metadata={"baud": meta, "variant": "gve64-v19"})
    files["meta-variant-garbage"] = written(good, metadata={"variant": "\x00" * 50,
                                                            "dialect": "A1=nope,,=,A99=x"})
    for label, fn in {
        "t-nan": lambda i: float("nan"), "t-inf": lambda i: float("inf") if i % 2 else 1.75e9,
        "t-neg-inf": lambda i: float("-inf"), "t-huge": lambda i: 1e300 * (i + 1),
        "t-negative": lambda i: -1.0 * i, "t-zero": lambda i: 0.0,
        "t-random": lambda i: rng.uniform(0, 2e9), "t-backwards": lambda i: 1.75e9 - i,
    }.items():
        files[f"num-{label}"] = written(_session(times=fn))
        files[f"num-v1-{label}"] = written(_session(times=fn, v1=True))
    rand = [(t, p, rng.randrange(2**64)) for t, p, _ in good]
    files["logtime-random"] = written(rand)
    files["logtime-random-v1"] = written([(t, p, rng.randrange(2**64))
                                          for t, p, _ in _session(v1=True)])
    files["empty"] = b""
    files["magic-only"] = MAGIC
    files["magic-garbage"] = MAGIC + bytes(rng.randrange(256) for _ in range(5000))
    files["text"] = b"hello, world\n"
    paths = []
    for name, data in files.items():
        p = dest / f"{name}.mcap"
        p.write_bytes(data)
        paths.append(p)
    d = dest / "a-directory.mcap"
    d.mkdir(exist_ok=True)
    paths.append(d)
    return paths


def intact_info(data: bytes, workdir: Path) -> dict[str, object]:
    """What ``capture info`` says of an intact file (to compare a mutant against)."""
    from conform.capture.recover import capture_info

    p = workdir / "intact.mcap"
    p.write_bytes(data)
    i = capture_info(p)
    return {"messages": dict(i.messages), "bytes": i.bytes}


# -- the worker: runs the commands in-process, one JSON line per file and command ----------
WORKER = r"""
import faulthandler, io, json, os, resource, signal, sys, contextlib
faulthandler.enable()
from conform.cli.main import main

def alarm(*_):
    raise TimeoutError("hang")
signal.signal(signal.SIGALRM, alarm)
limit = int(os.environ.get("CORPUS_TIMEOUT", "60"))
resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
for line in sys.stdin:
    cmd = json.loads(line)
    out, err = io.StringIO(), io.StringIO()
    code, hang, exc = 0, False, None
    print(json.dumps({"start": cmd}), flush=True)
    signal.alarm(limit)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            main(cmd)
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else 1
    except TimeoutError:
        hang = True
    except BaseException as e:
        import traceback
        exc = traceback.format_exc()[-2000:]
    finally:
        signal.alarm(0)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024
    print(json.dumps({"cmd": cmd, "code": code, "hang": hang, "exc": exc, "out": out.getvalue()[-3000:],
                      "err": err.getvalue()[-3000:], "rss_mb": rss}), flush=True)
"""


def run_commands(commands: list[list[str]], env: dict[str, str], timeout: float = 600,
                 cwd: Path | None = None) -> list[dict]:
    """Run ``conform`` command lines in one worker process (in ``cwd``); a result dict per
    command.

    A worker killed by a signal (a segfault) is restarted after the command that killed it,
    which gets ``{"signal": n}``.
    """
    import subprocess
    import sys

    results: list[dict] = []
    todo = list(commands)
    while todo:
        proc = subprocess.Popen([sys.executable, "-c", WORKER], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, text=True, env=env, cwd=cwd)
        out, _ = proc.communicate("\n".join(json.dumps(c) for c in todo) + "\n", timeout=timeout)
        started = None
        for line in out.splitlines():
            obj = json.loads(line)
            if "start" in obj:
                started = obj["start"]
                continue
            results.append(obj)
            todo.pop(0)
            started = None
        if proc.returncode != 0 and started is not None:
            results.append({"cmd": started, "signal": -proc.returncode, "code": proc.returncode})
            todo.pop(0)
        elif proc.returncode != 0:
            raise RuntimeError(f"corpus worker failed with {proc.returncode}")
    return results


def judge(result: dict, zero_ok: bool) -> str | None:
    """Why a command's outcome is unacceptable, or None if it is fine.

    Fine: exit 2 with one line on stderr; or a non-zero exit that says damaged, truncated or
    unreadable; or exit 0 where ``zero_ok`` (content that is hostile but not damaged, or a
    mutation that changed nothing the reader relies on).
    """
    if result.get("signal"):
        return f"killed by signal {result['signal']}"
    if result.get("hang"):
        return "hang"
    if result.get("exc"):
        return "traceback: " + result["exc"].strip().splitlines()[-1]
    if "Traceback" in result["err"] or "Traceback" in result["out"]:
        return "traceback printed"
    if result["rss_mb"] > 2048:
        return f"{result['rss_mb']} MB of RSS"
    code = result["code"]
    if code == 2:
        lines = result["err"].strip().splitlines()
        return None if len(lines) == 1 else f"exit 2 with {len(lines)} lines on stderr"
    if code != 0:
        text = (result["out"] + result["err"]).lower()
        words = ("damaged", "truncated", "unreadable", "lost", "incomplete")
        return None if any(w in text for w in words) else f"exit {code} without saying why"
    return None if zero_ok else "exit 0 on a damaged file"


CONTENT_HOSTILE = ("meta-", "num-", "logtime-")  # well-formed files with hostile values
# analysed with the HTML report and Parquet tables too (NaN and infinite values reach them)
REPORTED = {"num-t-nan", "num-v1-t-nan", "num-t-inf", "num-t-huge", "meta-baud-1e400",
            "meta-baud-nan", "logtime-random", "num-t-random", "json-all-null"}


def check_corpus(paths: list[Path], intact: dict[str, dict], workdir: Path, env: dict[str, str],
                 analyze_every: int = 1) -> tuple[dict[str, dict[str, int]], list[str]]:
    """Run info, recover and analyze over ``paths``; (outcome counts per command, failures).

    ``intact`` maps a base name ("v1", "v2") to its ``capture info --json`` output;
    ``analyze_every`` > 1 analyses only every n-th file (CI time).
    """
    cmds: list[list[str]] = []
    for i, p in enumerate(paths):
        cmds.append(["capture", "info", "--json", str(p)])
        cmds.append(["capture", "recover", str(p), "-o", str(workdir / f"{p.name}.rec.mcap"),
                     "--force"])
        if p.stem in REPORTED:
            cmds.append(["analyze", str(p), "--report", str(workdir / f"{p.stem}-report"),
                         "--parquet", str(workdir / f"{p.stem}-tables")])
        elif i % analyze_every == 0 or p.name.startswith(("json-", "num-", "meta-", "bomb-")):
            cmds.append(["analyze", str(p)])
    results = run_commands(cmds, env)
    info_ok: dict[str, bool] = {}
    counts: dict[str, dict[str, int]] = {}
    failures: list[str] = []
    for r in results:
        cmd = r["cmd"]
        name = Path(cmd[1] if cmd[0] == "analyze" else cmd[2] if cmd[1] == "recover"
                    else cmd[-1]).name
        command = " ".join(cmd[:2]) if cmd[0] == "capture" else cmd[0]
        if command == "capture info":
            same = False
            if r["code"] == 0:
                try:
                    got = json.loads(r["out"])
                    base = intact.get(name.split("-", 1)[0])
                    same = base is not None and got["messages"] == base["messages"] \
                        and got["bytes"] == base["bytes"]
                except (ValueError, KeyError):
                    same = False
            info_ok[name] = same
        zero_ok = name.startswith(CONTENT_HOSTILE) or info_ok.get(name, False) or (
            command == "capture recover" and ("was already complete" in r["out"] or
                                              " messages salvaged" in r["out"]))
        why = judge(r, zero_ok)
        c = counts.setdefault(command, {"files": 0, "exit 2": 0, "damaged/truncated": 0,
                                        "exit 0": 0, "failed": 0})
        c["files"] += 1
        if why is not None:
            c["failed"] += 1
            failures.append(f"{command} {name}: {why}")
        elif r["code"] == 2:
            c["exit 2"] += 1
        elif r["code"] != 0:
            c["damaged/truncated"] += 1
        else:
            c["exit 0"] += 1
    return counts, failures
