"""A careless GVE sender for check-sender's tests: no checksums, and after a garbled answer or
none it sends the same line again at once (a blind resend, GVE64 §13.5.13 says to ask `@`).
Queue full: sends again at once (hammering). Ignores INTA. Always exits 0.

    python blind.py PORT JOB
"""

import sys
import time

import serial


def main() -> int:
    port = serial.Serial(sys.argv[1], 115200, timeout=0.02)
    lines = [x.strip() for x in open(sys.argv[2]) if x.strip()]
    for body in lines:
        for _ in range(1000):
            port.write(f"!0{body}\r".encode())
            buf = b""
            end = time.monotonic() + 0.2
            while b"\r" not in buf and time.monotonic() < end:
                buf += port.read(port.in_waiting or 1)
            text = buf.split(b"\r")[0].decode("latin-1")
            if text[:1] in ("0", "8") and text[1:2] in ("", ","):
                break
    return 0


if __name__ == "__main__":
    sys.exit(main())
