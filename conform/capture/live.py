"""Live captures: the proxy (man in the middle on a pty) and the sniffer (Y-cable tap).

Both are thin adapters: a ``Forwarder`` or ``Tap`` from ``conform.link`` moves and
timestamps the bytes, a ``Recorder`` writes them, and (for the sniffer) a ``Merger`` puts
the two directions in causal order. The CLI commands wrap these with signal handling; tests
and other tools can run them in-process::

    with ProxyCapture(unit_url, "run.mcap", baud=115200) as proxy:
        print(proxy.host_path)       # the sender opens this
        proxy.wait()                 # until stop() or the unit is lost for good
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from typing import Self

from conform.capture.merge import HostLines, Merger
from conform.capture.recorder import Recorder
from conform.capture.session import wire_time
from conform.errors import UserError
from conform.link.endpoint import Endpoint
from conform.link.forward import Forwarder, Tap
from conform.link.peerwatch import PeerWatch
from conform.link.ports import Reopener
from conform.link.pty import PtyEndpoint
from conform.stops import STOP_SIGNALS


class _Live:
    runner: Forwarder | Tap
    recorder: Recorder
    _reopeners: list[Reopener]

    def wait(self, timeout: float | None = None) -> bool:
        """Block until stopped; ``True`` if it has stopped."""
        return self.runner.wait(timeout)

    def stop(self) -> None:
        self.runner.stop()

    asked = False   # a stop asked by a signal, acted on by :func:`run_until_signal`'s loop

    def ask_stop(self) -> None:
        """What a signal handler may call: it only records the request. ``stop()`` sets an
        ``Event``, whose lock the interrupted main thread may hold (inside ``Event.wait``):
        called from the handler it would wait for itself forever."""
        self.asked = True

    @property
    def failure(self) -> str | None:
        """Why the capture ended by itself (a port lost for good), else ``None``."""
        return self.runner.failure

    def _event(self, kind: str, side: str, detail: str) -> None:
        self.recorder.link_event(kind, detail, side=side)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _let_go(self) -> None:
        """Let the ports' pty numbers go, once nothing will reopen them (``Reopener``)."""
        for reopen in self._reopeners:
            reopen.close()


class ProxyCapture(_Live):
    """A pty for the sender, forwarded both ways to the unit, every byte recorded."""

    def __init__(
        self,
        unit_url: str,
        output: str | os.PathLike[str],
        *,
        baud: int = 115200,
        variant: str | None = None,
        decode: bool = True,
        reconnect: bool = False,
        link: str | None = None,
        flush_interval: float = 0.25,
        open_unit: Callable[[], Endpoint] | None = None,
    ) -> None:
        self.unit_url = unit_url
        self.baud = baud
        self._last = {"host": float("-inf"), "unit": float("-inf")}
        self._reopeners = [] if open_unit else [Reopener(unit_url, baud)]
        opener = open_unit or self._reopeners[0]
        unit = opener()
        try:
            self.host = PtyEndpoint(link=link)
        except OSError:
            unit.close()
            self._let_go()
            raise
        self.host_path = self.host.path
        try:
            self.recorder = Recorder(
                output,
                {"capture_method": "proxy", "host_port": self.host_path,
                 "unit_port": unit_url, "baud": baud, "variant": variant or "",
                 "reconnect": reconnect},
                baud=baud, variant=variant, decode=decode, flush_interval=flush_interval,
            )
        except Exception:
            self.host.close()
            unit.close()
            self._let_go()
            raise
        self.recorder.link_event("open", f"sender pty {self.host_path}", side="host")
        self.recorder.link_event("open", f"{unit_url} at {baud} Bd", side="unit")
        self.runner = Forwarder(
            self.host, unit, on_chunk=self._chunk, on_event=self._event,
            clock=self.recorder.now, reopen_unit=opener if reconnect else None,
        )
        self.runner.start()
        # the pty stays open on our side, so only the device node shows the sender leaving
        self.peer = PeerWatch(self.host.device,
                              lambda kind, detail: self._event(kind, "host", detail))

    def _chunk(self, direction: str, data: bytes, t_read: float) -> None:
        if direction == "host":
            # the sender's side is a pty: its bytes arrive at once, no wire time to subtract
            self._last["host"] = t_read
            self.recorder.chunk("host", data, t_read, t_read)
            return
        # the unit's bytes took len*10/baud on the wire, but an answer cannot have begun
        # before the proxy forwarded the command (an emulator's pty has no wire time at all)
        t_first = t_read - wire_time(len(data), self.baud)
        t_first = max(t_first, min(max(self._last["host"], self._last["unit"]), t_read))
        self._last["unit"] = t_read
        self.recorder.chunk("unit", data, t_read, t_first)

    def close(self) -> None:
        self.peer.close()
        self.runner.join()
        dropped = dict(self.runner.dropped)
        for side in ("host", "unit"):
            self.runner.endpoint(side).close()
        self._let_go()
        self.recorder.link_event("close", "capture finished", side="session")
        if any(dropped.values()):
            self.recorder.log("warning", f"bytes not delivered (port down): {dropped}")
        self.recorder.close({"dropped_to_host": dropped["host"],
                             "dropped_to_unit": dropped["unit"],
                             "ended_by": self.failure or "stop"})


class SniffCapture(_Live):
    """Two receive-only ports on a Y-cable, merged in time and recorded."""

    def __init__(
        self,
        host_url: str,
        unit_url: str,
        output: str | os.PathLike[str],
        *,
        baud: int = 115200,
        variant: str | None = None,
        decode: bool = True,
        reconnect: bool = False,
        flush_interval: float = 0.25,
        read_size: int = 256,
    ) -> None:
        open_host, open_unit = Reopener(host_url, baud), Reopener(unit_url, baud)
        self._reopeners = [open_host, open_unit]
        host = open_host()
        try:
            unit = open_unit()
        except Exception:
            host.close()
            self._let_go()
            raise
        try:
            self.recorder = Recorder(
                output,
                {"capture_method": "sniff", "host_port": host_url, "unit_port": unit_url,
                 "baud": baud, "variant": variant or "", "reconnect": reconnect},
                baud=baud, variant=variant, decode=decode, flush_interval=flush_interval,
            )
        except Exception:
            host.close()
            unit.close()
            self._let_go()
            raise
        self.merger = Merger(baud, read_size=read_size, host_lines=_host_lines(variant))
        self._lock = threading.Lock()
        self.recorder.link_event("open", f"{host_url} at {baud} Bd (host->unit tap)",
                                 side="host")
        self.recorder.link_event("open", f"{unit_url} at {baud} Bd (unit->host tap)",
                                 side="unit")
        self.runner = Tap(
            host, unit, on_chunk=self._chunk, on_event=self._event, clock=self.recorder.now,
            reopen_host=open_host if reconnect else None,
            reopen_unit=open_unit if reconnect else None, read_size=read_size,
        )
        self._ticker = threading.Thread(target=self._tick, name="merge-tick", daemon=True)
        self.runner.start()
        self._ticker.start()

    def _emit(self, chunks: list) -> None:
        for c in chunks:
            self.recorder.chunk(c.direction, c.data, c.t_read, c.t_first)

    def _chunk(self, direction: str, data: bytes, t_read: float) -> None:
        with self._lock:
            self._emit(self.merger.push(direction, data, t_read))

    def _tick(self) -> None:
        while not self.runner.wait(0.05):
            with self._lock:
                self._emit(self.merger.tick(self.recorder.now()))

    def close(self) -> None:
        self.runner.join()
        self._ticker.join(1.0)
        with self._lock:
            self._emit(self.merger.flush())
        for side in ("host", "unit"):
            self.runner.endpoint(side).close()
        self._let_go()
        self.recorder.link_event("close", "capture finished", side="session")
        self.recorder.close({"late_chunks": self.merger.late,
                             "ended_by": self.failure or "stop"})


def _host_lines(variant: str | None) -> HostLines | None:
    """The count of owed answers of the family serving ``variant`` (the default family's
    without one), for the merge; None (one answer per line) if it has none."""
    from conform.families import family_for_variant

    try:
        make = getattr(family_for_variant(variant or ""), "host_lines", None)
    except UserError:
        return None
    return make() if make is not None else None


def run_until_signal(live: _Live) -> str | None:
    """Run until SIGINT/SIGTERM/SIGHUP or a port lost for good; close cleanly; return the
    failure."""
    import signal

    previous = {}

    def stop(signum: int, frame: object) -> None:
        live.ask_stop()

    for sig in STOP_SIGNALS:
        previous[sig] = signal.signal(sig, stop)
    try:
        while not live.wait(0.05):
            if live.asked:
                live.stop()
    finally:
        live.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return live.failure
