"""``conform emulate serve grbl-…``: the grbl reference unit behind a pty or TCP, through the
same serving adapter as GVE (:class:`conform.emulator.serve.Emulator`: wire pacing, faults,
recording, reconnects), with a control socket (:mod:`.control`: input pins and faults)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

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


def serve(variant: str, *, faults: str | None = None, seed: int | None = None,
          answer_delay: float = 0.0, **served: Any) -> None:
    from conform.emulator.launch import ServedUnit, serve_unit
    from conform.families.grbl.spec.load import load_grbl
    from conform.families.grbl.unit.control import GrblControl
    from conform.families.grbl.unit.faults import GrblFaults
    from conform.families.grbl.unit.model import GrblUnit
    from conform.link.faults import FaultConfig

    spec = load_grbl()
    v = spec.variant(variant)
    config = FaultConfig.parse(faults) if faults else FaultConfig()

    def build(t_start: float) -> ServedUnit:
        unit = GrblUnit(v, spec, t0=t_start, line_time=max(answer_delay, 0.0005))
        injector = GrblFaults(config, seed, t_start)
        # backdate=False: the emulator reads a pty's bytes at once and paces them itself, so a
        # host line dated a wire time early would seem sent before the answer it waited for
        return ServedUnit(
            unit, describe=f"receive buffer {v.rx_buffer} bytes, planner {v.planner_blocks} blocks",
            injector=injector, control_handler=GrblControl(injector), decode=False, backdate=False,
            wrap_reopen=lambda reopen: reopen_with_power_cycle(reopen, unit, injector),
            end_counts=lambda: {"bytes_lost": unit.lost},
            stopped_note=lambda: f", {unit.lost} lost to a full receive buffer")

    serve_unit("grbl", v.id, build, faults=faults, seed=seed, answer_delay=answer_delay, **served)
