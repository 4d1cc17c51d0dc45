"""Where bytes really move: serial ports and URLs, ptys, a TCP server, forwarding loops.

Everything here offers the ``Endpoint`` interface (``name``, ``read(max, timeout)``,
``write(data)``, ``close()``) and raises ``PortGone`` when a port vanishes.
"""

from conform.link.endpoint import Endpoint, PortGone, WriteTimeout
from conform.link.forward import Forwarder, Tap
from conform.link.ports import Reopener, SerialEndpoint, open_port
from conform.link.pty import PtyEndpoint
from conform.link.tcp import TcpServerEndpoint

__all__ = [
    "Endpoint",
    "Forwarder",
    "PortGone",
    "PtyEndpoint",
    "Reopener",
    "SerialEndpoint",
    "Tap",
    "TcpServerEndpoint",
    "WriteTimeout",
    "open_port",
]
