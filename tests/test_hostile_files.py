"""A hostile-input corpus, generated here, for every user file that is not a capture: spec tables
(`conform spec check`), profile and dialect TOML (`conform profile diff`, `conform emulate
--profile/--dialect`, `conform run --dialect`), results.json (`conform report`).

Every case must end in one clear line on stderr and exit 2 (or, for a damaged file that is still
valid, a normal result); never a traceback, a hang or a runaway memory use. Most cases run the
command in-process (the same code path as the CLI); the heaviest also run as a subprocess with
a time limit and their peak RSS measured.
"""

from __future__ import annotations

import json
import random
import re
import resource
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from conform.cli.main import main
from conform.conformance.results import CheckResult, Grade, LogEntry, RunResults, TargetRun
from conform.families.gve.spec import load_spec
from conform.families.gve.spec.load import FILES

Case = tuple[str, Callable[[Path], None]]
DEEP = 5000
BIG = "9" * 5000


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """The command in-process: (exit code, stdout, stderr); any other exception fails the test."""
    try:
        main(argv)
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out = capsys.readouterr()
    return code, out.out, out.err


def assert_one_line(code: int, err: str, what: str) -> None:
    assert "Traceback" not in err, (what, err)
    assert code == 2, (what, code, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("conform: "), (what, err)


def _sparse(path: Path, size: int) -> None:
    with open(path, "wb") as f:
        f.truncate(size)


def _damage(rng: random.Random, data: bytes) -> dict[str, bytes]:
    """The generic damages of one file's bytes."""
    flipped = bytearray(data)
    for _ in range(8):
        i = rng.randrange(len(flipped))
        flipped[i] ^= 1 << rng.randrange(8)
    zeroed = bytearray(data)
    a = rng.randrange(len(data) // 2)
    zeroed[a:a + 64] = bytes(64)
    return {
        "empty": b"", "truncated": data[: len(data) // 2], "cut-mid-line": data[: len(data) // 3 + 7],
        "bitflips": bytes(flipped), "zeroed-range": bytes(zeroed),
        "binary": rng.randbytes(4096), "latin1": "é".encode("latin-1") * 100,
        "nul": b"\x00" * 1000, "deep-array": data + b"\nzz = " + b"[" * DEEP + b"]" * DEEP + b"\n",
        "deep-table": data + b"\nzz = " + b"{a=" * DEEP + b"1" + b"}" * DEEP + b"\n",
        "bignum": data + b"\nzz = " + BIG.encode() + b"\n",
        "inf-nan": data + b"\nzz = [inf, -inf, nan]\n",
    }


# ---------------------------------------------------------------- spec tables

SPEC_ROOT = load_spec().root


def _spec_cases() -> list[Case]:
    rng = random.Random(12)
    cases: list[Case] = []

    def put(name: str, data: bytes | None = None, *, directory: bool = False,
            remove: bool = False, sparse: int = 0) -> Callable[[Path], None]:
        def make(root: Path) -> None:
            path = root / name
            path.unlink()
            if directory:
                path.mkdir()
            elif sparse:
                _sparse(path, sparse)
            elif not remove:
                path.write_bytes(data or b"")
        return make

    for name in FILES:
        fname = f"{name}.toml"
        data = (SPEC_ROOT / fname).read_bytes()
        cases.append((f"{fname}: a directory", put(fname, directory=True)))
        cases.append((f"{fname}: missing", put(fname, remove=True)))
        cases.append((f"{fname}: 3 GB", put(fname, sparse=3 << 30)))
        for kind, damaged in _damage(rng, data).items():
            cases.append((f"{fname}: {kind}", put(fname, damaged)))

    def edit(fname: str, old: str, new: str) -> Callable[[Path], None]:
        def make(root: Path) -> None:
            path = root / fname
            text = path.read_text()
            assert old in text, (fname, old)
            path.write_text(text.replace(old, new, 1))
        return make

    v = "variants.toml"
    for what, old, new in [
        ("pulses range +-2^63", 'pulses = [-2147483647, 2147483647]',
         'pulses = [-9223372036854775808, 9223372036854775807]'),
        ("queue 2^63-1", "queue = 420", "queue = 9223372036854775807"),
        ("float32 range [-inf, nan]", 'float32 = [-3.4e38, 3.4e38]', 'float32 = [-inf, nan]'),
        ("duplicate axes", 'axes = ["X", "Y", "Z", "A"]', 'axes = ["X", "Y", "X", "A"]'),
        ("lower-case axis", 'axes = ["X", "Y", "Z", "A"]', 'axes = ["x", "Y", "Z", "A"]'),
        ("queue 0", "queue = 420", "queue = 0"),
        ("max_rate negative", "max_rate = 125000", "max_rate = -1"),
        ("bauds empty", "bauds = [", "bauds = [], old_bauds = ["),
        ("address 12", "spindle = 7", "spindle = 12"),
        ("ready_after_s 1e308", "ready_after_s = 2.0", "ready_after_s = 1e308"),
        ("reset A text", "A = 20,", 'A = "fast",'),
        ("reset unknown", "A = 20,", "Zzz = 20, A = 20,"),
        ("range as text", 'pause = [1, 24]', 'pause = "1..24"'),
        ("range reversed", 'pause = [1, 24]', 'pause = [24, 1]'),
        ("range float for an int", 'pause = [1, 24]', 'pause = [1.5, 24]'),
        ("variant a list", "[variant.gve64-v10]", "variant = [1]\n[zzz]"),
    ]:
        cases.append((f"{v}: {what}", edit(v, old, new)))
    for fname, what, old, new in [
        ("commands.toml", "inline range 2^63", "range = [0, 255]", "range = [0, 9223372036854775807]"),
        ("commands.toml", "inline range nan", "range = [0, 255]", "range = [0, nan]"),
        ("commands.toml", "min_count 0", "min_count = 3", "min_count = 0"),
        ("commands.toml", "answer width 0", "width = 8", "width = 0"),
        ("commands.toml", "params a table", "params = []", "params = {}"),
        ("eeprom.toml", "float default 1e39", "type = \"float\"", "type = \"float\"\ndefault = 1e39\nzz = 1"),
        ("status.toml", "queue_full_bit 9", "queue_full_bit = 5", "queue_full_bit = 9"),
        ("errors.toml", "inta_bit 99", "inta_bit = 3", "inta_bit = 99"),
        ("examples.toml", "given position text", 'given = ["position=-1000,2000,50"]',
         f'given = ["position={BIG}"]'),
        ("questions.toml", "range alternative 2^64", '1-4294967295 = "1..4294967295"',
         '1-18446744073709551616 = "1..2^64"'),
    ]:
        cases.append((f"{fname}: {what}", edit(fname, old, new)))

    def chain(root: Path) -> None:
        path = root / v
        extra = "".join(f'\n[variant.deep{i}]\nbase = "{"gve124" if i == 0 else f"deep{i - 1}"}"\n'
                        f'title = "deep {i}"\n' for i in reversed(range(40)))
        path.write_text(path.read_text() + extra)

    cases.append((f"{v}: base chain 40 deep", chain))

    def many_rows(fname: str, row: str) -> Callable[[Path], None]:
        def make(root: Path) -> None:
            path = root / fname
            path.write_text(path.read_text() + "".join(row.format(i=i) for i in range(100_000)))
        return make

    cases.append(("commands.toml: 100 000 extra rows (3 MB)", many_rows(
        "commands.toml", '\n[[command]]\nid = "Z{i}"\nmnemonic = "Z{i}"\naddresses = [0]\n'
        'family = "io"\nparams = []\neffect = "x"\nclause = ["GVE64 §13.5"]\n')))
    cases.append(("errors.toml: 100 000 extra empty rows", many_rows("errors.toml", "[[error]]\n")))
    cases.append(("examples.toml: 100 000 extra rows", many_rows(
        "examples.toml", '[[example]]\nid = "e{i}"\nclause = "A1"\nkind = "checksum"\n')))
    return cases


SPEC_CASES = _spec_cases()
# a damage that leaves a table valid (a flipped bit in a comment) is loaded: that is right too
MAY_LOAD = re.compile(r": (bitflips|zeroed-range|cut-mid-line|inf-nan|deep-array|deep-table|bignum)$")


@pytest.mark.slow
def test_spec_check_corpus(tmp_path, capsys):
    counts = {"refused": 0, "loaded": 0}
    for i, (what, make) in enumerate(SPEC_CASES):
        root = tmp_path / f"s{i}"
        shutil.copytree(SPEC_ROOT, root)
        make(root)
        start = time.monotonic()
        code, out, err = run_cli(["spec", "check", "--specs", str(root)], capsys)
        assert time.monotonic() - start < 20, what
        if code == 0 and MAY_LOAD.search(what):
            assert out.startswith("ok:"), (what, out)
            counts["loaded"] += 1
            continue
        assert_one_line(code, err, what)
        counts["refused"] += 1
        shutil.rmtree(root)
    print(f"spec check corpus: {len(SPEC_CASES)} cases, {counts}")
    assert counts["refused"] >= len(SPEC_CASES) - 30


@pytest.mark.parametrize("what", ["pulses range +-2^63", "queue 2^63-1", "float32 range [-inf, nan]",
                                  "duplicate axes", "base chain 40 deep", "a directory"])
def test_spec_items_of_the_issue(tmp_path, capsys, what):
    """Issue 12 item 7, one by one: each a line ``file:line: row: field: problem``, exit 2."""
    make = next(m for w, m in SPEC_CASES if w.endswith(what))
    root = tmp_path / "s"
    shutil.copytree(SPEC_ROOT, root)
    make(root)
    code, _, err = run_cli(["spec", "check", "--specs", str(root)], capsys)
    assert_one_line(code, err, what)
    if what != "a directory":
        assert re.search(r"variants\.toml:\d+: variant '[^']+': field '[^']+': ", err), err


@pytest.mark.slow
def test_spec_heavy_cases_in_a_subprocess(tmp_path):
    """Deep nesting, 100 000 rows and a 3 GB file as a user meets them: bounded time and memory."""
    for what in ("variants.toml: deep-array", "commands.toml: 3 GB",
                 "examples.toml: 100 000 extra rows"):
        make = dict(SPEC_CASES)[what]
        root = tmp_path / what.split(":")[0] / str(abs(hash(what)))
        shutil.copytree(SPEC_ROOT, root)
        make(root)
        start = time.monotonic()
        proc = subprocess.run([sys.executable, "-m", "conform", "spec", "check", "--specs",
                               str(root)], capture_output=True, text=True, timeout=60)
        took = time.monotonic() - start
        assert "Traceback" not in proc.stderr and proc.returncode in (0, 2), (what, proc.stderr)
        if proc.returncode == 2:
            assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
        assert took < 30, (what, took)
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    assert peak_mb < 2048, peak_mb


# ---------------------------------------------------------------- profile and dialect TOML

GOOD_PROFILE = '[meta]\nvariant = "gve64-v19"\n[dialect]\nA10 = "every-line"\n'


def _profile_cases() -> list[Case]:
    rng = random.Random(7)
    cases: list[Case] = []
    for kind, data in _damage(rng, GOOD_PROFILE.encode() * 3).items():
        cases.append((kind, lambda p, d=data: p.write_bytes(d)))
    for what, text in [
        ("no dialect", '[meta]\nvariant = "x"\n'),
        ("dialect a string", 'dialect = "A1=cr"\n'),
        ("dialect value a number", "[dialect]\nA1 = 5\n"),
        ("dialect value a table", "[dialect.A1]\nx = 1\n"),
        ("meta a number", "meta = 3\n[dialect]\nA1 = \"cr\"\n"),
        ("evidence a list", "evidence = [1]\n[dialect]\nA1 = \"cr\"\n"),
        ("unknown question", "[dialect]\nA99 = \"x\"\n"),
        ("huge question id", f"[dialect]\nA{BIG} = \"x\"\n"),
        ("not an alternative", "[dialect]\nA1 = \"sometimes\"\n"),
        ("nan", "[dialect]\nA1 = nan\n"),
    ]:
        cases.append((what, lambda p, t=text: p.write_text(t)))
    cases.append(("a directory", lambda p: p.mkdir()))
    cases.append(("missing", lambda p: None))
    cases.append(("8 GB", lambda p: _sparse(p, 8 << 30)))
    return cases


PROFILE_CASES = _profile_cases()


@pytest.mark.slow
def test_profile_corpus(tmp_path, capsys):
    """Every hostile profile through `profile diff`, `emulate --profile` and `run --dialect`."""
    good = tmp_path / "good.toml"
    good.write_text(GOOD_PROFILE)
    counts = {"profile diff": 0, "emulate --profile": 0, "run --dialect": 0, "valid": 0}
    for i, (what, make) in enumerate(PROFILE_CASES):
        path = tmp_path / f"p{i}.toml"
        make(path)
        code, out, err = run_cli(["profile", "diff", str(path), str(good)], capsys)
        if code in (0, 1) and "Traceback" not in err:
            counts["valid"] += 1  # damaged but still TOML with a [dialect]: a normal diff
        else:
            assert_one_line(code, err, f"profile diff: {what}")
            counts["profile diff"] += 1
        code, out, err = run_cli(["emulate", "gve64-v19", "--profile", str(path), "--tcp", "70000"],
                                 capsys)
        assert_one_line(code, err, f"emulate --profile: {what}")  # --tcp 70000 stops a valid one
        counts["emulate --profile"] += 1
        code, out, err = run_cli(["run", "--dialect", str(path), "--list", "--check", "zz"], capsys)
        if code == 0 and "Traceback" not in err:
            assert out == "", what  # a valid dialect: nothing matches the check
        else:
            assert_one_line(code, err, f"run --dialect: {what}")
            counts["run --dialect"] += 1
    print(f"profile corpus: {len(PROFILE_CASES)} files, {counts}")


@pytest.mark.parametrize("pair", ["A1", "=x", "A1=", "A1=sometimes", "A99=x", f"A{BIG}=x",
                                  f"A1={BIG}", "A1=cr\x00", "A1=cr=lf", " = "],
                         ids=lambda pair: repr(pair[:12]))
def test_dialect_options(capsys, pair):
    code, _, err = run_cli(["emulate", "gve64-v19", "--dialect", pair], capsys)
    assert_one_line(code, err, pair)


# ---------------------------------------------------------------- results.json

def _good_results() -> dict:
    run = TargetRun("emu:gve64-v19", "gve64-v19", True, "quick", "2026-01-01T00:00:00")
    run.checks = [
        CheckResult("gve64-v19/13.5.3/V/valid", Grade.PASS, "GVE64 §13.5.3", title="V ok",
                    variant="gve64-v19", target="emu:gve64-v19", sequence=["!0V1"],
                    log=[LogEntry(0.0, "tx", b"!0V1\r"), LogEntry(0.001, "rx", b"0\r")]),
        CheckResult("gve64-v19/13.5.9/G/x", Grade.FAIL, "GVE64 §13.5.9", variant="gve64-v19",
                    target="emu:gve64-v19", seed=3, duration=0.5),
    ]
    return RunResults([run], "conform run", "2026-01-01T00:00:00",
                      [{"name": "m", "variant": "gve64-v19", "fault": "f", "killed": True,
                        "caught_by": ["x"]}]).to_json()


def _results_cases() -> list[Case]:
    rng = random.Random(3)
    good = json.dumps(_good_results(), indent=1)
    cases: list[Case] = []
    for kind, data in _damage(rng, good.encode()).items():
        if kind in ("deep-array", "deep-table", "bignum", "inf-nan"):
            continue  # TOML damages; the JSON ones follow
        cases.append((kind, lambda p, d=data: p.write_bytes(d)))

    def edited(fn: Callable[[dict], None]) -> Callable[[Path], None]:
        def make(p: Path) -> None:
            d = json.loads(good)
            fn(d)
            p.write_text(json.dumps(d))
        return make

    def raw(text: str) -> Callable[[Path], None]:
        return lambda p: p.write_text(text)

    c0 = lambda d: d["checks"][0]  # noqa: E731
    for what, fn in [
        ("checks an object", lambda d: d.update(checks={})),
        ("a check a number", lambda d: d["checks"].__setitem__(0, 5)),
        ("grade unknown", lambda d: c0(d).update(grade="MAYBE")),
        ("grade missing", lambda d: c0(d).pop("grade")),
        ("title a list", lambda d: c0(d).update(title=[1])),
        ("log a string", lambda d: c0(d).update(log="x")),
        ("log entry t text", lambda d: c0(d)["log"][0].update(t="a")),
        ("log entry missing data", lambda d: c0(d)["log"][0].pop("data")),
        ("sequence of numbers", lambda d: c0(d).update(sequence=[1, 2])),
        ("seed text", lambda d: c0(d).update(seed="x")),
        ("duration true", lambda d: c0(d).update(duration=True)),
        ("runs a number", lambda d: d.update(runs=7)),
        ("run without target", lambda d: d["runs"][0].pop("target")),
        ("run duration text", lambda d: d["runs"][0].update(duration="long")),
        ("run notes of numbers", lambda d: d["runs"][0].update(notes=[1])),
        ("mutant name a number", lambda d: d["mutants"][0].update(name=1)),
        ("mutants a string", lambda d: d.update(mutants="x")),
        ("command a number", lambda d: d.update(command=5)),
        ("top level a list", lambda d: d.clear() or d.update(x=1)),
    ]:
        cases.append((what, edited(fn)))
    text = json.dumps(_good_results())
    for what, old, new in [("duration NaN", '"duration": 0.5', '"duration": NaN'),
                           ("t Infinity", '"t": 0.001', '"t": Infinity'),
                           ("t 1e400", '"t": 0.001', '"t": 1e400'),
                           ("seed 5000 digits", '"seed": 3', f'"seed": {BIG}'),
                           ("duration -Infinity", '"duration": 0.5', '"duration": -Infinity')]:
        assert old in text, old
        cases.append((what, raw(text.replace(old, new, 1))))
    cases.append(("deep nesting", raw('{"checks": ' + "[" * 100_000 + "]" * 100_000 + "}")))
    cases.append(("a list", raw("[1, 2]")))
    cases.append(("a directory", lambda p: p.mkdir()))
    cases.append(("missing", lambda p: None))
    cases.append(("4 GB", lambda p: _sparse(p, 4 << 30)))
    return cases


RESULTS_CASES = _results_cases()


def test_report_renders_the_good_results(tmp_path, capsys):
    path = tmp_path / "results.json"
    path.write_text(json.dumps(_good_results()))
    code, out, err = run_cli(["report", str(path), "-o", str(tmp_path / "out")], capsys)
    assert code == 0 and (tmp_path / "out" / "index.html").exists(), err


@pytest.mark.slow
def test_report_corpus(tmp_path, capsys):
    refused = 0
    for i, (what, make) in enumerate(RESULTS_CASES):
        path = tmp_path / f"r{i}.json"
        make(path)
        out_dir = tmp_path / f"out{i}"
        code, out, err = run_cli(["report", str(path), "-o", str(out_dir)], capsys)
        if code == 0 and what in ("bitflips", "zeroed-range"):
            continue  # the damage missed everything the report reads
        assert_one_line(code, err, what)
        assert not (out_dir / "index.html").exists(), what
        refused += 1
    print(f"report corpus: {len(RESULTS_CASES)} files, {refused} refused")
    assert refused >= len(RESULTS_CASES) - 2


@pytest.mark.slow
def test_report_heavy_cases_in_a_subprocess(tmp_path):
    for what in ("deep nesting", "4 GB", "seed 5000 digits"):
        path = tmp_path / f"{abs(hash(what))}.json"
        dict(RESULTS_CASES)[what](path)
        proc = subprocess.run([sys.executable, "-m", "conform", "report", str(path), "-o",
                               str(tmp_path / "out")], capture_output=True, text=True, timeout=60)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, (what, proc.stderr)
        assert len(proc.stderr.strip().splitlines()) == 1
    assert resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024 < 2048
