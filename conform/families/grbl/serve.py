"""``conform emulate serve grbl-…``: the grbl reference unit behind a pty or TCP, through the
same serving adapter as GVE (:class:`conform.emulator.serve.Emulator`: wire pacing, faults,
recording, reconnects), with a control socket (:mod:`.control`: input pins and faults)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from conform.errors import UserError

# seconds from power-up to the banner: an Arduino bootloader waits about half a second for an
# upload before grbl starts (an assumption: grbl's documents give no figure)
BOOT = 0.5


def reopen_with_power_cycle(reopen: Callable[[], Any], unit: Any, faults: Any,
                            clock: Callable[[], float] = time.monotonic) -> Callable[[], Any]:
    """The emulator's reopen hook: after an unplugged cable the board restarts (banner,
    planner empty) as the new port appears; after other link drops it just goes on."""
    def again() -> Any:
        if faults.unplugged:
            faults.unplugged = False
            unit.power_cycle(max(clock(), unit.now), boot=BOOT)
        return reopen()

    return again


def serve(variant: str, *, baud: int | None = None, tcp_port: int | None = None,
          faults: str | None = None, seed: int | None = None, link_path: str | None = None,
          record_path: str | None = None, answer_delay: float = 0.0,
          control_path: str | None = None, **_ignored: Any) -> None:
    from conform.emulator.launch import announce, check_pacing, control_server, open_endpoint, report, run_until_signal
    from conform.emulator.serve import Emulator
    from conform.families.grbl.spec.load import load_grbl
    from conform.families.grbl.unit.control import GrblControl
    from conform.families.grbl.unit.faults import GrblFaults
    from conform.families.grbl.unit.model import GrblUnit
    from conform.link.faults import FaultConfig

    spec = load_grbl()
    v = spec.variant(variant)
    check_pacing(baud, answer_delay)
    config = FaultConfig.parse(faults) if faults else FaultConfig()
    t_start = time.monotonic()
    unit = GrblUnit(v, spec, t0=t_start, line_time=max(answer_delay, 0.0005))
    injector = GrblFaults(config, seed, t_start)
    endpoint, reopen = open_endpoint(tcp_port, link_path)
    control = control_server(control_path, endpoint)
    recorder = None
    if record_path:
        from conform.capture import Recorder

        try:  # "line_baud", not "baud": see sendercheck.session.run_sender
            recorder = Recorder(record_path, {
                "capture_method": "emulator", "variant": v.id, "family": "grbl",
                "line_baud": baud or "", "unit_port": endpoint.name, "dialect": "",
                "faults": faults or "", "seed": "" if seed is None else seed}, decode=False)
        except UserError:
            endpoint.close()
            control.close()
            raise

    emulator = Emulator(unit, endpoint, baud=baud, injector=injector, recorder=recorder,
                        control=control, reopen=reopen_with_power_cycle(reopen, unit, injector),
                        report=report, control_handler=GrblControl(injector))
    announce(endpoint, f"{v.id} on {endpoint.name} (receive buffer {v.rx_buffer} bytes, "
             f"planner {v.planner_blocks} blocks); control: {control.path}")
    try:
        run_until_signal(emulator)
    finally:
        control.close()
        if recorder is not None:
            recorder.close({"bytes_in": emulator.bytes_in, "bytes_out": emulator.bytes_out,
                            "bytes_lost": unit.lost})
        report(f"stopped ({emulator.bytes_in} bytes in, {emulator.bytes_out} out, "
               f"{unit.lost} lost to a full receive buffer)")
