"""Directed checks generated from the tables, and the manuals' worked examples as golden checks.

For every command of the variant: a valid form, invalid syntax, wrong field counts, each range edge
and one past it, "not while running", and the same valid form with checksums on and with a wrong
checksum; for commands the variant lacks, that it answers 3 (§14.1). Semantic checks cover what
single forms cannot (queue capacity, the @ index, HALT/GO, position read-back, status words).

Ids read like the manual: ``gve64-v19/13.5.2/C/queue-full`` = variant / clause / command / form.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from conform.conformance.results import INFO, MUST
from conform.families.gve.conformance.corner_states import corner_checks
from conform.families.gve.conformance.from_state import from_held_checks, from_state_checks
from conform.families.gve.conformance.in_motion import (
    in_motion_checks,
    input_checks,
    st6_checks,
)
from conform.families.gve.conformance.motion_free import (
    SETTLE_S,
    motion_free_checks,
    queue_edge_steps,
    zero_line,
)
from conform.families.gve.conformance.planning import planning_checks
from conform.families.gve.conformance.question_checks import question_checks
from conform.families.gve.conformance.script import ENVIRONMENT, POSITION, Script, Step
from conform.families.gve.protocol import encode_command
from conform.families.gve.protocol.checksum import append_checksum, checksum

RESET = Step(reset=True)
OK, QUEUE_FULL, WATCHDOG, UNKNOWN, SYNTAX, RANGE, NOTHING_TO_GO, RUNNING = 0, 1, 2, 3, 4, 5, 6, 7
ZERO_EXTRA = "0,1,0"  # the vector beyond the queue's capacity: one Y pulse, seen if executed
AT_ONCE_S = 0.05  # tolerance of "the answer is sent at once" (GVE64 §13.7) on a link

# a typical valid value per range name
_TYPICAL = {"velocity": 1000, "pause": 5, "short": 512, "accel": 20, "percent": 100,
            "status_index": 2, "spindle": 0, "packet_count": 1, "uint32": 100, "travel": 100,
            "pulses": 100}
# valid arguments where the typical value would not do (or would be unsafe)
_VALID_ARGS: dict[str, list[Any]] = {
    "ER": [0x05], "EW": [0x05, 0xFF], "EFR": [0x40], "EUR": [0x48], "EFW": [0x40, 1.5],
    "EUW": [0x48, 100], "O": [0, 0xFF], "SR": [2], "SW": [2, 0x00], "Y": ["-"], "%": ["-"],
    "W": ["X", -100, 1000, 100, 500], "N<axis>": ["X", 100], "7V": [0], "*E": [1],
}
_POSITION_CMDS = {"P", "PF", "P4"}
# answers that depend on the unit at hand (its processor id, EEPROM contents, inputs): compared
# by the table's shape on a real unit. `?` is not among them: the firmware string is the
# variant's (tables), compared byte for byte.
_ENV_CMDS = {"Q", "ER", "EFR", "EUR", "I1", "I2"}


def answer_kind(cid: str) -> str:
    return POSITION if cid in _POSITION_CMDS else ENVIRONMENT if cid in _ENV_CMDS else ""


def answer_shape(cmd: Any) -> tuple[tuple[str, int | None], ...]:
    return tuple((f.radix, f.width) for f in cmd.answer)
_RANGE_QUESTIONS = {"velocity": ("A7",)}


@dataclass(frozen=True)
class Check:
    """One check of one variant: a script and what the tables say about it."""

    id: str
    variant: str
    clause: str
    title: str
    script: Script = ()
    level: str = MUST
    questions: tuple[str, ...] = ()
    intent: int | None = None  # the answer code the tables imply for the subject step
    kind: str = "directed"  # directed | example | machine
    na: str | None = None  # why it does not apply to this variant

    @property
    def key(self) -> str:
        parts = self.id.split("/")
        return "/".join(parts[2:]) if len(parts) > 2 else self.id

    @property
    def subject(self) -> str:
        """The command (``V``), open question (``A7``) or behaviour (``queue-full``) checked:
        the same in every variant, where the clause is not (GVE64 §13.5.3, GVE124 §12.5.3)."""
        parts = self.key.split("/")
        return parts[1] if parts[0] == "question" and len(parts) > 1 else parts[0]


def clause_number(clause: str) -> str:
    """``"GVE64 §13.5.2"`` → ``"13.5.2"``."""
    return clause.split("§", 1)[-1].strip() if "§" in clause else clause.replace(" ", "-")


def select(checks: Iterable[Check], patterns: Sequence[str]) -> list[Check]:
    """Checks whose id matches any glob (all when no pattern is given)."""
    checks = list(checks)
    if not patterns:
        return checks
    return [c for c in checks if any(fnmatch.fnmatchcase(c.id, p) or fnmatch.fnmatchcase(c.key, p)
                                     for p in patterns)]


class _Builder:
    def __init__(self, spec: Any, variant: Any, travel: int) -> None:
        self.spec = spec
        self.v = variant
        self.manual = variant.manual
        self.travel = travel
        self.deep = False
        # may the run move axes? Without motion the valid forms of L, C, W and packets carry
        # zero-pulse vectors and zero-length reference moves (docs/conformance.md, "What a
        # default run verifies"): the same answers and framing, without a pulse
        self.motion = True
        self.out: list[Check] = []
        self.range_questions: dict[str, tuple[str, ...]] = {}
        hi = variant.ranges.get("velocity", (0, 0))[1]
        if variant.max_rate < hi:  # A7 rate-limited would lower V, B, VL
            self.range_questions.update(_RANGE_QUESTIONS)
        for q in spec.questions.values():
            if q.range:
                self.range_questions[q.range] = (q.id,)

    # -- clauses and ids ---------------------------------------------------------------------
    def _origin(self, cid: str) -> Any | None:
        """The variant of the same manual that added ``cid`` on top of its base, if any."""
        for other in self.spec.variants.values():
            base = self.spec.variants.get(other.base) if other.base else None
            if base is not None and cid in other.commands and cid not in base.commands:
                if other.manual == self.manual:
                    return other
        return None

    def clause(self, cid: str) -> str:
        cmd = self.spec.commands[cid]
        main = cmd.clause_for(self.manual)
        if not main.startswith(self.manual):
            main = self.v.clause("commands")
        origin = self._origin(cid)
        if cid in self.v.commands and origin is not None and "add_commands" in origin.cite:
            # a command a later firmware added: cite the version clause too (GVE64 §14.1)
            chain, cur = [], self.v
            while cur is not None:
                chain.append(cur.id)
                cur = self.spec.variants.get(cur.base) if cur.base else None
            if origin.id in chain:
                return f"{main}, {origin.cite['add_commands']}"
        return main

    def absent_clause(self, cid: str) -> str:
        base = self.spec.variants.get(self.v.base) if self.v.base else None
        if base is not None and cid in base.commands and "remove_commands" in self.v.cite:
            return self.v.cite["remove_commands"]
        origin = self._origin(cid)
        if origin is not None and "add_commands" in origin.cite:
            return origin.cite["add_commands"]
        return self.v.clause("commands")

    def cid_slug(self, cid: str) -> str:
        return cid

    def add(self, cid: str | None, form: str, title: str, script: Sequence[Step], *,
            clause: str | None = None, intent: int | None = None,
            questions: Sequence[str] = (), kind: str = "directed", na: str | None = None,
            number: str | None = None) -> None:
        clause = clause or (self.clause(cid) if cid else self.v.clause("commands"))
        num = number or clause_number(clause.split(",")[0])
        name = f"{self.v.id}/{num}/{cid}/{form}" if cid else f"{self.v.id}/{num}/{form}"
        qs = tuple(dict.fromkeys(questions))
        self.out.append(Check(name, self.v.id, clause, title, tuple(script),
                              INFO if qs else MUST, qs, intent, kind, na))

    # -- lines -------------------------------------------------------------------------------
    def raw(self, text: str, cs: bool = False, **kw: Any) -> Step:
        body = text.encode("ascii")
        line = (append_checksum(body) if cs else body) + b"\r"
        return Step(line=line, **kw)

    def halt(self, cs: bool = False) -> Step:
        """``H``, waited for as long as the table says (it answers when the brake ends)."""
        return self.raw("!0H", cs, timeout=self.v.commands["H"].answer_within)

    def cmd_step(self, cid: str, args: Sequence[Any], cs: bool = False, address: int | None = None,
                 subject: bool = True, **kw: Any) -> Step:
        spec_cmd = self.v.commands.get(cid) or self._foreign(cid)
        addr = spec_cmd.addresses[0] if address is None else address
        if cid == "7V":
            addr = self.v.spindle_address
        elif addr == 0:
            addr = self.v.interpolator_address
        line = encode_command(self.v, spec_cmd, args, address=addr, checksum_on=cs)
        kind = kw.pop("kind", answer_kind(cid))
        kw.setdefault("timeout", spec_cmd.answer_within)
        if cid == ">":
            kw.setdefault("lines", 2)
        shape = answer_shape(spec_cmd) if kind == ENVIRONMENT else ()
        return Step(line=line, subject=subject, kind=kind, shape=shape, **kw)

    def _foreign(self, cid: str) -> Any:
        """A command this variant lacks, resolved by a variant that has it (for its ranges)."""
        for other in self.spec.variants.values():
            if cid in other.commands:
                return other.commands[cid]
        return self.spec.commands[cid]

    def valid_args(self, cid: str) -> list[Any]:
        if cid in _VALID_ARGS:
            if cid == "W" and not self.motion:
                return ["X", 0, 1000, 0, 500]
            return list(_VALID_ARGS[cid])
        cmd = self.v.commands.get(cid) or self._foreign(cid)
        args: list[Any] = []
        for p in cmd.params:
            if p.per_axis:
                if p.kind == "int":
                    pulses = 100 if self.motion else 0
                    args += [pulses, 0, 0][: max(p.min_count or 3, 1)]
                else:
                    n = len(self.v.axes)
                    args += [_TYPICAL.get(p.range_name or "", 1000)] * n
            elif p.kind == "sign":
                args.append(p.choices[-1])
            elif p.kind == "axis":
                args.append("X")
            else:
                args.append(_TYPICAL.get(p.range_name or "", p.lo if p.lo is not None else 0))
        return args

    # -- state setups ------------------------------------------------------------------------
    def running(self, cs: bool = False) -> list[Step]:
        """A long, slow C vector: the unit is RUN=1 for a good while."""
        return [self.raw("!0V10", cs), self.raw(f"!0C{self.travel},0,0", cs)]

    def held(self, cs: bool = False) -> list[Step]:
        """INTA=1 with a zero-pulse vector held for G (GVE64 §13.5.9): H with nothing
        running, then ``C0,0,0``; no axis moves."""
        return [self.halt(cs), self.raw(zero_line(cs), cs)]

    def inta(self, cs: bool = False) -> list[Step]:
        """INTA=1 by HALT during a move (GVE64 §13.5.9)."""
        return [*self.running(cs), self.halt(cs)]

    def position(self, x: int, y: int, z: int) -> list[Step]:
        if "N<axis>" in self.v.commands:
            return [self.raw(f"!0NX{x}"), self.raw(f"!0NY{y}"), self.raw(f"!0NZ{z}")]
        span = max(abs(x), abs(y), abs(z))
        return [self.raw("!0V1000"), self.raw(f"!0L{x},{y},{z}"),
                Step(wait=span / 1000.0 + 1.0)]

    def given(self, names: Sequence[str]) -> tuple[list[Step], bool]:
        steps: list[Step] = []
        cs = False
        for g in names:
            if g == "checksum-on":
                cs = True
            elif g == "queue-full":
                steps += queue_edge_steps(self.v, "", min(20, self.travel))[0][:-1]
            elif g == "inta":  # H sets INTA=1 whether or not a vector runs (§13.5.9)
                steps += self.inta() if self.motion else [self.halt()]
            elif g.startswith("position="):
                x, y, z = (int(t) for t in g.split("=", 1)[1].split(","))
                steps += self.position(x, y, z)
            elif g.startswith("st") and "=" in g:
                word, value = g[2:].split("=")
                steps.append(self.raw(f"!0SW{int(word)},{value}"))
            else:
                raise ValueError(f"examples.toml: unknown given state {g!r}")
        if cs:
            steps.append(self.raw("!0%+"))
        return steps, cs


def _edge_text(kind: str, value: int) -> str | None:
    if kind == "hex":
        return None if value < 0 else "%02X" % value
    return str(value)


def generate(spec: Any, variant_id: str, *, travel: int = 100000,
             deep: bool = False, motion: bool = True) -> list[Check]:
    """Every directed and example check of one variant (nothing runs). ``deep`` (the full
    profile) also tries the range edges of every axis of per-axis parameters."""
    v = spec.variant(variant_id)
    b = _Builder(spec, v, travel)
    b.deep = deep
    b.motion = motion
    universe = [cid for cid in spec.commands]
    for cid in universe:
        if cid in v.commands:
            _command_checks(b, cid)
        else:
            _absent_checks(b, cid)
    _semantic_checks(b)
    from_state_checks(b, {cid: _valid_form(b, cid) for cid in universe if cid in v.commands})
    from_held_checks(b)
    motion_free_checks(b)
    st6_checks(b)
    corner_checks(b)
    input_checks(b)
    in_motion_checks(b)
    planning_checks(b)
    question_checks(b)
    _example_checks(b)
    return b.out


def _command_checks(b: _Builder, cid: str) -> None:
    cmd = b.v.commands[cid]
    # valid form (with its own setup where a bare command would say little)
    form, intent = _valid_form(b, cid)
    valid = [RESET, *form]
    b.add(cid, "valid", f"{cid} in a valid form is accepted", valid, intent=intent,
          questions=_valid_questions(cid))
    # the same with checksums on, and with a wrong one (GVE64 §13.3.2)
    if cid not in ("%",):
        cs_setup, _ = _valid_setup(b, cid, cs=True)
        valid_cs = [RESET, b.raw("!0%+"), *cs_setup, *_valid_steps(b, cid, cs=True)]
        b.add(cid, "checksum", f"{cid} with checksums on: same answer, with a correct checksum",
              valid_cs, intent=intent, questions=_valid_questions(cid))
        bad = _bad_checksum(b, cid)
        if bad is not None:
            b.add(cid, "bad-checksum", f"{cid} with a wrong checksum is not executed",
                  [RESET, b.raw("!0%+"), bad], intent=SYNTAX, questions=("A11",))
    # syntax
    syntax = _syntax_line(b, cid)
    if syntax is not None:
        # a mnemonic shared with a command this variant lacks may be taken for that one
        shared = any(c.mnemonic == cmd.mnemonic and c.id not in b.v.commands
                     for c in b.spec.commands.values())
        b.add(cid, "syntax", f"{cid} with a stray character is a syntax error (4)",
              [RESET, Step(line=syntax, subject=True)], intent=None if shared else SYNTAX)
    # field counts of per-axis parameters
    for p in cmd.params:
        if not p.per_axis:
            continue
        need = p.min_count or len(b.v.axes)
        base = 0 if p.kind == "int" else _TYPICAL.get(p.range_name or "", 1000)
        few = ",".join(str(base) for _ in range(need - 1))
        many = ",".join(str(base) for _ in range(len(b.v.axes) + 1))
        b.add(cid, "fields-few", f"{cid} with {need - 1} fields (fewer than {need})",
              [RESET, b.raw(f"!0{cmd.mnemonic}{few}", subject=True)], intent=SYNTAX,
              questions=("A22",))
        b.add(cid, "fields-many", f"{cid} with {len(b.v.axes) + 1} fields (more than the axes)",
              [RESET, b.raw(f"!0{cmd.mnemonic}{many}", subject=True)], intent=SYNTAX,
              questions=("A22",))
    # range edges
    _range_checks(b, cid)
    # not while running
    if not cmd.while_running:
        b.add(cid, "running", f"{cid} while a vector runs is refused (7)",
              [RESET, *b.running(), b.cmd_step(cid, b.valid_args(cid))], intent=RUNNING,
              questions=("A27",) if cid in ("W", "Y") else ())
    # the spindle address for commands it also answers (GVE64 §13.6)
    if 7 in cmd.addresses and 0 in cmd.addresses and cid not in ("J",):
        b.add(cid, "address-7", f"{cid} at the spindle address (7)",
              [RESET, b.cmd_step(cid, b.valid_args(cid), address=b.v.spindle_address)],
              clause=f"{b.clause(cid)}", questions=("A19",) if b.manual == "GVE124" else (),
              intent=None)


def _valid_form(b: _Builder, cid: str) -> tuple[list[Step], int | None]:
    """A command's valid form after its own setup, and the answer it intends."""
    setup, intent = _valid_setup(b, cid)
    return [*setup, *_valid_steps(b, cid)], intent


def _valid_questions(cid: str) -> tuple[str, ...]:
    return {"G": ("A15",), "@": ("A9", "A10"), ">": ("A9",), "J": ("A17",), "H": ("A24",),
            "Y": ("A9", "A14"), "EFR": ("A9",), "EUR": ("A9",), "EFW": ("A18",),
            "EUW": ("A18",), "W": ("A16",), "L": ("A4",), "*S": ("A12",),
            "*E": ("A12",)}.get(cid, ())


def _valid_setup(b: _Builder, cid: str, cs: bool = False) -> tuple[list[Step], int | None]:
    if cid == "G":
        return (b.inta(cs) if b.motion else b.held(cs)), OK
    if cid == ">":
        return [b.raw("!0V1000", cs)], None
    if cid == "R":
        return [b.raw("!0K", cs)], OK
    if cid in ("H", "J", "@", "?", "Q", "EFR", "EUR", "EFW", "EUW", "Y", "W", "*S", "*E"):
        return [], None
    return [], OK


def _valid_steps(b: _Builder, cid: str, cs: bool = False) -> list[Step]:
    if cid in ("*S", "*E"):
        c = b.cmd_step("C", b.valid_args("C"), cs, answer=False, subject=False)
        # the vector the packet carried is accounted for by the position it reached
        return [b.cmd_step("*S", [], cs, answer=False), c, b.cmd_step("*E", [1], cs),
                Step(wait=1.0 if b.motion else SETTLE_S), b.cmd_step("PF", [], cs, subject=False)]
    if cid == "J":
        return [b.cmd_step("J", [], cs), b.raw("!0?", False, wait=2.2, ready=True)]
    step = b.cmd_step(cid, b.valid_args(cid), cs)
    if cid in ("L", "C", "W"):
        # a move runs its course; zero-pulse vectors (no motion allowed) only need working off
        return [step, Step(wait=1.5 if b.motion else SETTLE_S),
                b.cmd_step("PF", [], cs, subject=False)]
    return [step]


def _bad_checksum(b: _Builder, cid: str) -> Step | None:
    step = b.cmd_step(cid, b.valid_args(cid), cs=True)
    line = step.line[:-1]
    body, tail = line[:-2], line[-2:]
    good = int(tail, 16)
    assert good == checksum(body)
    wrong = b"%02X" % ((good + 1) & 0xFF)
    return Step(line=body + wrong + b"\r", subject=True, timeout=step.timeout)


def _syntax_line(b: _Builder, cid: str) -> bytes | None:
    cmd = b.v.commands[cid]
    addr = b.v.spindle_address if cid == "7V" else b.v.interpolator_address
    if not cmd.params:
        return f"!{addr}{cmd.mnemonic}#\r".encode()
    line = encode_command(b.v, cmd, b.valid_args(cid), address=addr)
    text = line.decode()[:-1]
    # put the stray character inside the first parameter
    head = 2 + len(cmd.mnemonic)
    first = cmd.params[0]
    pos = head + len(first.sep) + (1 if first.kind in ("axis", "sign") else 1)
    return (text[:pos] + "#" + text[pos:] + "\r").encode()


def _range_checks(b: _Builder, cid: str) -> None:
    cmd = b.v.commands[cid]
    args = b.valid_args(cid)
    # where each parameter's value sits in the argument list
    index = 0
    for p in cmd.params:
        at = index
        after = len(cmd.params) - cmd.params.index(p) - 1  # fixed parameters after this one
        index += (len(args) - index - after) if p.per_axis else 1
        if p.kind not in ("int", "uint", "hex") or p.lo is None or p.hi is None:
            continue
        questions = b.range_questions.get(p.range_name or "", ())
        if p.per_axis and b.deep:
            for k in range(1, index - at):
                _edges(b, cid, p, args, at + k, f"range/{p.name}/{b.v.axes[k]}", questions)
        _edges(b, cid, p, args, at, f"range/{p.name}", questions)


def _edges(b: _Builder, cid: str, p: Any, args: list[Any], at: int, prefix: str,
           questions: tuple[str, ...]) -> None:
    """lo, lo-1, hi, hi+1 of the parameter value at ``args[at]``."""
    cmd = b.v.commands[cid]
    edges = [("lo", p.lo, OK), ("lo-1", p.lo - 1, RANGE), ("hi", p.hi, OK),
             ("hi+1", p.hi + 1, RANGE)]
    for name, value, intent in edges:
        if value < 0 and p.kind in ("uint", "hex"):
            intent = SYNTAX  # no digits for a negative number: not a well-formed parameter
        texts = [("%02X" % a if isinstance(a, int) and q.kind == "hex" else str(a))
                 for a, q in zip(args, _expand(cmd, args), strict=True)]
        texts[at] = _edge_text(p.kind, value) or "-1"
        line = _join(b, cmd, texts)
        steps: list[Step] = [RESET]
        if cid == "*E":  # the count closes a packet
            steps.append(b.cmd_step("*S", [], answer=False, subject=False))
            intent = intent if name != "hi" else SYNTAX  # count mismatch (A12)
        kind = answer_kind(cid) if intent == OK else ""
        steps.append(Step(line=line, subject=True, timeout=cmd.answer_within, kind=kind,
                          shape=answer_shape(cmd) if kind == ENVIRONMENT else ()))
        b.add(cid, f"{prefix}/{name}",
              f"{cid} {p.name}={value} ({'inside' if intent == OK else 'outside'} "
              f"{p.lo}..{p.hi})", steps, intent=intent, questions=questions)


def _expand(cmd: Any, args: list[Any]) -> list[Any]:
    """The parameter spec of each argument value."""
    out = []
    fixed_after = 0
    for i, p in enumerate(cmd.params):
        if p.per_axis:
            fixed_after = len(cmd.params) - i - 1
            n = len(args) - len(out) - fixed_after
            out += [p] * n
        else:
            out.append(p)
    return out


def _join(b: _Builder, cmd: Any, texts: list[str]) -> bytes:
    addr = b.v.spindle_address if cmd.id == "7V" else b.v.interpolator_address
    out = f"!{addr}{cmd.mnemonic}"
    specs = _expand(cmd, texts)
    prev = None
    for text, p in zip(texts, specs, strict=True):
        out += (p.sep if p is not prev else ",") + text
        prev = p
    return (out + "\r").encode()


def _absent_checks(b: _Builder, cid: str) -> None:
    clause = b.absent_clause(cid)
    step = b.cmd_step(cid, b.valid_args(cid))
    b.add(cid, "absent", f"{cid} is not in {b.v.id}: unknown command (3)",
          [RESET, Step(line=step.line, subject=True)], clause=clause, intent=UNKNOWN)
    na = f"{b.v.id} has no {cid} ({clause})"
    for form in ("valid", "checksum", "syntax"):
        b.add(cid, form, f"{cid} {form}", [], clause=clause, na=na)


def _semantic_checks(b: _Builder) -> None:
    v = b.v
    # queue capacity (GVE64 §13.5.2; A5): `queue` vectors fit while one runs, the next answers
    # 1; F shows it. Whether the vector beyond was taken is read back once the queue has run:
    # answered 0 and never executed is a FAIL (§13.7 code 1), whatever A5 says
    fill, drain = queue_edge_steps(v, f"!0C{ZERO_EXTRA}", min(20, b.travel))
    b.add("C", "queue-full", f"the queue holds {v.queue} C vectors with one running; the next "
          "answers 1; the position read back after the queue has run shows what was executed",
          [RESET, *fill, b.cmd_step("F", [], subject=False), Step(wait=drain),
           b.cmd_step("F", [], subject=False), b.cmd_step("PF", [], subject=False)],
          clause=f"{b.clause('C')}, {v.clause('queue')}", intent=QUEUE_FULL, questions=("A5",))
    # the @ index (GVE64 §13.5.13; A10)
    b.add("@", "advance", "@ counts the commands received",
          [RESET, b.cmd_step("@", []), b.raw("!0V1000"), b.raw("!0A20"), b.raw("!0V1001"),
           b.cmd_step("@", [])], questions=("A9", "A10"))
    b.add("@", "errors", "@ after rejected lines (unknown, syntax, range)",
          [RESET, b.raw("!0V1000"), b.raw("!0ZZ"), b.raw("!0V1#"), b.raw("!0V9"),
           b.cmd_step("@", [])], questions=("A9", "A10"))
    # > repeats the last command and its answer (GVE64 §13.5.13; A9)
    b.add(">", "after-error", "> after an out-of-range command repeats its answer",
          [RESET, b.raw("!0V9"), b.cmd_step(">", [])], questions=("A9",))
    # GO with nothing to start (GVE64 §13.7, §13.5.9; A15)
    b.add("G", "nothing-to-go", "G with nothing stopped answers 6",
          [RESET, b.cmd_step("G", [])], intent=NOTHING_TO_GO, questions=("A15",),
          clause=f"{b.clause('G')}")
    b.add("G", "nothing-left", "G with INTA set (SW6,80) but nothing queued answers 6",
          [RESET, b.raw("!0SW6,80"), b.cmd_step("G", [])], intent=NOTHING_TO_GO)
    b.add("G", "resume", "G finishes the halted vector: the position reaches its end",
          [RESET, b.raw("!0V1000"), b.raw("!0C2000,0,0"), Step(wait=0.5),
           b.halt(), b.cmd_step("G", []), Step(wait=4.0),
           b.cmd_step("PF", [], subject=False)], intent=OK)
    # HALT during a move: INTA on the answer and afterwards (GVE64 §13.5.9, §13.7)
    b.add("H", "running", "H brakes a move; the answer and the next carry INTA",
          [RESET, *b.running(), b.cmd_step("H", []), b.cmd_step("SR", [6], subject=False),
           b.raw("!0V1000"), b.cmd_step("PF", [], subject=False)], questions=("A24",))
    # position read-back after moves, every axis separately (GVE64 §13.5.6)
    moves = [(1, -2, 3, 4)[: len(v.axes)], (300, 0, -200, 0)[: len(v.axes)]]
    for i, m in enumerate(moves):
        vec = ",".join(str(x * 100) for x in m)
        span = max(abs(x) * 100 for x in m)
        steps = [RESET, b.raw("!0V5000"), b.raw(f"!0L{vec}"), Step(wait=span / 5000 + 1.0)]
        for pc in ("P", "PF", "P4"):
            if pc in v.commands:
                steps.append(b.cmd_step(pc, []))
        b.add("L", f"position-{i + 1}", f"L{vec} then P/PF/P4 read every axis", steps,
              clause=f"{b.clause('L')}, {b.clause('PF').split(',')[0]}",
              questions=("A4",))
    if "N<axis>" in v.commands:
        steps = [RESET]
        for k, axis in enumerate(v.axes):
            steps.append(b.raw(f"!0N{axis}{(k + 1) * 111 * (-1) ** k}"))
        for pc in ("P", "PF", "P4"):
            if pc in v.commands:
                steps.append(b.cmd_step(pc, []))
        b.add("N<axis>", "read-back", "N<axis> sets each counter; P/PF/P4 read them", steps)
    b.add("N", "zero", "N zeroes every counter",
          [RESET, *b.position(5, -6, 7), b.raw("!0N"), b.cmd_step("PF", [])])
    # status words written and read back (GVE64 §13.5.12; A20)
    for w in range(0, 7):
        value = "A5" if w != 6 else "00"
        b.add("SR", f"word-{w}", f"SW{w},{value} then SR{w}",
              [RESET, b.raw(f"!0SW{w},{value}"), b.cmd_step("SR", [w]) if w in v.status_words
               else b.raw(f"!0SR{w}", subject=True)],
              questions=("A20",) if w not in v.status_words else ())
    # EEPROM byte written and read back (GVE64 §13.5.10)
    b.add("EW", "read-back", "EW10,5A then ER10 reads 5A",
          [RESET, b.raw("!0EW10,5A"), b.cmd_step("ER", [0x10], subject=True, kind="")])
    # K/R: the manual's recovery sequence (GVE64 §13.5.9)
    b.add("K", "recovery", "the manual's recovery example: H, K, L out and back, R, G",
          [RESET, b.raw("!0V1000"), b.raw(f"!0C{b.travel},0,0"), b.raw(f"!0C{b.travel},0,0"),
           Step(wait=0.2), b.halt(), b.raw("!0SR6"), b.raw("!0K", subject=True),
           b.raw("!0L0,0,-1000"), Step(wait=3.0), b.raw("!0L0,0,1000"), Step(wait=3.0),
           b.raw("!0R", subject=True), b.raw("!0V500"), b.raw("!0XA"), b.raw("!0G"),
           b.raw("!0SR6"), b.cmd_step("PF", [], subject=False)], questions=("A4",))
    # inputs: an enabled interrupt brakes and sets INTA (GVE64 §13.5.12)
    b.add("SR", "interrupt", "an enabled input interrupt stops the move and sets INTA and ST4",
          [RESET, b.raw("!0SW0,01"), *b.running(), Step(wait=0.2),
           Step(input=(1, 0, True)), Step(wait=1.0), b.cmd_step("SR", [4]),
           b.raw("!0SR6"), b.raw("!0V1000"), Step(input=(1, 0, False))], questions=("A24",))
    b.add("I1", "inputs", "I1 shows an active input",
          [RESET, Step(input=(1, v.input_bits["port1"][-1], True)), b.cmd_step("I1", []),
           Step(input=(1, v.input_bits["port1"][-1], False))])  # inputs are physical: released
    # reset (GVE64 §13.4)
    b.add("J", "reset-state", "J restores the reset state: position, checksum off, V",
          [RESET, *b.position(10, 20, 30), b.raw("!0%+"), b.raw("!0J", cs=True),
           b.raw("!0PF", wait=2.2, ready=True, kind=POSITION, subject=True), b.raw("!0@")],
          questions=("A17", "A10"))
    # spindle: address 7 V is not address 0 V (GVE64 §13.6)
    if "7V" in v.commands:
        b.add("7V", "not-0V", "!7V500 is the spindle; !0V500 the interpolator's velocity",
              [RESET, b.raw("!7V500", subject=True), b.raw("!0V5", subject=True)])
    # unknown address: silence (A23)
    a23 = b.spec.questions["A23"].clauses
    b.add(None, "unknown-address", "a line for another address gets no answer",
          [RESET, b.raw("!3V100", subject=True), b.raw("!0V100")], questions=("A23",),
          clause=next((c for c in a23 if c.startswith(b.manual)), a23[0]))
    # the manual's timing words (GVE64 §13.7, GVE124 §12.6): answers are sent at once (HALT's
    # once the unit has stopped); a line that does not arrive complete is answered 2 when the
    # watchdog runs out (A13). Tolerance: the USB converter latency the manuals name (1–16 ms
    # each way) and the unit's own time, ±AT_ONCE_S.
    words = b.spec.questions["A13"].clauses
    timing = next((c for c in words if c.startswith(b.manual)), words[0])
    # a mnemonic no firmware has: unknown command (3)
    b.add(None, "unknown-command", "a mnemonic no firmware has is an unknown command (3)",
          [RESET, b.raw("!0ZZ", subject=True)], clause=timing, intent=UNKNOWN,
          questions=("A21",))
    b.add(None, "timing/at-once", "answers come at once (HALT's too when nothing moves)",
          [RESET, b.cmd_step("V", [1000], tolerance=AT_ONCE_S),
           b.cmd_step("F", [], tolerance=AT_ONCE_S),
           b.cmd_step("?", [], tolerance=AT_ONCE_S),
           b.cmd_step("H", [], tolerance=AT_ONCE_S)], clause=timing)
    b.add(None, "timing/watchdog", "a line without its CR is answered 2 when the watchdog runs "
          "out", [RESET, Step(line=b"!0V100", subject=True, timeout=1.5, tolerance=AT_ONCE_S),
                  b.raw("!0V100")],
          clause=timing, intent=WATCHDOG, questions=("A13",))
    # checksum missing while on (A11)
    b.add("%", "missing-checksum", "with checksums on, a line without one is refused",
          [RESET, b.raw("!0%+"), b.raw("!0V1000", subject=True)], intent=SYNTAX,
          questions=("A11",))


def _example_checks(b: _Builder) -> None:
    for ex in b.spec.examples:
        clause = next((c for c in ex.clauses if c.startswith(b.manual + " ")), ex.clauses[0])
        name = ex.id.split("/", 1)[1]
        if ex.kind == "checksum":
            # the manual's checksummed line, sent to a unit with checksums on
            assert ex.line is not None
            steps = [RESET, b.raw("!0%+"), Step(line=ex.line.encode() + b"\r", subject=True)]
            b.add(None, name, f"{ex.line} (the manual's checksum) is accepted", steps,
                  clause=clause, kind="example", number=clause_number(clause))
            continue
        setup, _ = b.given(ex.given)
        steps = [RESET, *setup]
        sends = list(ex.send)
        for i, text in enumerate(sends):
            last = i == len(sends) - 1
            packet_inner = ex.kind == "packet" and not last
            kind = POSITION if text[2:4] in ("PF", "P4") or text[2:3] == "P" else ""
            steps.append(Step(line=text.encode() + b"\r", answer=not packet_inner,
                              subject=True, kind=kind))
        if "queue-full" in ex.given:  # was the vector beyond the capacity executed?
            drain = queue_edge_steps(b.v, "", min(20, b.travel))[1]
            steps += [Step(wait=drain), b.cmd_step("PF", [], subject=False)]
        na = None
        if b.manual != "GVE64" and not any(c.startswith(b.manual) for c in ex.clauses):
            na = f"{ex.id} is a GVE64 example"
        b.add(None, name, f"{' '.join(ex.send)} → {' '.join(ex.expect)}", steps, clause=clause,
              kind="example", number=clause_number(clause), na=na,
              intent=int(ex.expect[0][0], 16) & 7 if ex.expect else None,
              questions=("A5",) if "queue-full" in ex.given else ())
