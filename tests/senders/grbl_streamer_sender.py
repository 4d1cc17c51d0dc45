"""Drive grbl-streamer (PyPI ``grbl-streamer``, the sender engine of several grbl GUIs, not
written here) headless: connect, wait for grbl's banner, stream a job, exit.

    python grbl_streamer_sender.py PORT JOB [incremental|default]

``incremental``: grbl-streamer's send-response mode (``incremental_streaming = True``: the
next line after the last one's ok). ``default``: its character counting against a 128-byte
buffer, with its status-poll thread that sends ``$G`` and ``$#`` after the banner outside the
count. Both poll ``?`` every 0.2 s. Exit status 0 when the job finished without error:N or
ALARM, 1 otherwise (and when grbl restarted during the job), 2 when it never booted.
"""

import sys
import threading
import time

from grbl_streamer import GrblStreamer

PORT, JOB = sys.argv[1], sys.argv[2]
MODE = sys.argv[3] if len(sys.argv) > 3 else "incremental"
TIMEOUT = 120.0

events = {"boot": threading.Event(), "finished": threading.Event(), "failed": threading.Event()}
boots = []


def on_event(event, *data):
    if event == "on_boot":
        boots.append(time.monotonic())
        events["boot"].set()
        if len(boots) > 1:               # grbl restarted: the job's state is gone
            events["failed"].set()
    elif event == "on_job_completed":
        events["finished"].set()
    elif event in ("on_error", "on_alarm"):
        events["failed"].set()


def main() -> int:
    g = GrblStreamer(on_event)
    g.cnect(PORT, 115200)
    try:
        if not events["boot"].wait(10.0):
            return 2
        g.poll_start()
        time.sleep(0.5)                  # its boot-time $G/$# requests go out with the polls
        g.incremental_streaming = MODE == "incremental"
        g.load_file(JOB)
        events["finished"].clear()       # its boot also reports a (new, empty) job finished
        g.job_run()
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            if events["failed"].is_set():
                return 1
            if events["finished"].is_set():
                return 0
            time.sleep(0.05)
        return 1
    finally:
        g.poll_stop()
        g.disconnect()


if __name__ == "__main__":
    sys.exit(main())
