"""The text grbl sends: banner, status report, ``$$``, ``$#``, ``$N``, ``$I`` and feedback
messages, formatted as gnea/grbl grbl/report.c prints them (CR LF after every line)."""

from __future__ import annotations

from conform.families.grbl.protocol.gcode import MM_PER_INCH, Modal
from conform.families.grbl.spec.load import GrblSpec, Variant

HELP = "[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]"
MSG = {
    "reset": "[MSG:Reset to continue]",
    "locked": "[MSG:'$H'|'$X' to unlock]",
    "unlocked": "[MSG:Caution: Unlocked]",
    "enabled": "[MSG:Enabled]",
    "disabled": "[MSG:Disabled]",
    "pgm_end": "[MSG:Pgm End]",
    "restore": "[MSG:Restoring defaults]",
    "sleep": "[MSG:Sleeping]",
    "spindle_restore": "[MSG:Restoring spindle]",
    "door": "[MSG:Check Door]",
}


def line(text: str) -> bytes:
    return text.encode("latin-1") + b"\r\n"


def banner(v: Variant) -> bytes:
    """A blank line, then the welcome line (report.c report_init_message)."""
    return b"\r\n" + line(v.banner)


def axes(values: list[float], inches: bool) -> str:
    if inches:
        return ",".join(f"{x / MM_PER_INCH + 0.0:.4f}" for x in values)
    return ",".join(f"{round(x, 3) + 0.0:.3f}" for x in values)


def settings_lines(spec: GrblSpec, settings: dict[int, float]) -> list[str]:
    out = []
    for n, s in spec.settings.items():
        out.append(f"${n}={s.text(settings[n])}")
    return out


def params_lines(m: Modal, prb: list[float], prb_ok: bool, inches: bool) -> list[str]:
    out = [f"[G{54 + i}:{axes(c, inches)}]" for i, c in enumerate(m.coords)]
    out.append(f"[G28:{axes(m.g28, inches)}]")
    out.append(f"[G30:{axes(m.g30, inches)}]")
    out.append(f"[G92:{axes(m.g92, inches)}]")
    tlo = m.tlo / MM_PER_INCH if inches else m.tlo
    out.append(f"[TLO:{tlo:.{4 if inches else 3}f}]")
    out.append(f"[PRB:{axes(prb, inches)}:{1 if prb_ok else 0}]")
    return out


def build_lines(v: Variant, info: str) -> list[str]:
    return [f"[VER:{v.version}.{v.build}:{info}]",
            f"[OPT:{v.options},{v.planner_blocks},{v.rx_buffer}]"]
