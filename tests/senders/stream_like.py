"""A sender that behaves as grbl's own doc/script/stream.py does (its behaviour read from
gnea/grbl, written anew here): wake grbl with "\\r\\n\\r\\n", wait 2 s and throw away what
came back, poll '?' once a second from a thread, then stream the job.

    python stream_like.py PORT JOB [counting|settings]

``counting`` (stream.py's default): strip spaces and comments, count the bytes of unanswered
lines and wait for answers while the count reaches 127; errors are counted, not acted on, so
it streams on after error:N and ALARM (as stream.py does). ``settings`` (stream.py -s): send a
line, wait for its ok or error:N, then the next (send-response). Exit status 0 once every
line is answered (stream.py ends that way; its final "press Enter" is left out).
"""

import re
import sys
import threading
import time

import serial

PORT, JOB = sys.argv[1], sys.argv[2]
MODE = sys.argv[3] if len(sys.argv) > 3 else "counting"
RX_BUFFER_SIZE = 128
REPORT_INTERVAL = 1.0


def answer(port: serial.Serial) -> bool:
    """Read lines until an ok or error:N (other messages are only shown); False on timeout."""
    while True:
        text = port.readline().decode("latin-1").strip()
        if not text:
            return False
        if text.startswith(("ok", "error")):
            return True


def main() -> int:
    port = serial.Serial(PORT, 115200, timeout=5.0)
    lock = threading.Lock()
    running = True

    def poll() -> None:
        while running:
            with lock:
                port.write(b"?")
            time.sleep(REPORT_INTERVAL)

    port.write(b"\r\n\r\n")
    time.sleep(2.0)
    port.reset_input_buffer()
    threading.Thread(target=poll, daemon=True).start()
    with open(JOB) as f:
        lines = f.read().splitlines()
    try:
        if MODE == "settings":
            for line in lines:
                with lock:
                    port.write(line.strip().encode() + b"\n")
                if not answer(port):
                    return 1
            return 0
        counts: list[int] = []
        for line in lines:
            block = re.sub(r"\s|\(.*?\)", "", line).upper()
            counts.append(len(block) + 1)
            while sum(counts) >= RX_BUFFER_SIZE - 1:
                if not answer(port):
                    return 1
                del counts[0]
            with lock:
                port.write(block.encode() + b"\n")
        while counts:
            if not answer(port):
                return 1
            del counts[0]
        return 0
    finally:
        running = False
        port.close()


if __name__ == "__main__":
    sys.exit(main())
