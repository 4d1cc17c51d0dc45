"""The answer grammar (GVE64 §13.7, GVE124 §12.6), built from the tables: what a well-formed
answer to a line may look like, so that a fuzzer or a test can judge a unit's answers without
asking the unit.

An answer line is one hex digit (bit 3 INTA, bits 2..0 the error code of specs/gve/errors.toml), then
``,field`` for each field of the command's ``answer`` row (specs/gve/commands.toml) when the code is
0, then ``,XX`` (GVE64 §13.3.2) while checksums are on, then CR. ``>`` may send the repeated line
before its answer (A9), ``J`` answers ``0`` or nothing (A17), ``*S`` nothing, ``*E`` ``code,count``
(GVE64 §13.3.3).
"""

from __future__ import annotations

import re

from conform.families.gve.protocol.answers import answer_digit, encode_answer
from conform.families.gve.protocol.checksum import checksum
from conform.families.gve.protocol.commands import Command, Rejection
from conform.families.gve.spec.model import AnswerField, Dialect, Spec, Variant

_TEXT = rb"[\x20-\x2b\x2d-\x7e]"  # printable ASCII without the field separator
_FLOAT = rb"(?:-?[0-9]+(?:\.[0-9]+)?(?:e[-+][0-9]+)?|-?inf|nan)"  # EFR's %g (A9)
_ANY_FIELDS = re.compile(rb"(?:," + _TEXT + rb"*)*\Z")
_COUNT = re.compile(rb"(?:,[0-9]+)?\Z")
_NONE = re.compile(rb"\Z")
_ECHO = re.compile(rb"![0-9][^\r]*\Z")
_TAIL = re.compile(rb",([0-9A-F]{2})\Z")
_SPECIAL = frozenset((">", "*S", "J", "%", "*E"))

# Code 7 ("not while running") beyond the rows the errors table names and the rows with
# while_running = false: vectors under MPG (A14), W and Y during a job (A27), W while INTA is set
# (docs/unit-model.md). K twice and R are in the table's raised_by.
_RUNNING_TOO = frozenset(("C", "L", "W", "Y"))


def _field(f: AnswerField, dialect: Dialect, command_id: str) -> bytes:
    if command_id == "@" and dialect["A9"] == "hex-index":
        return rb"[0-9A-F]{2}"
    if f.radix == "dec":
        return rb"-?[0-9]+"
    if f.radix == "hex":
        return rb"[0-9A-F]{%d}" % f.width if f.width else rb"[0-9A-F]+"
    if f.radix == "float":
        return _FLOAT
    return _TEXT + (rb"{%d}" % f.width if f.width else rb"*")


class AnswerGrammar:
    """Judge the bytes a unit answered to one line (:meth:`check`) or one answer line."""

    def __init__(self, spec: Spec, variant: Variant, dialect: Dialect) -> None:
        self.dialect = dialect
        self.inta_any_code = dialect["A24"] == "every-answer"
        self.echo = dialect["A9"] != "repeat-answer-only"
        self.j_answers = dialect["A17"] == "answer-then-deaf"
        self.fields: dict[str, re.Pattern[bytes]] = {}
        self.codes: dict[str, frozenset[int]] = {}
        self._exact: dict[tuple[object, bool], frozenset[bytes]] = {}
        everyone = {e.code for e in spec.errors.values() if "*" in e.raised_by}
        for cid, cmd in variant.commands.items():
            body = b"".join(b"," + _field(f, dialect, cid) for f in cmd.answer)
            self.fields[cid] = (_COUNT if cid == "*E" else
                                re.compile(body + rb"\Z") if body else _NONE)
            codes = set(everyone)
            codes.update(e.code for e in spec.errors.values() if cid in e.raised_by)
            if not cmd.while_running or cid in _RUNNING_TOO:
                codes.add(7)
            if cid == "*E":  # the packet's first (or last, A12) error, whatever it was
                codes.update(spec.errors)
            self.codes[cid] = frozenset(codes)

    # ------------------------------------------------------------------------------------
    def check_line(self, line: bytes, cs: bool | None, name: str | None = None,
                   code: int | None = None) -> str | None:
        """None when ``line`` (no CR) is a well-formed answer; else what is wrong.

        ``cs``: checksums on (True), off (False) or not known (None: either form). ``name``:
        the command answered (None: any); ``code``: the one error code expected.
        """
        if cs is None:
            problem = self.check_line(line, False, name, code)
            if problem is None or _TAIL.search(line) is None:
                return problem
            return self.check_line(line, True, name, code)
        if cs:
            m = _TAIL.search(line)
            if m is None:
                return f"{line!r}: checksums are on but the answer has no ,XX"
            if checksum(line[: m.start() + 1]) != int(m.group(1), 16):
                return f"{line!r}: checksum {m.group(1).decode()} is wrong"
            line = line[: m.start()]
        if not line:
            return "empty answer line"
        digit = answer_digit(line[0])
        if digit is None:
            return f"{line!r}: the first byte is not an answer digit"
        got = digit & 7
        if digit & 8 and got and not self.inta_any_code:
            return f"{line!r}: INTA on an error answer (A24 ok-only)"
        rest = line[1:]
        if code is not None and got != code:
            return f"{line!r}: code {got}, expected {code}"
        if name is None:
            pattern = _ANY_FIELDS if got == 0 else _COUNT
        else:
            if got not in self.codes[name]:
                return f"{line!r}: code {got} is not one {name} answers (specs/gve/errors.toml)"
            pattern = self.fields[name] if got == 0 or name == "*E" else _NONE
        if pattern.match(rest) is None:
            return f"{line!r}: fields do not fit the answer of {name or 'any command'}"
        return None

    def check(self, out: bytes, cs: bool | None, verdict: Command | Rejection | None,
              silent: bool = False) -> str | None:
        """Judge everything answered to one complete line.

        ``verdict``: the line as the tables read it (None: not known, every line is judged on
        its own); ``silent``: the line must get no answer (deaf after J, inside a packet).
        """
        if verdict is not None and not silent and cs is not None:
            key = verdict.name if verdict.__class__ is Command else verdict.code
            exact = self._exact.get((key, cs))
            if exact is None:
                exact = self._exact[(key, cs)] = self._exact_answers(verdict, cs)
            if out in exact:
                return None
        if out and not out.endswith(b"\r"):
            return f"{out[-20:]!r}: the answer does not end in CR"
        lines = out.split(b"\r")[:-1]
        if silent:
            return None if not lines else f"{out[:40]!r}: an answer where silence is due"
        if verdict is None:
            return self._free(lines, cs)
        name = verdict.name
        if verdict.__class__ is Rejection:
            if verdict.code is None:
                return None if not lines else f"{out[:40]!r}: answered a line the unit ignores"
            if len(lines) != 1:
                return f"{out[:40]!r}: {len(lines)} answer lines to a rejected line"
            return self.check_line(lines[0], cs, None, verdict.code)
        if name == ">":
            if len(lines) == 2 and self.echo:
                if _ECHO.match(lines[0]) is None:
                    return f"{lines[0]!r}: the repeated line is not a command line"
                return self.check_line(lines[1], cs)
            if len(lines) != 1:
                return f"{out[:60]!r}: {len(lines)} lines answered to >"
            return self.check_line(lines[0], cs)
        if name == "*S":
            return None if not lines else f"{out[:40]!r}: *S is not answered"
        if name == "J":
            if not self.j_answers:
                return None if not lines else f"{out[:40]!r}: J is silent (A17)"
            if len(lines) != 1:
                return f"{out[:40]!r}: J answers one 0 (A17)"
            return self.check_line(lines[0], cs, "J", 0)
        if len(lines) != 1:
            return f"{out[:60]!r}: {len(lines)} answer lines to {name}"
        if name == "%":  # the answer goes out under the state the command set
            cs = None
        return self.check_line(lines[0], cs, name)

    def _exact_answers(self, verdict: Command | Rejection, cs: bool) -> frozenset[bytes]:
        """Every complete answer without fields that :meth:`check` accepts for this verdict (a
        shortcut for the common answers; anything else takes the full path)."""
        if verdict.__class__ is Rejection:
            if verdict.code is None:
                return frozenset((b"",))
            codes: frozenset[int] = frozenset((verdict.code,))
        elif verdict.name in _SPECIAL:
            return frozenset()
        else:
            codes = self.codes[verdict.name]
        out = set()
        for code in codes:
            if code == 0 and self.fields[verdict.name] is not _NONE and verdict.__class__ is Command:
                continue  # its fields take the full path
            for inta in (False, True):
                if inta and code and not self.inta_any_code:
                    continue
                out.add(encode_answer(code, inta, checksum_on=cs))
        return frozenset(out)

    def _free(self, lines: list[bytes], cs: bool | None) -> str | None:
        """Answers to bytes that were not one known line: each line well-formed on its own,
        an echoed line (``>``) followed by an answer."""
        after_echo = False
        for line in lines:
            if self.echo and line[:1] == b"!" and not after_echo:
                if _ECHO.match(line) is None:
                    return f"{line!r}: the repeated line is not a command line"
                after_echo = True
                continue
            after_echo = False
            problem = self.check_line(line, cs)
            if problem is not None:
                return problem
        return f"{lines[-1]!r}: a repeated line without its answer" if after_echo else None
