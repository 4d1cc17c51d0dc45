"""What every grbl check runs on: a session with the unit (one line written, its answer lines
read, realtime bytes kept apart), the check record and its outcome. Kept apart from the checks
themselves so that every module of checks can build on it without importing the others."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from conform.conformance.results import MUST
from conform.conformance.runner import RunOptions
from conform.conformance.target import HarnessError
from conform.families.grbl.protocol.codec import split_unit
from conform.families.grbl.spec.load import GrblSpec, Variant

STOP = (b"!", b"\x18")
_SETTING = re.compile(r"^\$(\d+)=(.*)$")
_NUM = re.compile(r"-?\d+\.\d+")
_WRITE = re.compile(rb"\$(\d+|RST)=")


@dataclass
class Talk:
    lines: list[str]
    t: float

    def kinds(self, spec: GrblSpec) -> list[str]:
        return [spec.classify(x)[0] if x else "blank" for x in self.lines]


class Session:
    """Drives one target for the checks: fresh state, send and collect grbl lines."""

    def __init__(self, target: Any, spec: GrblSpec, v: Variant) -> None:
        self.target = target
        self.spec = spec
        self.v = v
        self.original: dict[int, str] | None = None   # a real unit's settings before the run
        self.dirty = False
        self.options = RunOptions()   # the run's profile, seed and budgets (the runner's)
        self.max_steps: int | None = None   # --max-steps: the bound on every random move

    def settings(self) -> dict[int, str]:
        out = {}
        for x in self.talk(b"$$\n").lines:
            m = _SETTING.match(x)
            if m:
                out[int(m.group(1))] = m.group(2)
        return out

    def restore(self) -> None:
        """Put back every setting a check changed on a real unit (they live in EEPROM)."""
        if not self.dirty or self.original is None:
            return
        self.dirty = False
        self.talk(b"\x18", banner=True)
        now = self.settings()
        for n, value in self.original.items():
            if now.get(n) != value:
                self.talk(f"${n}={value}\n".encode())

    def fresh(self) -> None:
        t = self.target
        if t.emulated:
            t.reset()
            t.begin_log()
            self.collect(banner=True, timeout=0.5)
            return
        t.begin_log()
        got = self.talk(b"\x18", banner=True, timeout=3.0)
        if not any(x.startswith("Grbl ") for x in got.lines):
            raise HarnessError("no banner after a soft reset (Ctrl-X)")
        if any("unlock" in x for x in got.lines):
            self.talk(b"$X\n")
        if self.original is None:
            self.original = self.settings()

    def talk(self, data: bytes, *, answers: int | None = None, banner: bool = False,
             status: int | None = None, timeout: float = 2.0, linger: float = 0.05) -> Talk:
        if answers is None:
            answers = data.count(b"\n")
        if _WRITE.search(data):
            self.dirty = True
        if status is None:
            status = data.count(b"?") if not answers else 0
        t = self.target
        try:
            t.send(data)
        except Exception as exc:  # noqa: BLE001 - any link failure is the harness's
            raise HarnessError(str(exc)) from None
        return self.collect(answers=answers, banner=banner or b"\x18" in data, status=status,
                            timeout=timeout, linger=linger)

    def collect(self, *, answers: int = 0, banner: bool = False, status: int = 0,
                timeout: float = 2.0, linger: float = 0.05) -> Talk:
        t = self.target
        buf = b""
        lines: list[str] = []
        deadline = t.now() + timeout
        done_at: float | None = None
        while True:
            seen = _count(lines, self.spec)
            done = (seen["answers"] >= answers and seen["status"] >= status
                    and (seen["banner"] >= 1 or not banner))
            if done and done_at is None:
                done_at = t.now()
            end = min(deadline, done_at + linger) if done_at is not None else deadline
            if t.now() >= end:
                break
            try:
                chunk = t.receive(end)
            except Exception as exc:  # noqa: BLE001
                raise HarnessError(str(exc)) from None
            if chunk:
                buf += chunk
                got, buf = split_unit(buf, self.spec)
                lines += [g.text for g in got]
        return Talk(lines, t.now())

    def wait(self, seconds: float) -> list[str]:
        return self.collect(timeout=seconds, linger=seconds).lines


def _count(lines: list[str], spec: GrblSpec) -> dict[str, int]:
    out = {"answers": 0, "status": 0, "banner": 0}
    for x in lines:
        kind = spec.classify(x)[0] if x else "blank"
        if kind in ("ok", "error"):
            out["answers"] += 1
        elif kind == "status":
            out["status"] += 1
        elif kind == "banner":
            out["banner"] += 1
    return out


SEQUENCES = "/interface/sequences/random"
ALARM_DELAY = 0.5    # report.c report_alarm_message: delay_ms(500) after every ALARM:N
REALTIME_GAP = 0.02  # protocol.c handles all pending realtime flags in one pass: keep them apart
Outcome = tuple[bool | None, str, str]     # passed (None: not applicable), expected, actual


@dataclass
class GrblCheck:
    id: str
    clause: str
    title: str
    run: Callable[[Session], Outcome]
    level: str = MUST
    motion: bool = False
    eeprom: bool = False

    @property
    def subject(self) -> str:
        """What is checked, as grbl names it: ``$11``, ``error:3``, ``ALARM:2``, else the kind
        (``example``, ``realtime``, ``state``)."""
        parts = self.id.split("/")[2:]
        names = {"setting": "${}", "error": "error:{}", "alarm": "ALARM:{}"}
        if len(parts) > 1 and parts[0] in names:
            return names[parts[0]].format(parts[1])
        return parts[0] if parts else self.id
