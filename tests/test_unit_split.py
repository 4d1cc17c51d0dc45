"""The reference unit answers byte for byte as it did before its split into command families.

``tests/data/unit_transcripts.jsonl.xz`` holds transcripts recorded from the single-class unit
(before ``conform/families/gve/unit/model.py`` was split by command family): for every variant
under the default dialect and under each single alternative of every open question (and a few
random mixes), a few thousand random and directed inputs (command lines from the tables,
mutated and cut lines, noise, packets, checksum toggles, resets, queue filling, halts, K/R, W,
inputs asserted) with their times, and what the unit did: the bytes and times of every answer
and a digest of its observable state (position, queue, ST0..ST6, INTA/RUN, index, modal
values, EEPROM, deadlines...) and of the vectors its executor finished (times, speeds) after
each input. The test replays the inputs against today's unit and requires the same
observations.

Re-record (only for a deliberate change of behaviour): ``python tests/test_unit_split.py``
(with ``PYTHONPATH`` at the tree whose unit is to be recorded).
"""

from __future__ import annotations

import hashlib
import json
import lzma
import random
import sys
from pathlib import Path
from typing import Any

import pytest

from conform.families.gve.spec import load_spec
from conform.families.gve.unit import Unit

FIXTURE = Path(__file__).parent / "data" / "unit_transcripts.jsonl.xz"


def _b(s: str) -> bytes:
    return s.encode("latin-1")


def _s(b: bytes) -> str:
    return b.decode("latin-1")


def _state(unit: Unit) -> bytes:
    """Everything a user of the unit can read."""
    return repr((unit.now, unit.position, unit.queue_len, tuple(unit.status(n) for n in range(7)),
                 unit.inta, unit.run, unit.checksum_on, unit.index, unit.outputs, unit.spindle,
                 sorted(unit.modal.items()), unit.deaf, unit.mpg, unit.last_exchange,
                 unit.next_deadline(), unit.input_level(1), unit.input_level(2), unit.eeprom,
                 unit.executor.running, unit.executor.braking)).encode()


CHECK_EVERY = 16
"""A transcript keeps the digest of the unit's states so far after every this many inputs."""


class Observer:
    """Drives a unit through recorded inputs; a chained digest of its state after each one."""

    def __init__(self, unit: Unit) -> None:
        self.unit = unit
        self.chain = hashlib.blake2b(digest_size=8)

    def step(self, op: list[Any]) -> Any:
        if self.unit.executor.log is None:  # a J makes a new executor
            self.unit.executor.log = []
        got = apply(self.unit, op)
        self.chain.update(_state(self.unit))
        log = self.unit.executor.log
        if log:  # the vectors that finished: when, at what speeds, starved or not
            self.chain.update(repr(log).encode())
            log.clear()
        return got

    def digest(self) -> str:
        return self.chain.hexdigest()


def apply(unit: Unit, op: list[Any]) -> Any:
    """Run one recorded input on ``unit``; what it returned (JSON-ready)."""
    kind = op[0]
    if kind == "x":
        t_ans, out = unit.exchange(_b(op[2]), op[1])
        got: Any = [t_ans, _s(out)]
    elif kind == "r":
        unit.receive(_b(op[2]), op[1])
        got = None
    elif kind == "p":
        got = [[due, _s(b)] for due, b in unit.poll(op[1])]
    elif kind == "i":
        unit.set_input(op[1], op[2], op[3], op[4])
        got = None
    elif kind == "l":
        unit.set_level(op[1], op[2], op[3], op[4])
        got = None
    else:
        raise ValueError(f"unknown op {kind!r}")
    return got


def make_unit(spec: Any, session: dict[str, Any]) -> Unit:
    return Unit(spec.variant(session["variant"]), spec.dialect(session["dialect"]),
                t0=session.get("t0", 0.0), **session.get("options", {}))


# ------------------------------------------------------------------------------ recording
def _scripts(naxes: int, axes: tuple[str, ...]) -> list[list[str]]:
    """Directed command sequences (bodies after ``!0``), one family of behaviour each."""
    z = ",0" * (naxes - 2)
    ax = axes[0]
    return [
        [f"L1000,0{z}", "F", "P", "H", "F", "G", "F", "P4"],
        [f"C500,500{z}", f"C-500,0{z}", "K", f"L10,10{z}", "F", "R", "R", "F", "D", "F"],
        ["SW0,FF", "SW2,00", "F", "SR0", "SR4", "SR6", "G", "SW0,00", "SW6,80", "SW6,00"],
        ["%+", "?", "Q", "@", ">", "%-", "@"],
        ["*S", f"C1,2{z}", "B20000", f"C3,4{z}", "*E3", "*S", "V100", "*E1", "*E0"],
        ["V125000", "A1000", "B125000", "T24", "$100", "XM200", "XA", "XU", "XD", "VK", "VN",
         f"VL{','.join(['5000'] * naxes)}"],
        [f"W{ax},5000,1000,300,500", "P4", f"W{ax},-100,1000,50,500", "N", f"N{ax}123", "PF"],
        ["Y+", f"C5,5{z}", "Y&", "F", "Y-", f"L5,5{z}"],
        ["EW10,55", "ER10", "EFW20,1.5", "EFR20", "EUW30,7", "EUR30", "EFW20,3FC00000"],
        ["O0,0F", "I1", "I2", "SR3", "SW1,C0", "SW3,C0"],
        ["J", "?"],
        [f"C100000,-100000{z}", "H", "F", f"C1,1{z}", "G", "D", "G"],
    ]


def _record_session(spec: Any, variant: Any, choices: dict[str, str], rng: random.Random,
                    steps: int, options: dict[str, Any]) -> dict[str, Any]:
    from conform.families.gve.protocol.checksum import append_checksum
    from conform.families.gve.testing.fuzz import _noise, line_pool, recovery_frames

    dialect = spec.dialect(choices)
    session = {"variant": variant.id, "dialect": choices, "t0": 0.0, "options": options}
    unit = make_unit(spec, session)
    obs = Observer(unit)
    term = b"\r\n" if dialect["A1"] == "crlf" else b"\r"
    addr = b"!%d" % variant.interpolator_address
    pool = line_pool(spec, variant, spec.dialect(), rng, 150)
    scripts = _scripts(len(variant.axes), variant.axes)
    z = b",0" * (len(variant.axes) - 2)
    fill = [b"C%d,%d" % (10 * (i % 7) - 30, i % 5) + z for i in range(variant.queue + 3)]
    ports = [(1, b) for b in variant.input_bits.get("port1", ())] + [
        (2, b) for b in variant.input_bits.get("port2", ())]
    ops: list[list[Any]] = []
    seen: list[Any] = []
    digests: list[list[Any]] = []
    t = 0.0

    def frame(body: bytes) -> bytes:
        on = unit.checksum_on if rng.random() < 0.9 else not unit.checksum_on
        return (append_checksum(body) if on else body) + term

    def run(op: list[Any]) -> None:
        nonlocal t
        t = round(t, 6)  # short numbers in the file; any time will do
        if op[0] in "xrp":
            op[1] = t
        elif op[0] in "il":
            op[4] = t
        ops.append(op)
        seen.append(obs.step(op))
        if len(ops) % CHECK_EVERY == 0:
            digests.append([len(ops), obs.digest()])

    def send(data: bytes) -> None:
        nonlocal t
        if rng.random() < 0.7:
            run(["x", t, _s(data)])
            t = max(t, seen[-1][0])
        else:  # in pieces, then what is due
            cuts = sorted(rng.sample(range(len(data) + 1), min(2, len(data) + 1)))
            for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True):
                if a < b:
                    run(["r", t, _s(data[a:b])])
                    t += rng.choice((0.0, 0.0003, 0.003, 0.15))
            run(["p", t])

    def mutate(f: bytes) -> bytes:
        i = rng.randrange(len(f) + 1)
        k = rng.randrange(7)
        if k == 0 and f:
            b = bytearray(f)
            b[min(i, len(f) - 1)] ^= 1 << rng.randrange(8)
            return bytes(b)
        if k == 1:
            return f[:i]
        if k == 2:
            return f + f
        if k == 3:
            return f[:i] + rng.choice((b"\r", b"\n")) + f[i:]
        if k == 4:
            return f[:i] + b"9" * rng.choice((21, 300)) + f[i:]
        if k == 5:
            return f[:i] + rng.choice(pool) + term
        return f.replace(b",", b" ,", 1)

    for _ in range(steps):
        r = rng.random()
        if r < 0.45:
            send(frame(rng.choice(pool)))
        elif r < 0.55:
            send(mutate(frame(rng.choice(pool))))
        elif r < 0.60:
            send(_noise(rng, rng.randrange(20)))
        elif r < 0.603:  # fill the queue and beyond
            for body in fill + [b"F", b"@", b">"]:
                send(frame(addr + body))
        elif r < 0.75:
            for body in rng.choice(scripts):
                send(frame(addr + body.encode()))
                t += rng.choice((0.0, 0.001, 0.05))
        elif r < 0.82 and ports:
            port, bit = rng.choice(ports)
            if rng.random() < 0.8:
                run(["i", port, bit, rng.random() < 0.6, t])
            else:
                run(["l", port, bit, rng.random() < 0.5, t])
        elif r < 0.90:
            t += rng.choice((0.01, 0.1, 0.5, 2.5))
            run(["p", t])
        elif r < 0.93:
            n = rng.randrange(5)
            body = [addr + b"*S"] + [rng.choice(pool) for _ in range(n)]
            for b in body + [addr + b"*E%d" % rng.choice((n, n + 1))]:
                send(frame(b))
        elif r < 0.95:
            send(frame(addr + (b"%+" if rng.random() < 0.5 else b"%-")))
        elif r < 0.96:
            send(frame(addr + b"J"))
        elif r < 0.97:
            for f in recovery_frames(variant, dialect):
                send(f)
            t += 2.1
        elif r < 0.98:
            send(addr + b"C" + _noise(rng, 80, one_line=True) + term)
        else:
            run(["p", t])
        t += rng.choice((0.0, 0.0005, 0.002, 0.02, 0.3))
    if not digests or digests[-1][0] != len(ops):
        digests.append([len(ops), obs.digest()])
    return {**session, "ops": ops, "seen": seen, "digests": digests}


def record(path: Path = FIXTURE, seed: int = 13) -> None:
    """Write the transcripts of the unit as it is now (see the module docstring)."""
    from conform.families.gve.testing.fuzz import dialects

    spec = load_spec()
    rng = random.Random(seed)
    configs = dialects(spec, rng, 6)
    sessions = []
    for variant in spec.variants:
        v = spec.variant(variant) if isinstance(variant, str) else variant
        for i, choices in enumerate(configs):
            options: dict[str, Any] = {}
            if i % 5 == 1:
                options["answer_delay"] = 0.0015
            if i % 7 == 2:
                options["fast_path"] = False
            if i % 6 == 3:
                options["switches"] = {v.axes[0]: 400}
                options["switch_release"] = 50
            steps = 400 if not choices else 40
            sessions.append(_record_session(spec, v, choices, rng, steps, options))
    path.parent.mkdir(parents=True, exist_ok=True)
    with lzma.open(path, "wt", encoding="utf-8", preset=9) as fh:
        for s in sessions:
            fh.write(json.dumps(s, separators=(",", ":")) + "\n")


# ------------------------------------------------------------------------------ the tests
PUBLIC = ("checksum_on", "deaf", "eeprom", "encode", "exchange", "executor", "index",
          "input_level", "inta", "last_exchange", "modal", "moving", "mpg", "next_deadline", "now",
          "outputs", "poll", "position", "queue_len", "receive", "run", "set_input", "set_level",
          "spindle", "status")
"""``Unit``'s public names before the split (``docs/unit-model.md``, API)."""


def test_public_api_is_unchanged() -> None:
    assert tuple(n for n in dir(Unit) if not n.startswith("_")) == PUBLIC


def test_every_command_of_the_tables_has_one_handler() -> None:
    """The dispatch covers ``specs/commands.toml`` exactly, each handler on one family module."""
    from conform.families.gve.unit.dispatch import HANDLER_NAMES

    spec = load_spec()
    assert set(HANDLER_NAMES) == set(spec.commands)
    for variant_id in spec.variants:
        unit = Unit(spec.variant(variant_id))
        assert set(unit.handlers) == set(spec.commands)
        for cid, name in HANDLER_NAMES.items():
            owner = next(c for c in type(unit).__mro__ if name in vars(c))
            assert owner is not Unit and owner.__module__ != Unit.__module__, (cid, owner)
            assert unit.handlers[cid].__func__ is vars(owner)[name], cid


def _sessions() -> list[dict[str, Any]]:
    with lzma.open(FIXTURE, "rt", encoding="utf-8") as fh:
        return [json.loads(line) for line in fh]


def test_fixture_is_substantial() -> None:
    sessions = _sessions()
    ops = sum(len(s["ops"]) for s in sessions)
    answered = sum(1 for s in sessions for got in s["seen"] if got and got[-1])
    assert {s["variant"] for s in sessions} == set(load_spec().variants)
    assert len(sessions) >= 150 and ops >= 30_000 and answered >= 15_000


@pytest.mark.parametrize("part", range(4))
def test_replay_is_byte_identical(part: int) -> None:
    spec = load_spec()
    for session in _sessions()[part::4]:
        obs = Observer(make_unit(spec, session))
        checks = iter(session["digests"])
        at, digest = next(checks)
        where = f"{session['variant']} {session['dialect']} {session['options']}"
        for i, (op, want) in enumerate(zip(session["ops"], session["seen"], strict=True)):
            got = json.loads(json.dumps(obs.step(op)))
            if got != want:
                pytest.fail(f"{where} input {i} {op!r:.120}: got {got!r:.300}, "
                            f"recorded {want!r:.300}")
            if i + 1 == at:
                if obs.digest() != digest:
                    pytest.fail(f"{where}: the state differs within inputs {at - CHECK_EVERY}"
                                f"..{at - 1} (last {op!r:.120})")
                at, digest = next(checks, (None, None))
        assert at is None, f"{where}: digests beyond the inputs"


if __name__ == "__main__":
    record()
    print(f"wrote {FIXTURE} ({FIXTURE.stat().st_size:,} bytes)", file=sys.stderr)
