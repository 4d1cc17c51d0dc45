"""A careful Marlin sender for check-sender's tests: numbered, checksummed lines, one in
flight; on Resend: N it sends N; when nothing comes for a while (a lost ok, the unit not busy)
it goes on with the next line, since the numbering makes that safe (a line really lost is
asked for again); on an unexpected `start` (the unit restarted) it stops.

    python marlin_careful.py PORT JOB
"""

import os
import sys
import time

import serial


def frame(n, cmd):
    body = f"N{n} {cmd}".encode()
    cs = 0
    for b in body:
        cs ^= b
    return body + b"*%d\n" % cs


def main(port_path, job_path):
    job = [x.split(";")[0].strip() for x in open(job_path)]
    job = [x for x in job if x]
    port = serial.Serial(port_path, int(os.environ.get("CONFORM_BAUD", "250000")), timeout=0.05)
    buf = b""
    time.sleep(0.3)
    port.reset_input_buffer()
    port.write(b"M110 N0\n")
    n = 1
    quiet_since = time.monotonic()
    waiting = True          # for M110's own ok: the number is set when M110 runs, so a
    skip_ok = True          # numbered line sent before that would be taken, then undone
    while True:
        if not waiting:
            if n > len(job):
                return 0
            port.write(frame(n, job[n - 1]))
            waiting = True
            quiet_since = time.monotonic()
        buf += port.read(4096)
        *lines, buf = buf.split(b"\n")
        for line in lines:
            line = line.strip()
            quiet_since = time.monotonic()
            if line == b"start":
                print("the unit restarted: stopping the job", flush=True)
                return 3
            if line.startswith(b"Resend:"):
                n = int(line.split(b":")[1])
                waiting = False
                skip_ok = True
            elif line.startswith(b"ok"):
                if waiting and not skip_ok:
                    n += 1
                if waiting:
                    waiting = False
                skip_ok = False
        if waiting and time.monotonic() - quiet_since > 2.5:
            print(f"no answer for N{n}: taking the ok as lost", flush=True)
            n += 1
            waiting = False


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
