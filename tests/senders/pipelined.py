"""A GVE sender that ignores the simplex rule (GVE64 §13.3.1) for check-sender's tests: it
keeps up to four commands in flight before reading their answers. Exits 0.

    python pipelined.py PORT JOB
"""

import sys

import serial

WINDOW = 4


def main() -> int:
    port = serial.Serial(sys.argv[1], 115200, timeout=0.5)
    lines = [x.strip() for x in open(sys.argv[2]) if x.strip()]
    outstanding = 0
    for body in lines:
        port.write(f"!0{body}\r".encode())
        outstanding += 1
        if outstanding >= WINDOW:
            port.read_until(b"\r")
            outstanding -= 1
    while outstanding:
        port.read_until(b"\r")
        outstanding -= 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
