"""Speed profiles of one vector: pure functions, plain floats.

The unit moves every vector along a trapezoid (or triangle) of speed against time with one
acceleration ``a`` for speeding up and slowing down (GVE64 §13.5.2-13.5.3). The executor in
:mod:`conform.families.gve.unit.motion` chains these profiles; everything here is stateless so the
analyser and the tests can use the same equations.

Units: distances in path units (pulses of the dominant axis, or the Euclidean length with
VK), speeds in path units per second, accelerations in path units per second squared,
times in seconds.

A profile is a plain 8-tuple ``(v0, a1, t1, vc, t2, t3, ve, a)``:

* phase 1 lasts ``t1`` and changes the speed from ``v0`` to ``vc`` at rate ``a1``
  (``+a``, ``-a`` or 0);
* phase 2 cruises at ``vc`` for ``t2``;
* phase 3 brakes at rate ``a`` from ``vc`` to ``ve`` for ``t3`` (the final ramp; a profile
  that only brakes has ``t1 == t2 == 0``).

:class:`Profile` names the fields; the executor uses bare tuples on its hot path.
"""

from __future__ import annotations

from math import sqrt
from typing import NamedTuple


class Profile(NamedTuple):
    """One vector's speed profile (see the module docstring for the phases)."""

    v0: float
    a1: float
    t1: float
    vc: float
    t2: float
    t3: float
    ve: float
    a: float


def plan(length: float, v0: float, v_exit: float, v_peak: float, a: float) -> tuple:
    """Plan the fastest profile over ``length`` from ``v0`` that ends at ``v_exit``.

    The speed never exceeds ``v_peak`` except while braking down from an entry speed that is
    already above it. ``v_exit`` is clipped to ``v_peak``. When ``v_exit`` cannot be reached
    within ``length`` (too short to brake down to it, or to speed up to it) the profile ends
    at the speed that is reachable, which is then its ``ve``. A zero length passes the entry
    speed through in zero time.
    """
    if v_exit > v_peak:
        v_exit = v_peak
    if length <= 0.0:
        return (v0, 0.0, 0.0, v0, 0.0, 0.0, v0, a)
    two_a = a + a
    v02 = v0 * v0
    ve2 = v_exit * v_exit
    vp2 = v_peak * v_peak
    d3 = (vp2 - ve2) / two_a
    if v0 <= v_peak:
        d1 = (vp2 - v02) / two_a
        if d1 + d3 <= length:
            return (v0, a, (v_peak - v0) / a, v_peak, (length - d1 - d3) / v_peak,
                    (v_peak - v_exit) / a, v_exit, a)
        vm2 = (two_a * length + v02 + ve2) * 0.5
        if vm2 <= v02:
            # Too short to brake from v0 down to v_exit: brake all the way.
            vx2 = v02 - two_a * length
            vx = sqrt(vx2) if vx2 > ve2 else v_exit
            return (v0, 0.0, 0.0, v0, 0.0, (v0 - vx) / a, vx, a)
        if vm2 >= ve2:
            vm = sqrt(vm2)
            if vm2 > ve2:
                return (v0, a, (vm - v0) / a, vm, 0.0, (vm - v_exit) / a, v_exit, a)
            return (v0, a, (vm - v0) / a, vm, 0.0, 0.0, vm, a)
        # Too short to speed up from v0 to v_exit: accelerate all the way.
        vx = sqrt(v02 + two_a * length)
        return (v0, a, (vx - v0) / a, vx, 0.0, 0.0, vx, a)
    # Entry above the peak: brake to the peak, cruise, brake to the exit.
    d1 = (v02 - vp2) / two_a
    if d1 + d3 <= length:
        return (v0, -a, (v0 - v_peak) / a, v_peak, (length - d1 - d3) / v_peak,
                (v_peak - v_exit) / a, v_exit, a)
    vx2 = v02 - two_a * length
    vx = sqrt(vx2) if vx2 > ve2 else v_exit
    return (v0, 0.0, 0.0, v0, 0.0, (v0 - vx) / a, vx, a)


def duration(p: tuple) -> float:
    """Total time of a profile."""
    return p[2] + p[4] + p[5]


def length_of(p: tuple) -> float:
    """Total distance a profile covers (equals the planned length up to rounding)."""
    v0, _a1, t1, vc, t2, t3, ve, _a = p
    return (v0 + vc) * 0.5 * t1 + vc * t2 + (vc + ve) * 0.5 * t3


def distance_at(p: tuple, t: float) -> float:
    """Distance covered ``t`` seconds after the profile starts (clamped to its ends)."""
    if t <= 0.0:
        return 0.0
    v0, a1, t1, vc, t2, t3, ve, a = p
    if t < t1:
        return (v0 + 0.5 * a1 * t) * t
    d = (v0 + vc) * 0.5 * t1
    t -= t1
    if t < t2:
        return d + vc * t
    d += vc * t2
    t -= t2
    if t < t3:
        return d + (vc - 0.5 * a * t) * t
    return d + (vc + ve) * 0.5 * t3


def speed_at(p: tuple, t: float) -> float:
    """Speed ``t`` seconds after the profile starts (``v0`` before, ``ve`` after)."""
    v0, a1, t1, vc, t2, t3, ve, a = p
    if t <= 0.0:
        return v0
    if t < t1:
        return v0 + a1 * t
    t -= t1 + t2
    if t < 0.0:
        return vc
    if t < t3:
        return vc - a * t
    return ve


def braking_distance(v: float, a: float) -> float:
    """Distance needed to brake from ``v`` to rest at ``a``."""
    return v * v / (a + a)


def braking_time(v: float, a: float) -> float:
    """Time needed to brake from ``v`` to rest at ``a``."""
    return v / a


def brake(v: float, a: float, room: float) -> tuple:
    """Profile of braking from ``v`` at ``a`` within ``room``.

    Stops at rest if the braking distance fits, otherwise ends at the end of ``room`` at the
    speed left (``ve`` > 0).
    """
    if room < 0.0:
        room = 0.0
    v2 = v * v
    rest = v2 / (a + a)
    if rest <= room:
        return (v, 0.0, 0.0, v, 0.0, v / a, 0.0, a)
    vx = sqrt(v2 - 2.0 * a * room)
    return (v, 0.0, 0.0, v, 0.0, (v - vx) / a, vx, a)


def path_length(d: tuple, vk: bool) -> tuple[float, int]:
    """``(length, dominant)`` of a relative vector ``d`` (pulses per axis).

    ``dominant`` is max |d_i|. The path length that speeds apply to is ``dominant`` with VN,
    and with VK the Euclidean length of the first three axes (X, Y, Z; the manual's formula
    leaves A out), but never less than ``dominant`` so no axis outruns the path speed.
    """
    dom = max(map(abs, d)) if d else 0
    if not vk or dom == 0:
        return float(dom), dom
    e = sqrt(sum(x * x for x in d[:3]))
    return (e if e > dom else float(dom)), dom


def speed_cap(d: tuple, length: float, dom: int, v: float,
              vl: tuple | None = None, max_rate: float = 0.0) -> float:
    """Path speed of a vector: ``v`` capped so no axis exceeds its VL limit or ``max_rate``."""
    cap = v
    if dom == 0:
        return cap
    if max_rate:
        c = max_rate * length / dom
        if c < cap:
            cap = c
    if vl:
        for x, lim in zip(d, vl, strict=False):
            if x:
                c = lim * length / (x if x > 0 else -x)
                if c < cap:
                    cap = c
    return cap


def progress(d: tuple, dom: int, length: float, s: float) -> list[int]:
    """Integer per-axis offsets after ``s`` of ``length`` along ``d``.

    The dominant axis has done ``floor(s / length * dom)`` pulses; every other axis has done
    its share of that, rounded toward the start (toward zero), like a Bresenham stepper.
    """
    if s >= length or dom == 0:
        return list(d)
    if s <= 0.0:
        return [0] * len(d)
    n = int(s * dom / length)
    if n >= dom:
        return list(d)
    return [x * n // dom if x >= 0 else -((-x * n) // dom) for x in d]
