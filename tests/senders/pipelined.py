"""A GVE sender that ignores the simplex rule (GVE64 §13.3.1) for check-sender's tests: it
writes four commands in one burst, then reads their four answers. Exits 0.

    python pipelined.py PORT JOB
"""

import sys

import serial

WINDOW = 4


def main() -> int:
    port = serial.Serial(sys.argv[1], 115200, timeout=0.5)
    lines = [x.strip() for x in open(sys.argv[2]) if x.strip()]
    for k in range(0, len(lines), WINDOW):
        burst = lines[k:k + WINDOW]
        port.write(b"".join(f"!0{body}\r".encode() for body in burst))
        for _ in burst:
            port.read_until(b"\r")
    return 0


if __name__ == "__main__":
    sys.exit(main())
