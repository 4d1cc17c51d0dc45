"""``conform emulate serve marlin-…``: the Marlin reference unit behind a pty or TCP, through
the engine's serving adapter (:class:`conform.emulator.serve.Emulator`: wire pacing, faults,
recording, reconnects), with a control socket (:mod:`.control`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from conform.errors import UserError


def reopen_with_reset(reopen: Callable[[], Any], unit: Any, faults: Any,
                      clock: Callable[[], float] = time.monotonic) -> Callable[[], Any]:
    """After a pulled cable the board restarts as its port comes back (a USB board is powered
    and reset through the cable); after other link drops it just goes on."""
    def again() -> Any:
        if faults.unplugged:
            faults.unplugged = False
            unit.power_cycle(max(clock(), unit.now))
        return reopen()

    return again


def build(variant: str, *, t0: float, baud: int | None, faults: str | None, seed: int | None,
          answer_delay: float = 0.0, lose: float = 0.0) -> tuple[Any, Any]:
    """The unit and its fault injector, as ``serve`` and check-sender use them."""
    from conform.families.marlin.spec import load_marlin
    from conform.families.marlin.unit.faults import MarlinFaults
    from conform.families.marlin.unit.unit import MarlinUnit
    from conform.link.faults import FaultConfig

    spec = load_marlin()
    v = spec.variant(variant)
    config = FaultConfig.parse(faults) if faults else FaultConfig()
    unit = MarlinUnit(v, spec, t0=t0, line_time=max(answer_delay, 0.0005))
    return unit, MarlinFaults(config, seed, t0, lose=lose)


def serve(variant: str, *, baud: int | None = None, tcp_port: int | None = None,
          faults: str | None = None, seed: int | None = None, link_path: str | None = None,
          record_path: str | None = None, answer_delay: float = 0.0,
          control_path: str | None = None, quiet: bool = False, **_ignored: Any) -> None:
    from conform.emulator.launch import (
        announce,
        check_pacing,
        control_server,
        open_endpoint,
        report,
        run_until_signal,
    )
    from conform.emulator.serve import Emulator
    from conform.families.marlin.unit.control import MarlinControl

    check_pacing(baud, answer_delay)
    t_start = time.monotonic()
    unit, injector = build(variant, t0=t_start, baud=baud, faults=faults, seed=seed,
                           answer_delay=answer_delay)
    v = unit.v
    endpoint, reopen = open_endpoint(tcp_port, link_path)
    control = control_server(control_path, endpoint)
    recorder = None
    if record_path:
        from conform.capture import Recorder

        try:
            recorder = Recorder(record_path, {
                "capture_method": "emulator", "variant": v.id, "family": "marlin",
                "line_baud": baud or "", "unit_port": endpoint.name, "dialect": "",
                "faults": faults or "", "seed": "" if seed is None else seed}, decode=False)
        except UserError:
            endpoint.close()
            control.close()
            raise
    emulator = Emulator(unit, endpoint, baud=baud, injector=injector, recorder=recorder,
                        control=control, reopen=reopen_with_reset(reopen, unit, injector),
                        report=report, control_handler=MarlinControl(injector))
    announce(endpoint, f"{v.id} on {endpoint.name} (queue {v.bufsize} commands, receive "
             f"buffer {v.rx_buffer} bytes, planner {v.planner_blocks} blocks); control: "
             f"{control.path}")
    try:
        run_until_signal(emulator, quiet)
    finally:
        control.close()
        if recorder is not None:
            recorder.close({"bytes_in": emulator.bytes_in, "bytes_out": emulator.bytes_out,
                            "bytes_lost": unit.lost})
        twice = sorted(k for k, n in unit.truth.executed.items() if n > 1)
        report(f"stopped ({emulator.bytes_in} bytes in, {emulator.bytes_out} out, {unit.lost} "
               f"lost to a full receive buffer, {len(unit.truth.log)} commands run"
               + (f", lines run twice: {twice[:20]}" if twice else "") + ")")
