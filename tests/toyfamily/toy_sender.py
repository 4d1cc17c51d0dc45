"""A sender of the toy line protocol, for check-sender's tests: the job's lines one at a time,
each once the line before is answered.

    python toy_sender.py PORT JOB [--skip N] [--blind]

An answer that has not come within ANSWER_WAIT is taken as lost: the sender asks GET and sends
the SET line again only when the register does not hold its value. The deviant senders the
tests expect check-sender to catch: ``--skip N`` leaves out the job's Nth line (1-based),
``--blind`` sends a line again at once when its answer is lost (executing it twice).
"""

from __future__ import annotations

import argparse
import sys
import time

import serial

ANSWER_WAIT = 0.3  # s; the toy unit answers within milliseconds
TRIES = 20


class Line:
    def __init__(self, port: serial.Serial) -> None:
        self.port, self.buf = port, b""

    def ask(self, text: str) -> str | None:
        """Send one line; its answer, or None when none came in time."""
        self.port.write(text.encode("ascii") + b"\r")
        end = time.monotonic() + ANSWER_WAIT
        while time.monotonic() < end:
            self.buf += self.port.read(64)
            if b"\r" in self.buf:
                answer, _, self.buf = self.buf.partition(b"\r")
                return answer.decode("latin-1")
        return None

    def holds(self, value: str) -> bool | None:
        """Whether the register holds ``value`` (None: no answer to GET either)."""
        for _ in range(TRIES):
            got = self.ask("GET")
            if got is not None:
                return got == f"VAL {value}"
        return None


def send(line: Line, text: str, blind: bool = False) -> bool:
    for _ in range(TRIES):
        got = line.ask(text)
        if got == "OK":
            return True
        if got is not None:
            print(f"{text!r} answered {got!r}: stopping", flush=True)
            return False
        word, _, value = text.partition(" ")
        if word == "SET" and not blind and line.holds(value):
            return True   # executed; only its answer was lost
    print(f"{text!r}: no answer after {TRIES} tries", flush=True)
    return False


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("port")
    ap.add_argument("job")
    ap.add_argument("--skip", type=int, default=0, help="leave out the job's Nth line")
    ap.add_argument("--blind", action="store_true", help="send a line again when unanswered")
    a = ap.parse_args()
    with open(a.job, encoding="ascii") as f:
        lines = [x.strip() for x in f if x.strip()]
    with serial.Serial(a.port, 115200, timeout=0.02) as port:
        line = Line(port)
        for n, text in enumerate(lines, 1):
            if n != a.skip and not send(line, text, a.blind):
                return 1
    print(f"{len(lines)} lines sent", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
