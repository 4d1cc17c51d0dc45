"""Bring a reference unit into the state a worked example names (specs/gve/examples.toml `given`).

Only protocol commands are used (no reaching into the model), so the same steps describe
what a test must send to any target: ``checksum-on`` -> ``%+``; ``st<n>=<hex>`` -> ``SWn,x``;
``inta`` -> ``H``; ``position=x,y,z`` -> ``N<axis>`` where the variant has it, else ``N`` and
one L vector, run to its end; ``queue-full`` -> ``V10`` then C vectors until the answer is 1.
"""

from __future__ import annotations

from collections.abc import Sequence

from conform.families.gve.protocol.checksum import append_checksum
from conform.families.gve.unit.model import Unit, run_until_idle


class GivenError(ValueError):
    """A `given` item the helper does not know or could not reach."""


def command(unit: Unit, body: bytes) -> bytes:
    """``body`` (``b"!0V10"``) framed for the unit's current checksum mode."""
    return (append_checksum(body) if unit.checksum_on else body) + b"\r"


def send(unit: Unit, body: bytes, t: float) -> tuple[float, bytes]:
    """Exchange one command body; return (time of the answer, answer bytes)."""
    return unit.exchange(command(unit, body), t)


def drive_given(unit: Unit, given: Sequence[str], t: float = 0.0) -> float:
    """Send what ``given`` needs, in order; return the time after the last answer."""
    addr = b"!%d" % unit.variant.interpolator_address
    for item in given:
        key, _, value = item.partition("=")
        if key == "checksum-on":
            t, ans = send(unit, addr + b"%+", t)
        elif key.startswith("st") and key[2:].isdigit():
            t, ans = send(unit, addr + b"SW%s,%s" % (key[2:].encode(), value.encode()), t)
        elif key == "inta":
            t, ans = send(unit, addr + b"H", t)
            ans = ans[:1].replace(b"8", b"0")
        elif key == "position":
            t, ans = _position(unit, addr, [int(v) for v in value.split(",")], t)
        elif key == "queue-full":
            t, ans = _fill(unit, addr, t)
        else:
            raise GivenError(f"unknown given item {item!r}")
        if ans[:1] not in (b"0", b"8"):
            raise GivenError(f"{item!r}: the unit answered {ans!r}")
    return t


def _position(unit: Unit, addr: bytes, target: list[int], t: float) -> tuple[float, bytes]:
    axes = unit.variant.axes
    if unit.variant.has("N<axis>"):
        ans = b"0"
        for axis, value in zip(axes, target, strict=False):
            t, ans = send(unit, addr + b"N%s%d" % (axis.encode(), value), t)
        return t, ans
    t, ans = send(unit, addr + b"N", t)
    vector = list(target) + [0] * (len(axes) - len(target))
    t, ans = send(unit, addr + b"L" + b",".join(b"%d" % v for v in vector), t)
    return run_until_idle(unit, t), ans


def _fill(unit: Unit, addr: bytes, t: float) -> tuple[float, bytes]:
    t, ans = send(unit, addr + b"V10", t)
    for _ in range(unit.variant.queue + 2):
        t, ans = send(unit, addr + b"C1000,0,0", t)
        if ans[:1] == b"1":
            return t, b"0"
    raise GivenError("queue-full: the queue never filled")
