"""A careful GVE sender for check-sender's tests: checksums on, strictly simplex, and after a
garbled or lost answer it asks `>` and `@` before doing anything (GVE64 §13.5.13).

    python careful.py PORT JOB [--no-checksums]

It reads `@` before every vector, so after an uncertain answer an unchanged index means the
vector never arrived (send it again) and a changed one means it did (the `>` answer, asked
first, is its answer). Queue full (1): wait 20 ms and send it again. An answer with INTA: stop
sending vectors, wait until the input that caused it (SR4) is released, then `G`.
Exit 0 when every job line was acknowledged, 1 otherwise.
"""

import os
import sys
import termios
import time

import serial

# what a dropped line raises: pyserial lets termios.error (no OSError) through from a flush
LINK_ERRORS = (serial.SerialException, OSError, termios.error)

# how long an answer may take before it counts as lost: an emulator on a loaded machine can be
# a few hundred ms late, and a late answer taken for lost is a second line in flight
TIMEOUT = 0.4
QUIET = 0.25
PARENT = os.getppid()


def summed(body: str) -> str:
    s = body + ","
    return s + "%02X" % (sum(s.encode()) & 0xFF)


class Link:
    def __init__(self, port: str, checksums: bool) -> None:
        self.path = port
        self.port = serial.Serial(port, 115200, timeout=0.02)
        self.cs = False
        self.want_cs = checksums
        self.buf = b""

    def reopen(self) -> None:
        """The link dropped (a cable pulled): open the port again once it is back (up to 30 s);
        what was in flight counts as lost, and the caller recovers through `>` and `@`."""
        try:
            self.port.close()
        except LINK_ERRORS:
            pass
        self.buf = b""
        deadline = time.monotonic() + 30.0
        while True:
            if os.getppid() != PARENT:
                # whoever judged it is gone (killed): its port is not coming back, and a
                # pty number it named may already be another program's port
                raise SystemExit("careful: the program that ran it is gone")
            try:
                self.port = serial.Serial(self.path, 115200, timeout=0.02)
                return
            except LINK_ERRORS:
                if time.monotonic() > deadline:
                    raise SystemExit("careful: the port did not come back") from None
                time.sleep(0.1)

    def read_some(self) -> bytes | None:
        """What has come (b"" for nothing yet), or None when the link dropped (reopened)."""
        try:
            return self.port.read(self.port.in_waiting or 1)
        except LINK_ERRORS:
            self.reopen()
            return None

    def line(self, body: str) -> bytes:
        return ((summed("!0" + body) if self.cs else "!0" + body) + "\r").encode()

    def read_line(self, timeout: float = TIMEOUT) -> str | None:
        end = time.monotonic() + timeout
        while b"\r" not in self.buf:
            if time.monotonic() > end:
                return None
            got = self.read_some()
            if got is None:
                return None
            self.buf += got
        line, _, self.buf = self.buf.partition(b"\r")
        return line.decode("latin-1")

    def settle(self) -> None:
        """After an answer taken for lost: wait until the line has been quiet for QUIET s
        (at most 3 s), dropping what comes, so that a late answer is not read as the next
        command's (one answer behind, every later command would be a second in flight)."""
        self.buf = b""
        start = last = time.monotonic()
        while (now := time.monotonic()) - last < QUIET and now - start < 3.0:
            if self.read_some() != b"":
                last = time.monotonic()

    def send(self, body: str) -> None:
        """One command; what is already waiting is left over from before (the sender is
        strictly simplex, and nothing it sent is unanswered): dropped, not read as its answer."""
        try:
            if self.buf or self.port.in_waiting:
                self.port.reset_input_buffer()
                self.buf = b""
            self.port.write(self.line(body))
        except LINK_ERRORS:
            self.reopen()   # the line is lost with the link: its answer will not come

    def parse(self, text: str | None) -> tuple[int, list[str]] | None:
        """(code incl. INTA, fields) of a clean answer, else None."""
        if not text or text[0] not in "0123456789ABCDEF":
            return None
        parts = text.split(",")
        if self.cs:
            if len(parts) < 2 or len(parts[-1]) != 2:
                return None
            head = text[: text.rfind(",") + 1]
            try:
                if (sum(head.encode()) & 0xFF) != int(parts[-1], 16):
                    return None
            except ValueError:
                return None
            parts = parts[:-1]
        if len(parts[0]) != 1:
            return None
        return int(parts[0], 16), parts[1:]

    def ask(self, body: str, tries: int = 40) -> tuple[int, list[str]]:
        """A command that may be repeated safely: send until a clean answer."""
        for _ in range(tries):
            self.send(body)
            ans = self.parse(self.read_line())
            if ans is not None:
                return ans
            self.settle()
        raise SystemExit(f"careful: no clean answer to {body}")

    def repeat(self) -> tuple[str | None, tuple[int, list[str]] | None]:
        """`>`: (the echoed line, its answer) or (None, None) when damaged."""
        self.send(">")
        echo = self.read_line()
        if echo is None or not echo.startswith("!"):
            return None, None
        return echo, self.parse(self.read_line())


def main() -> int:
    port, job = sys.argv[1], sys.argv[2]
    link = Link(port, "--no-checksums" not in sys.argv)
    lines = [x.strip() for x in open(job) if x.strip()]
    if link.want_cs:
        for _ in range(40):
            link.port.write(b"!0%+\r")
            text = link.read_line()
            link.cs = True
            if link.parse(text) is not None:
                break
            link.cs = False
            link.settle()
        else:
            return 3
    inta_seen = False
    k = 0
    while k < len(lines):
        body = lines[k]
        vector = body[0] in "CL"
        before = None
        if vector:
            code, fields = link.ask("@")
            inta_seen |= bool(code & 8)
            before = fields[0] if fields else None
        if inta_seen:
            inta_seen = False
            resume(link)
            continue
        link.send(body)
        ans = link.parse(link.read_line())
        if ans is None and vector:
            ans = recover(link, body, before)
            if ans == "resend":
                continue
        elif ans is None:
            link.settle()
            continue  # not a vector: sending it again is harmless
        code, _ = ans
        if code & 8:
            inta_seen = True
        code &= 7
        if code == 1:
            time.sleep(0.02)
            continue
        if code in (2, 3, 4, 5):
            continue  # refused: certainly not taken (damaged on the way)
        if code not in (0, 6):
            return 1
        k += 1
    if link.cs:  # leave the unit as found; the answer to %- has no checksum
        line = link.line("%-")
        link.cs = False
        for _ in range(40):
            link.port.write(line)
            if link.parse(link.read_line()) is not None:
                break
            link.settle()
    return 0


def recover(link: Link, body: str, before: str | None):
    """After a garbled answer or none: `>` first (it repeats the last line and its answer),
    then `@` (asking `@` first would make `>` repeat the `@`)."""
    ours = link.line(body).decode().rstrip("\r")
    for _ in range(40):
        link.settle()
        echo, rep = link.repeat()
        if rep is None:
            continue
        _code, fields = link.ask("@")
        now = fields[0] if fields else None
        if now == before:
            return "resend"  # the vector never arrived
        if echo == ours:
            return rep  # it arrived: the repeated answer is its answer
        if rep[0] & 7 in (2, 3, 4, 5):
            return "resend"  # it arrived damaged and was refused
        raise SystemExit(f"careful: index moved but `>` shows {echo!r}: stopping")
    raise SystemExit("careful: no clean answer to `>`")


def resume(link: Link) -> None:
    """Interrupted (INTA): SR4 says which input did it; wait until that input is released
    (back high: active low after reset), then G."""
    _code, fields = link.ask("SR4")
    cause = int(fields[0], 16) if fields else 0
    while cause:
        _code, fields = link.ask("I1")
        if fields and int(fields[0], 16) & cause == cause:
            break
        time.sleep(0.05)
    while True:
        code, _ = link.ask("G")
        if code & 7 in (0, 6):
            return
        time.sleep(0.05)


if __name__ == "__main__":
    sys.exit(main())
