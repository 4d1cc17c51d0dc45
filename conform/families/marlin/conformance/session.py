"""Driving one Marlin target for the checks: a fresh state, numbered lines, and collecting the
unit's lines until enough answers came (an ``ok``) or the time is up."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from conform.conformance.target import HarnessError
from conform.families.marlin.protocol.codec import checksum, split_lines
from conform.families.marlin.spec import MarlinSpec, Variant


@dataclass
class Talk:
    lines: list[str]
    t0: float
    t: float
    times: list[float] = field(default_factory=list)   # when each line was read

    def kinds(self, spec: MarlinSpec) -> list[str]:
        return [spec.classify(x)[0] for x in self.lines]

    def text(self) -> str:
        return " | ".join(self.lines) or "(silence)"


class Session:
    def __init__(self, target: Any, spec: MarlinSpec, v: Variant) -> None:
        self.target, self.spec, self.v = target, spec, v
        self.n = 0          # the last line number sent
        self._rest = b""

    def numbered(self, command: str, n: int | None = None, *, cs: int | None = None) -> bytes:
        """``N<n> <command>*<cs>\\n`` (the next number unless ``n``; ``cs`` overrides)."""
        if n is None:
            self.n += 1
            n = self.n
        body = f"N{n} {command}".encode("latin-1")
        return body + b"*%d\n" % (checksum(body) if cs is None else cs)

    def fresh(self) -> None:
        """The emulator: a new unit (its banner read); a real unit: line numbers back to 0."""
        t = self.target
        self.n, self._rest = 0, b""
        if t.emulated:
            t.reset()
            t.begin_log()
            self.collect(until=lambda ls: "start" in ls and ls[-1:] != ["start"], timeout=1.0,
                         linger=0.05)
            return
        t.begin_log()
        t.drain()
        # numbered: queue.cpp takes the number from M110's own N without a sequence check,
        # and the M110 handler sets it again (either form sets Marlin's number)
        got = self.talk(self.numbered("M110 N0", 0), timeout=3.0)
        if not any(self.spec.classify(x)[0].startswith("ok") for x in got.lines):
            raise HarnessError(f"no ok for N0 M110 N0 ({got.text()})")

    def oks(self, lines: list[str]) -> int:
        return sum(1 for x in lines if self.spec.classify(x)[0].startswith("ok"))

    def talk(self, data: bytes, *, answers: int | None = None, timeout: float = 2.0,
             linger: float = 0.1) -> Talk:
        """Send ``data``; collect until ``answers`` ok lines (one per line sent) came."""
        want = data.count(b"\n") if answers is None else answers
        try:
            sent, _ = self.target.send(data)
        except Exception as exc:  # noqa: BLE001 - a link failure is the harness's
            raise HarnessError(f"{type(exc).__name__}: {exc}") from None
        return self.collect(until=lambda ls: self.oks(ls) >= want, timeout=timeout,
                            linger=linger, since=sent)

    def collect(self, *, until: Any = None, timeout: float = 2.0, linger: float = 0.1,
                since: float | None = None) -> Talk:
        """Lines until ``until`` holds (then ``linger`` more) or ``timeout``; the Talk's t0 is
        ``since`` when given: the moment before the bytes were written, since a unit on another
        core can read them before the write returns and a time taken after it runs short."""
        t = self.target
        t0 = t.now() if since is None else since
        deadline = t.now() + timeout
        lines: list[str] = []
        times: list[float] = []
        done_at: float | None = None
        while True:
            if done_at is None and until is not None and until(lines):
                done_at = t.now()
            end = min(deadline, done_at + linger) if done_at is not None else deadline
            if t.now() >= end:
                break
            try:
                chunk = t.receive(end)
            except Exception as exc:  # noqa: BLE001
                raise HarnessError(f"{type(exc).__name__}: {exc}") from None
            if chunk:
                got, self._rest = split_lines(self._rest + chunk)
                lines += [g.decode("latin-1") for g in got]
                times += [t.now()] * len(got)
        return Talk(lines, t0, t.now(), times)

    def wait(self, seconds: float) -> Talk:
        return self.collect(timeout=seconds, linger=seconds)
