"""Move bytes between link ends with one thread per direction, and survive a lost port.

``Forwarder(host, unit)`` copies host->unit and unit->host (the proxy); ``Tap(host, unit)``
only reads both (the sniffer on a Y-cable). Every chunk is timestamped the moment its read
returns and handed to ``on_chunk(direction, data, t_read)`` just before it is forwarded, so
a recorder sees every command before the answer it causes; ``on_chunk`` must only queue.
A port that raises ``PortGone`` becomes ``on_event("disconnect", side, detail)``; with a
``reopen`` factory for that side the loop retries every ``retry_interval`` seconds and
reports ``"reconnect"``; otherwise that side stays down and the loop ends (``Forwarder``)
or goes on with the other side (``Tap``).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from conform.errors import LinkError
from conform.link.endpoint import Endpoint, PortGone

ChunkHook = Callable[[str, bytes, float], None]
EventHook = Callable[[str, str, str], None]  # kind, side, detail
Reopen = Callable[[], Endpoint]

READ_SIZE = 4096


class _Side:
    def __init__(self, name: str, endpoint: Endpoint, reopen: Reopen | None) -> None:
        self.name = name
        self.endpoint = endpoint
        self.reopen = reopen
        self.up = threading.Event()
        self.up.set()
        self.lost_for_good = False


class _Runner:
    """Pumps, loss handling and reconnection shared by ``Forwarder`` and ``Tap``."""

    forwards: bool = False
    stop_on_first_loss: bool = False

    def __init__(
        self,
        host: Endpoint,
        unit: Endpoint,
        *,
        on_chunk: ChunkHook,
        on_event: EventHook | None = None,
        clock: Callable[[], float] = time.time,
        reopen_host: Reopen | None = None,
        reopen_unit: Reopen | None = None,
        retry_interval: float = 0.5,
        read_size: int = READ_SIZE,
        poll: float = 0.1,
    ) -> None:
        self.sides = {
            "host": _Side("host", host, reopen_host),
            "unit": _Side("unit", unit, reopen_unit),
        }
        self.on_chunk = on_chunk
        self.on_event = on_event or (lambda kind, side, detail: None)
        self.clock = clock
        self.retry_interval = retry_interval
        self.read_size = read_size
        self.poll = poll
        self.dropped = {"host": 0, "unit": 0}
        self.failure: str | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []

    # -- lifecycle -------------------------------------------------------------------------
    def start(self) -> None:
        for src, dst in (("host", "unit"), ("unit", "host")):
            t = threading.Thread(
                target=self._pump, args=(src, dst if self.forwards else None),
                name=f"pump-{src}", daemon=True,
            )
            self._threads.append(t)
            t.start()

    def stop(self) -> None:
        self._stop.set()

    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the loop ends (stopped or a port lost for good); ``True`` if it has."""
        return self._stop.wait(timeout)

    def join(self, timeout: float | None = 2.0) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout)

    def endpoint(self, side: str) -> Endpoint:
        return self.sides[side].endpoint

    # -- the pump --------------------------------------------------------------------------
    def _pump(self, src_name: str, dst_name: str | None) -> None:
        src = self.sides[src_name]
        while not self._stop.is_set():
            if not src.up.wait(self.poll):
                continue
            endpoint = src.endpoint
            try:
                data = endpoint.read(self.read_size, self.poll)
            except PortGone as exc:
                self._lost(src, endpoint, str(exc))
                continue
            if not data:
                continue
            t_read = self.clock()
            # record before forwarding: the answer to these bytes cannot then be recorded
            # ahead of them by the other pump (on_chunk must be cheap: it only queues)
            self.on_chunk(src_name, data, t_read)
            if dst_name is not None:
                self._deliver(self.sides[dst_name], data)

    def _deliver(self, dst: _Side, data: bytes) -> None:
        if not dst.up.is_set():
            self.dropped[dst.name] += len(data)
            return
        endpoint = dst.endpoint
        try:
            endpoint.write(data)
        except PortGone as exc:
            self.dropped[dst.name] += len(data)
            self._lost(dst, endpoint, str(exc))
        except LinkError as exc:  # write timeout: the other side is not reading
            self.dropped[dst.name] += len(data)
            self.on_event("error", dst.name, str(exc))

    # -- loss and reconnection -------------------------------------------------------------
    def _lost(self, side: _Side, endpoint: Endpoint, detail: str) -> None:
        with self._lock:
            if side.endpoint is not endpoint or not side.up.is_set():
                return  # the other pump noticed first
            side.up.clear()
        try:
            endpoint.close()
        except Exception:  # noqa: BLE001 - closing a dead port may fail in any way
            pass
        self.on_event("disconnect", side.name, detail)
        if side.reopen is not None and not self._stop.is_set():
            threading.Thread(
                target=self._reconnect, args=(side,), name=f"reopen-{side.name}", daemon=True
            ).start()
            return
        side.lost_for_good = True
        others_dead = all(s.lost_for_good for s in self.sides.values())
        if self.stop_on_first_loss or others_dead:
            self.failure = f"{side.name} port lost: {detail}"
            self._stop.set()

    def _reconnect(self, side: _Side) -> None:
        assert side.reopen is not None
        attempts = 0
        while not self._stop.is_set():
            attempts += 1
            try:
                endpoint = side.reopen()
            except LinkError as exc:
                if attempts == 1:
                    self.on_event("error", side.name, f"waiting for the port: {exc}")
                self._stop.wait(self.retry_interval)
                continue
            with self._lock:
                side.endpoint = endpoint
                side.up.set()
            self.on_event("reconnect", side.name, f"{endpoint.name} back after {attempts} tries")
            return


class Forwarder(_Runner):
    """The proxy's loop: host<->unit both ways; losing a port for good ends it."""

    forwards = True
    stop_on_first_loss = True


class Tap(_Runner):
    """The sniffer's loop: read-only on both ports; one lost port leaves the other running."""

    forwards = False
    stop_on_first_loss = False
