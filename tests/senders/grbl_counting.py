"""A grbl sender for check-sender's tests: character counting (the 128-byte receive buffer),
`?` polled alone four times a second, and a MODE that is either right or one known mistake.

    python grbl_counting.py PORT JOB [MODE]

good            counts every line it sends (terminator included) and frees it on its ok or
                error:N; stops after error:N, ALARM or an unasked restart (banner) and exits 1;
                after a lost or damaged answer it waits, and when two status reports say Idle
                with no answer coming, every line has been taken: it clears its count; when
                the port vanishes it opens it again and stops (the board restarted with it)
overflow        counts against 256 bytes instead of 128
uncounted-poll  sends `$G` every ten lines outside its count (a polling thread)
counts-realtime puts each `?` in its count and takes a status report for an answer
realtime-line   sends `?` followed by a newline
ignore-error    goes on after error:N (and exits 0)
ignore-alarm    goes on after ALARM (and the error:9 that follow)
resend          after waiting 0.5 s for an answer it sends the oldest unanswered line again
waits-forever   waits for every answer, however long (no recovery after a lost one)
continue-after-restart  after the port came back (or a restart banner) it clears its count
                and goes on with the job
auto-resume     answers a Hold it did not cause with `~`
fast-poll       polls `?` fifty times a second
send-response   one line at a time: the next only after the answer to the last
"""

import collections
import sys
import termios
import time

import serial

# what a dropped line raises: pyserial lets termios.error (no OSError) through from a flush
LINK_ERRORS = (serial.SerialException, OSError, termios.error)

PORT, JOB = sys.argv[1], sys.argv[2]
MODE = sys.argv[3] if len(sys.argv) > 3 else "good"
RX = 256 if MODE == "overflow" else 128
POLL = 0.02 if MODE == "fast-poll" else 0.25
STALL = 0.5


def open_port(deadline):
    while True:
        try:
            return serial.Serial(PORT, 115200, timeout=0.01)
        except LINK_ERRORS:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


class Sender:
    def __init__(self):
        self.port = open_port(time.monotonic() + 5)
        self.buf = b""
        self.counted = collections.deque()   # [text, size] of lines in grbl's buffer
        self.last_answer = time.monotonic()
        self.idle_reports = 0
        self.stop = None
        self.lost_answers = 0

    def write(self, data):
        try:
            self.port.write(data)
        except LINK_ERRORS:
            self.reconnect()

    def reconnect(self):
        try:
            self.port.close()
        except LINK_ERRORS:
            pass
        time.sleep(0.1)
        self.port = open_port(time.monotonic() + 10)
        self.buf = b""
        self.counted.clear()   # whatever was in grbl's buffer went with the link
        if MODE != "continue-after-restart":
            self.stop = self.stop or "grbl restarted (the port vanished)"

    def lines_in(self):
        try:
            self.buf += self.port.read(self.port.in_waiting or 1)
        except LINK_ERRORS:
            self.reconnect()
        while b"\n" in self.buf:
            line, _, self.buf = self.buf.partition(b"\n")
            yield line.strip().decode("latin-1")

    def start(self):
        time.sleep(0.1)
        self.port.reset_input_buffer()
        self.write(b"\x18")
        end = time.monotonic() + 3
        while time.monotonic() < end:
            if any(x.startswith("Grbl ") for x in self.lines_in()):
                return

    def answer(self, text):
        if self.counted:
            self.counted.popleft()
        self.last_answer = time.monotonic()
        self.idle_reports = 0
        if text.startswith("error:") and MODE not in ("ignore-error", "ignore-alarm") \
                and self.stop is None:
            self.stop = text

    def handle(self, text):
        if text == "ok" or text.startswith("error:"):
            self.answer(text)
        elif text.startswith("<"):
            state = text[1:].split("|", 1)[0]
            if MODE == "counts-realtime" and self.counted:
                self.counted.popleft()
            if MODE == "auto-resume" and state.startswith("Hold"):
                self.write(b"~")
            stalled = self.counted and time.monotonic() - self.last_answer > STALL
            self.idle_reports = self.idle_reports + 1 if stalled and state == "Idle" else 0
            if self.idle_reports >= 2 and MODE not in ("waits-forever", "resend"):
                # grbl stands idle and answers nothing: every line was taken, the answers lost
                self.lost_answers += len(self.counted)
                self.counted.clear()
                self.idle_reports = 0
        elif text.startswith("ALARM:") and MODE != "ignore-alarm":
            self.stop = self.stop or text
        elif text.startswith("Grbl "):
            self.counted.clear()
            if MODE != "continue-after-restart":
                self.stop = self.stop or "grbl restarted"
        # anything else: a push message, or a damaged line: never taken for an answer

    def room(self, line):
        if MODE == "send-response":
            return not self.counted
        return sum(c[1] for c in self.counted) + len(line) + 1 <= RX

    def run(self, lines):
        self.start()
        i, last_poll = 0, 0.0
        while (i < len(lines) and self.stop is None) or (self.counted and self.stop is None) \
                or (self.counted and not self.stop.startswith(("grbl", "ALARM"))):
            now = time.monotonic()
            if now - last_poll >= POLL:
                self.write(b"?\n" if MODE == "realtime-line" else b"?")
                if MODE == "counts-realtime":
                    self.counted.append(["?", 1])
                last_poll = now
            while self.stop is None and i < len(lines) and self.room(lines[i]):
                if MODE == "uncounted-poll" and i % 10 == 5:
                    self.write(b"$G\n")
                self.write(lines[i].encode() + b"\n")
                self.counted.append([lines[i], len(lines[i]) + 1])
                i += 1
            for text in self.lines_in():
                self.handle(text)
            if MODE == "resend" and self.counted and time.monotonic() - self.last_answer > STALL:
                text, size = self.counted.popleft()
                self.write(text.encode() + b"\n")
                self.counted.append([text, size])
                self.last_answer = time.monotonic()
        if self.lost_answers:
            print(f"warning: {self.lost_answers} answers never arrived", file=sys.stderr)
        if self.stop:
            print(f"stopped: {self.stop}", file=sys.stderr)
            return 1
        return 0


def main():
    lines = [x.strip() for x in open(JOB) if x.strip()]
    return Sender().run(lines)


if __name__ == "__main__":
    sys.exit(main())
