"""Drive bCNC's sender engine (PyPI ``bCNC``, its ``Sender`` class and GRBL1 controller, not
written here) headless: open the port as bCNC does, queue a job's lines as its run does, wait
until every line is answered, exit.

    python bcnc_sender.py PORT JOB

bCNC counts the bytes of every line it queues against a 128-byte buffer (its ``$G`` and
``$#`` requests go through the same queue and count), polls ``?`` every 0.125 s, wakes grbl
with two empty lines, and stops a run at error:N or ALARM. Exit status 0 when the whole job
was answered ok, 1 after error:N or ALARM or when it stalls, 2 when bCNC cannot start.
"""

import builtins
import gettext
import importlib.util
import os
import sys
import tempfile
import time
from queue import Empty

PORT, JOB = sys.argv[1], sys.argv[2]
os.environ["HOME"] = tempfile.mkdtemp(prefix="bcnc-home-")   # bCNC writes ~/.bCNC
spec = importlib.util.find_spec("bCNC")
if spec is None or spec.origin is None:
    sys.exit(2)
HERE = os.path.dirname(spec.origin)
sys.path[:0] = [HERE, os.path.join(HERE, "lib"), os.path.join(HERE, "controllers"),
                os.path.join(HERE, "plugins")]

builtins._ = getattr(builtins, "_", None) or gettext.gettext   # bCNC's GUI installs it
import Utils  # noqa: E402  (bCNC's own modules sit on its folder, not a package)

Utils.loadConfiguration()
from Sender import Sender  # noqa: E402


def main() -> int:
    with open(JOB) as f:
        job = [x.strip() for x in f.read().splitlines() if x.strip()]
    s = Sender()
    s.open(PORT, 115200)
    failed = False
    try:
        time.sleep(1.0)                  # its wake-up lines are answered
        s.running = True                 # as bCNC's run: no $G polls while a job runs
        s._runLines = len(job)
        start = s._gcount
        for line in job:
            s.queue.put(line + "\n")
        deadline = time.monotonic() + 120.0
        last, last_t = start, time.monotonic()
        while time.monotonic() < deadline:
            try:
                while True:
                    kind, text = s.log.get_nowait()
                    if kind == Sender.MSG_ERROR:
                        failed = True
            except Empty:
                pass
            if failed:
                return 1
            if s._gcount - start >= len(job):
                return 0
            if s._gcount != last:
                last, last_t = s._gcount, time.monotonic()
            elif time.monotonic() - last_t > 10.0:
                return 1                 # nothing answered for 10 s
            time.sleep(0.05)
        return 1
    finally:
        s.running = False
        s.thread = None                  # ends its serial thread
        time.sleep(0.3)
        s.serial.close()


if __name__ == "__main__":
    sys.exit(main())
