"""A sender that opens the port, sends one command and then hangs (check-sender's timeout)."""

import sys
import time

import serial

port = serial.Serial(sys.argv[1], 115200, timeout=0.1)
port.write(b"!0?\r")
while True:
    time.sleep(1)
