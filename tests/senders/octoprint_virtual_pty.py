"""OctoPrint's own Marlin-like simulator (the bundled virtual_printer plugin,
octoprint.plugins.virtual_printer.virtual.VirtualPrinter) exposed on a pty, so `conform run`
can hold it against Marlin's source like any unit behind a port. Its settings are the
plugin's defaults. Prints the pty's path on the first line; runs until SIGTERM.

    python octoprint_virtual_pty.py      (with an interpreter that has OctoPrint)
"""

import os
import select
import signal
import sys
import tempfile
import threading
import tty


class Defaults:
    """The plugin's settings object, answering from get_settings_defaults()."""

    def __init__(self, values, base):
        self.values = values
        self.base = base

    def global_get_basefolder(self, name, **_kw):
        path = os.path.join(self.base, name)
        os.makedirs(path, exist_ok=True)
        return path

    def get(self, path, merged=False, **_kw):
        node = self.values
        for key in path:
            node = node.get(key) if isinstance(node, dict) else None
        return node

    def get_boolean(self, path, **kw):
        return bool(self.get(path))

    def get_int(self, path, **kw):
        value = self.get(path)
        return None if value is None else int(value)

    def get_float(self, path, **kw):
        value = self.get(path)
        return None if value is None else float(value)


def main():
    base = tempfile.mkdtemp(prefix="conform-virtual-")
    from octoprint.settings import settings

    settings(init=True, basedir=base)
    from octoprint.plugin import plugin_manager

    plugin_manager(init=True, plugin_folders=[], plugin_disabled_list=[])
    from octoprint.plugins.virtual_printer import VirtualPrinterPlugin
    from octoprint.plugins.virtual_printer.virtual import VirtualPrinter
    from octoprint.printer.profile import PrinterProfileManager

    vp = VirtualPrinter(Defaults(VirtualPrinterPlugin().get_settings_defaults(), base),
                        PrinterProfileManager(), data_folder=base, read_timeout=0.05)
    master, slave = os.openpty()
    tty.setraw(slave)
    print(os.ttyname(slave), flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())

    def answers():
        while not stop.is_set():
            line = vp.readline()
            if line:   # its readline() gives some lines (ok, wait) without their line end
                os.write(master, line if line.endswith(b"\n") else line + b"\n")

    threading.Thread(target=answers, daemon=True).start()
    while not stop.is_set():
        ready, _, _ = select.select([master], [], [], 0.1)
        if ready:
            try:
                data = os.read(master, 4096)
            except OSError:
                continue
            if data:
                vp.write(data)
    vp.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
