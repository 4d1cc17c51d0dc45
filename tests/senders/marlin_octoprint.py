"""OctoPrint 1.11's serial layer (octoprint.util.comm.MachineCom) streaming a job headless:
settings and plugins in a throw-away base folder, connect, select the job file, print,
wait until the print is done, failed or the connection closed, disconnect.

    python marlin_octoprint.py PORT JOB      (with an interpreter that has OctoPrint)
"""

import logging
import os
import shutil
import sys
import tempfile
import threading
import time


def main(port, job_path):
    base = tempfile.mkdtemp(prefix="conform-octoprint-")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s",
                        stream=sys.stdout)
    logging.getLogger("SERIAL").setLevel(logging.DEBUG)
    try:
        from octoprint.settings import settings

        s = settings(init=True, basedir=base)
        s.set(["serial", "log"], True)
        from octoprint.plugin import plugin_manager

        plugin_manager(init=True, plugin_folders=[], plugin_disabled_list=[])
        from octoprint.printer.profile import PrinterProfileManager
        from octoprint.util import comm

        done = threading.Event()
        outcome = {}

        class Callback(comm.MachineComPrintCallback):
            def on_comm_state_change(self, state):
                print(f"octoprint: state {state}", flush=True)
                if state in (comm.MachineCom.STATE_CLOSED, comm.MachineCom.STATE_ERROR,
                             comm.MachineCom.STATE_CLOSED_WITH_ERROR) and started[0]:
                    outcome.setdefault("end", f"connection state {state}")
                    done.set()

            def on_comm_print_job_done(self, suppress_script_output=False):
                outcome.setdefault("end", "done")
                done.set()

            def on_comm_print_job_failed(self, reason=None):
                outcome.setdefault("end", f"failed: {reason}")
                done.set()

            def on_comm_print_job_cancelled(self, suppress_script_output=False):
                outcome.setdefault("end", "cancelled")
                done.set()

        started = [False]
        com = comm.MachineCom(port, int(os.environ.get("CONFORM_BAUD", "250000")), Callback(),
                              PrinterProfileManager())
        com.start()
        deadline = time.monotonic() + 20
        while not com.isOperational() and time.monotonic() < deadline:
            time.sleep(0.1)
        if not com.isOperational():
            print(f"octoprint: not operational ({com.getStateString()})", flush=True)
            com.close()
            return 2
        com.selectFile(job_path, False)
        started[0] = True
        com.startPrint()
        done.wait(3600)
        print(f"octoprint: print {outcome.get('end')}", flush=True)
        com.close()
        return 0 if outcome.get("end") == "done" else 3
    finally:
        shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
