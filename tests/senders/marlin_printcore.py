"""Printrun's printcore (printrun 2.2.0, headless) streaming a job: connect, wait until it
is online, startprint, wait until it has sent everything, disconnect.

    python marlin_printcore.py PORT JOB
"""

import logging
import os
import sys
import time

from printrun import gcoder
from printrun.printcore import printcore


def main(port, job_path):
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stdout)
    p = printcore()
    p.loud = True
    p.connect(port, int(os.environ.get("CONFORM_BAUD", "250000")))
    deadline = time.monotonic() + 10
    while not p.online and time.monotonic() < deadline:
        time.sleep(0.05)
    if not p.online:
        print("printcore: the printer never came online", flush=True)
        p.disconnect()
        return 2
    lines = [x.rstrip("\n") for x in open(job_path)]
    p.startprint(gcoder.LightGCode(lines))
    while p.printing:
        time.sleep(0.05)
    time.sleep(0.5)
    p.disconnect()
    print("printcore: job sent", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
