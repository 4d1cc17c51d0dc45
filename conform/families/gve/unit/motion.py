"""The reference unit's vector executor: the L/C queue and its timing, driven by explicit times.

Sans-I/O: the executor never reads a clock and never sleeps. The caller (the unit model, the
analyser replaying a capture, a benchmark) says what time it is with :meth:`advance` and the
executor completes whatever has finished by then. ``push`` only appends; a vector is planned
lazily when it becomes the head of the queue, so pushing stays O(1).

The rules (GVE64 §13.5.2-13.5.5, §13.5.9) and every choice the manual leaves open are written
down in ``docs/motion-model.md``; the short version:

* a vector's modal parameters (V, A, B, $, T, VK/VN, VL) are captured when it is pushed;
* an L vector and a C vector not followed by a C vector end at rest, then the next vector
  waits the T pause of the one that ended;
* a C vector ends at ``min(B, its speed cap)`` if its successor C was queued no later than the
  moment its stop ramp would have had to begin; otherwise it stops (starvation);
* a vector shorter than ``$`` (dominant-axis pulses) aims at that junction speed, a long one
  at its capped V;
* HALT brakes at the running vector's A, carrying on into queued C vectors if the ramp is
  longer than what is left of the vector; G finishes the stopped vector from rest.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from math import sqrt
from typing import NamedTuple

from conform.families.gve.unit.kinematics import brake, distance_at, length_of, path_length, plan, progress
from conform.families.gve.unit.kinematics import speed_at as _profile_speed
from conform.families.gve.unit.kinematics import speed_cap as _speed_cap

MIN_SPEED = 1.0
"""Floor for speeds after XA/XU/XD/XM (pulses/s), so that a zero percent never stalls time."""

# Exit decisions of the head vector.
_PENDING = -1
_REST = 0
_JOIN = 1


class MotionStateError(RuntimeError):
    """An executor operation that the unit refuses in its current state (e.g. D while running).

    The unit model maps it to an answer code (7 for "not allowed while running").
    """


@dataclass(frozen=True, slots=True)
class MotionParams:
    """Modal motion parameters, captured by every vector when it is pushed.

    ``v`` V in pulses/s; ``a`` acceleration in pulses/s² (the command's A times 1000);
    ``b`` B brake speed in pulses/s; ``short`` the ``$`` threshold in dominant-axis pulses;
    ``pause`` T in seconds; ``vk`` True for VK (Euclidean path speed), False for VN;
    ``vl`` per-axis limits in pulses/s or None. Defaults follow the GVE64 reset state
    (``specs/gve/variants.toml``: A20 V1000 $512 B35000 T5 VN).
    """

    v: float = 1000.0
    a: float = 20000.0
    b: float = 35000.0
    short: int = 512
    pause: float = 0.005
    vk: bool = False
    vl: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if not (self.v > 0 and self.a > 0 and self.b > 0 and self.pause >= 0):
            raise ValueError(f"motion parameters out of range: {self!r}")
        if self.vl is not None and not all(x > 0 for x in self.vl):
            raise ValueError(f"VL limits must be positive: {self.vl!r}")

    def replace(self, **changes: object) -> MotionParams:
        """A copy with some fields changed (the modal commands use this)."""
        return replace(self, **changes)


class Completion(NamedTuple):
    """One finished vector, as recorded in :attr:`MotionExecutor.log`.

    ``seq`` counts pushes from 0; ``t_start`` is when the vector (or its remainder after G)
    began moving; ``rest`` is True if it ended at rest (T pause follows); ``starved`` is True if
    it started from rest only because its C predecessor had no successor in time.
    """

    seq: int
    t_start: float
    t_end: float
    v_in: float
    v_out: float
    rest: bool
    starved: bool


# Speed functions for apply_speed (the unit model chooses the rounding it believes in).
def speed_xa(v_last: float) -> Callable[[float], float]:
    """XA: every queued vector gets the last V."""
    return lambda _v: v_last


def speed_xu(v: float) -> float:
    """XU: up by 1/16 of the current speed."""
    return v * 17.0 / 16.0


def speed_xd(v: float) -> float:
    """XD: down by 1/16 of the current speed."""
    return v * 15.0 / 16.0


def speed_xm(v_last: float, percent: float) -> Callable[[float], float]:
    """XM n: every queued vector gets n % of the last V (VL still caps at execution)."""
    return lambda _v: v_last * percent / 100.0


class MotionExecutor:
    """The vector queue of one unit and the motion it produces, in virtual time.

    Call :meth:`advance` with the current time before every operation that depends on time
    (``push`` stamps the vector with the time of the last ``advance``). Times are floats in
    seconds and must never go backwards.
    """

    __slots__ = (
        "axes", "capacity", "max_rate", "params", "log", "completed", "starvations",
        "_q", "_now", "_pos", "_done", "_seq",
        "_planned", "_t0", "_soff", "_prof", "_tend", "_len", "_dom", "_vj", "_vpeak",
        "_exit", "_tdec", "_final", "_vstart", "_vin", "_vstarved",
        "_v", "_ready", "_dry",
        "_halted", "_t_stop", "_forced", "_hoff", "_go", "_parked",
    )

    def __init__(self, axes: int = 4, capacity: int = 420, max_rate: float = 0.0,
                 params: MotionParams | None = None, log: list | None = None) -> None:
        self.axes = axes
        self.capacity = capacity
        self.max_rate = float(max_rate or 0.0)
        self.params = params or MotionParams()
        self.log = log
        self.completed = 0
        self.starvations = 0
        self._q: deque = deque()
        self._now = 0.0
        self._pos = [0] * axes
        self._done: list = []
        self._seq = 0
        self._planned = False
        self._t0 = self._soff = self._tend = self._len = self._tdec = 0.0
        self._vj = self._vpeak = self._vstart = self._vin = 0.0
        self._prof: tuple = (0.0,) * 8
        self._dom = 0
        self._exit = _REST
        self._final = True
        self._vstarved = False
        self._v = 0.0
        self._ready = 0.0
        self._dry = False
        self._halted = False
        self._t_stop = 0.0
        self._forced: deque = deque()
        self._hoff = 0.0
        self._go = False
        self._parked: tuple | None = None

    # ------------------------------------------------------------------ queue input
    def push(self, d: Sequence[int], cont: bool = True) -> None:
        """Queue a vector (relative pulses per axis), stamped with the last advance() time.

        ``d`` must have exactly :attr:`axes` entries. Does not check the capacity: the unit
        model answers 1 when :attr:`queue_len` has reached :attr:`capacity` and does not push.
        """
        if len(d) != self.axes:
            raise ValueError(f"vector {d!r} does not have {self.axes} axes")
        self._q.append((d, cont, self.params, self._now, self._seq))
        self._seq += 1

    @property
    def queue_len(self) -> int:
        """Vectors accepted and not finished, the running (or stopped) one included."""
        return len(self._q)

    @property
    def now(self) -> float:
        """The time of the last advance()."""
        return self._now

    @property
    def running(self) -> bool:
        """True while vectors are being executed (moving, pausing between them or braking)."""
        if not self._q:
            return False
        if self._halted:
            return self._planned
        return True

    @property
    def interrupted(self) -> bool:
        """True after halt() until resume(), clear() or park()."""
        return self._halted

    @property
    def braking(self) -> bool:
        """True while a halt ramp is still under way."""
        return self._halted and self._planned

    @property
    def parked(self) -> bool:
        """True between park() and restore()."""
        return self._parked is not None

    # ------------------------------------------------------------------ time
    def advance(self, t: float) -> int:
        """Complete every vector that finishes by ``t``; return how many did."""
        if t < self._now:
            raise ValueError(f"time went backwards: {t} < {self._now}")
        self._now = t
        n = 0
        q = self._q
        while True:
            if not self._planned:
                if self._halted:
                    if self._forced:
                        self._load_forced()
                    elif self._go:
                        self._go = False
                        self._halted = False
                        if self._ready < self._t_stop:
                            self._ready = self._t_stop
                        continue
                    else:
                        break
                elif q:
                    self._plan_head()
                else:
                    break
            if self._exit < 0:
                if len(q) > 1:
                    nxt = q[1]
                    if nxt[1] and nxt[3] <= self._tdec:
                        self._exit = _JOIN
                        p = self._prof
                        self._prof = p = plan(self._len - self._soff, p[0], self._vj,
                                              self._vpeak, p[7])
                        self._tend = self._t0 + p[2] + p[4] + p[5]
                    else:
                        self._exit = _REST
                elif t >= self._tdec:
                    self._exit = _REST
                else:
                    break
            if self._tend > t:
                break
            if self._final:
                self._complete()
                n += 1
            else:
                self._stop()
        return n

    def next_event_time(self) -> float | None:
        """When the running vector (or the halt ramp) ends, if nothing else is pushed.

        None when nothing is queued or the unit is interrupted and at rest. The answer may
        change after push(), apply_speed(), halt() or resume().
        """
        if not self._planned:
            if self._halted or not self._q:
                return None
            self._plan_head()
        return self._tend

    # ------------------------------------------------------------------ position
    @property
    def position(self) -> tuple[int, ...]:
        """Position counters at the time of the last advance()."""
        return self._position(self._now)

    def position_at(self, t: float) -> tuple[int, ...]:
        """Advance to ``t`` and return the position counters then."""
        self.advance(t)
        return self._position(t)

    def speed_at(self, t: float) -> float:
        """Advance to ``t`` and return the path speed then (0 at rest)."""
        self.advance(t)
        if not self._planned or t < self._t0:
            return 0.0
        return _profile_speed(self._prof, t - self._t0)

    def _position(self, t: float) -> tuple[int, ...]:
        pos = self._base()
        if not self._planned:
            return tuple(pos)
        s = self._soff + distance_at(self._prof, t - self._t0)
        off = progress(self._q[0][0], self._dom, self._len, s)
        return tuple(p + o for p, o in zip(pos, off, strict=True))

    def _base(self) -> list[int]:
        """The counters (the head's start while it runs), with finished vectors added in."""
        done = self._done
        if done:
            self._pos = [p + s for p, s in zip(self._pos, map(sum, zip(*done, strict=True)),
                                                    strict=True)]
            done.clear()
        return self._pos

    def set_position(self, axis: int, value: int) -> None:
        """Set one position counter (N<axis>); refused while running."""
        if self.running:
            raise MotionStateError("position counters cannot be set while running")
        self._base()[axis] = int(value)

    def zero(self) -> None:
        """Zero every position counter (N); refused while running."""
        if self.running:
            raise MotionStateError("position counters cannot be zeroed while running")
        self._done.clear()
        self._pos = [0] * self.axes

    # ------------------------------------------------------------------ HALT / G / D / K / R
    def halt(self, t: float) -> float:
        """Brake the running vector at its A from time ``t``; return when motion stops.

        The unit is interrupted afterwards whether or not anything was moving. If the ramp
        is longer than what is left of the vector, it carries on into the queued C vectors
        (which then count as finished); it never crosses into an L vector or past a vector
        that was to end at rest, where the motion simply ends.
        """
        self.advance(t)
        if self._halted:
            self._go = False
            return self._tend if self._planned else max(t, self._t_stop)
        self._halted = True
        self._t_stop = t
        q = self._q
        if not q:
            return t
        if not self._planned:
            self._plan_head()
        dt = t - self._t0
        prof = self._prof
        s = self._soff + distance_at(prof, dt)
        v = _profile_speed(prof, dt) if dt >= 0.0 else 0.0
        if v <= 0.0:
            self._stop_at(s)
            return t
        if self._exit == _JOIN:
            join = True
        elif self._exit == _PENDING:
            join = len(q) > 1 and q[1][1] and q[1][3] <= self._tdec
        else:
            join = False
        bp = brake(v, prof[7], self._len - s)
        self._t0 = t
        self._soff = s
        self._prof = bp
        self._tend = tc = t + bp[5]
        self._final = bp[6] > 0.0
        self._exit = _JOIN if join else _REST
        v = bp[6]
        k = 1
        forced = self._forced
        while join and v > 0.0 and k < len(q):
            d, _c, p, _ta, _s = q[k]
            length, dom = path_length(d, p.vk)
            bp = brake(v, p.a, length)
            v = bp[6]
            forced.append((tc, bp, v > 0.0, length, dom))
            tc += bp[5]
            k += 1
            join = k < len(q) and q[k][1]
        self._t_stop = tc
        return tc

    def resume(self, t: float) -> bool:
        """G: finish the stopped vector from rest, then the queue; False if not interrupted.

        If a halt ramp is still under way at ``t`` the motion restarts when it ends.
        """
        self.advance(t)
        if not self._halted:
            return False
        if self._planned:
            self._go = True
            return True
        self._halted = False
        if self._ready < t:
            self._ready = t
        return True

    def clear(self) -> None:
        """D: delete every queued vector, the stopped one included; position kept."""
        if self.running:
            raise MotionStateError("D is not allowed while running")
        self._q.clear()
        self._halted = False
        self._hoff = 0.0
        self._dry = False
        self._forced.clear()

    def park(self) -> None:
        """K: set the queue (and the interrupted state) aside; only L vectors may follow."""
        if self.running:
            raise MotionStateError("K is not allowed while running")
        if self._parked is not None:
            raise MotionStateError("K twice without R")
        self._parked = (self._q, self._halted, self._hoff, self._t_stop)
        self._q = deque()
        self._halted = False
        self._hoff = 0.0
        self._dry = False

    def restore(self) -> None:
        """R: bring back what park() set aside (the interrupted state included)."""
        if self.running:
            raise MotionStateError("R is not allowed while running")
        if self._parked is None:
            raise MotionStateError("R without K")
        if self._q:
            raise MotionStateError("R with vectors still queued since K")
        self._q, self._halted, self._hoff, t_stop = self._parked
        self._parked = None
        self._dry = False
        if self._t_stop < t_stop:
            self._t_stop = t_stop

    # ------------------------------------------------------------------ XA / XU / XD / XM
    def apply_speed(self, t: float, fn: Callable[[float], float],
                    accel: float | None = None) -> None:
        """Change V (and, with ``accel`` in pulses/s², A) of every queued vector at ``t``.

        The running vector is replanned from its current speed and place; a halt ramp is
        left alone. Speeds are floored at :data:`MIN_SPEED`.
        """
        self.advance(t)
        memo: dict[int, MotionParams] = {}

        def conv(p: MotionParams) -> MotionParams:
            np = memo.get(id(p))
            if np is None:
                v = fn(p.v)
                np = p.replace(v=v if v > MIN_SPEED else MIN_SPEED,
                               a=p.a if accel is None else accel)
                memo[id(p)] = np
            return np

        self._q = q = deque((d, c, conv(p), ta, s) for d, c, p, ta, s in self._q)
        if not self._planned or self._halted:
            return
        d, _c, p, _ta, _s = q[0]
        cap = _speed_cap(d, self._len, self._dom, p.v, p.vl, self.max_rate)
        self._vj = vj = p.b if p.b < cap else cap
        self._vpeak = vpeak = vj if self._dom < p.short else cap
        prof = self._prof
        if t > self._t0:
            dt = t - self._t0
            self._soff += distance_at(prof, dt)
            v0 = _profile_speed(prof, dt)
            self._t0 = t
        else:
            v0 = prof[0]
        rem = self._len - self._soff
        if rem < 0.0:
            rem = 0.0
        prof = plan(rem, v0, vj if self._exit == _JOIN else 0.0, vpeak, p.a)
        self._prof = prof
        self._tend = self._t0 + prof[2] + prof[4] + prof[5]
        if self._exit == _PENDING:
            self._tdec = self._t0 + prof[2] + prof[4]

    # ------------------------------------------------------------------ internals
    def _plan_head(self) -> None:
        """Plan the head of the queue from rest or from the previous vector's exit speed."""
        q = self._q
        d, cont, p, tacc, _seq = q[0]
        t0 = self._ready
        if tacc > t0:
            t0 = tacc
        v0 = self._v
        dom = max(map(abs, d))
        cap = p.v
        if dom:
            if p.vk:
                x = d[0]
                y = d[1]
                z = d[2] if len(d) > 2 else 0
                length = sqrt(x * x + y * y + z * z)
                if length < dom:
                    length = float(dom)
            else:
                length = float(dom)
            mr = self.max_rate
            if mr:
                c = mr * length / dom
                if c < cap:
                    cap = c
            if p.vl is not None:
                cap = _speed_cap(d, length, dom, cap, p.vl)
        else:
            length = 0.0
        b = p.b
        vj = b if b < cap else cap
        vpeak = vj if dom < p.short else cap
        self._len = length
        self._dom = dom
        self._vj = vj
        self._vpeak = vpeak
        soff = self._hoff
        if soff:
            self._pos = [a - o for a, o in zip(self._base(), progress(d, dom, length, soff),
                                                strict=True)]
            length -= soff
        self._soff = soff
        self._t0 = t0
        self._vstart = t0
        self._vin = v0
        self._final = True
        self._planned = True
        if self._dry:
            self._dry = False
            self._vstarved = cont
            if cont:
                self.starvations += 1
        else:
            self._vstarved = False
        a = p.a
        if not cont:
            ex = _REST
        elif len(q) > 1:
            nxt = q[1]
            ex = (_JOIN if nxt[3] <= t0 else _PENDING) if nxt[1] else _REST
        else:
            ex = _PENDING
        if ex == _JOIN:
            prof = plan(length, v0, vj, vpeak, a)
        else:
            prof = plan(length, v0, 0.0, vpeak, a)
            if ex == _PENDING:
                self._tdec = tdec = t0 + prof[2] + prof[4]
                if len(q) > 1:
                    if q[1][3] <= tdec:
                        ex = _JOIN
                        prof = plan(length, v0, vj, vpeak, a)
                    else:
                        ex = _REST
        self._exit = ex
        self._prof = prof
        self._tend = t0 + prof[2] + prof[4] + prof[5]

    def _complete(self) -> None:
        """The head finished: move the counters, hand its exit speed to the next vector."""
        q = self._q
        d, cont, p, _ta, seq = q.popleft()
        done = self._done
        done.append(d)
        if len(done) >= 1024:
            self._base()
        self.completed += 1
        self._planned = False
        self._hoff = 0.0
        tend = self._tend
        if self._halted:
            rest = not self._forced
            self._v = 0.0 if rest else self._prof[6]
            self._ready = tend + p.pause if rest else tend
        elif self._exit == _JOIN:
            self._v = self._prof[6]
            self._ready = tend
            rest = False
        else:
            self._v = 0.0
            self._ready = tend + p.pause
            rest = True
            if cont and (not q or q[0][1]):
                self._dry = True
        if self.log is not None:
            self.log.append(Completion(seq, self._vstart, tend, self._vin, self._prof[6],
                                       rest, self._vstarved))

    def _stop(self) -> None:
        """A halt ramp ended inside the head vector: keep the rest of it for G."""
        self._stop_at(self._soff + length_of(self._prof))

    def _stop_at(self, s: float) -> None:
        d = self._q[0][0]
        off = progress(d, self._dom, self._len, s)
        self._pos = [a + o for a, o in zip(self._base(), off, strict=True)]
        self._hoff = s
        self._planned = False
        self._v = 0.0

    def _load_forced(self) -> None:
        """The next segment of a halt ramp that runs on into queued C vectors."""
        t0, prof, final, length, dom = self._forced.popleft()
        self._t0 = self._vstart = t0
        self._vin = prof[0]
        self._vstarved = False
        self._prof = prof
        self._tend = t0 + prof[5]
        self._final = final
        self._len = length
        self._dom = dom
        self._soff = 0.0
        self._exit = _JOIN if final else _REST
        self._planned = True
