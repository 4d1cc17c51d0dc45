"""The emulator's engine side, shared by every family: serving a sans-I/O reference unit on a
pty or TCP (serve.py) and its control socket (control.py)."""
