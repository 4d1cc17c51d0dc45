"""The queue replay's one sequential scan, compiled: vectors and modal parameters only.

The same rules as ``conform.unit.motion.MotionExecutor`` (``_plan_head``, ``advance``,
``_complete`` and the final drain of ``queue.replay``) for a session that never halts,
clears, parks or resets the queue: the executor's state lives in two small arrays, the
queue is a head index into the vectors in push order, and every vector's modal parameters
(V, A, B, $, T, VK/VN) are given as columns, captured at its push as the executor does.
Sessions with H, G, D, K, R or J take the Python executor (``queue.replay`` decides; a
streamed replay hands this scan's state over to it at the first of them).
``tests/test_analysis_replay.py`` checks that both give the same completions.
"""

from __future__ import annotations

from math import sqrt

import numpy as np
from numba import njit

from conform.families.gve.unit.kinematics import plan

_REST, _JOIN, _PENDING = 0, 1, -1
# float state
T0, TEND, LEN, VJ, VPEAK, TDEC, VSTART, VIN, V, READY, PROF = range(11)  # PROF: 8 slots
# int state
H, N, PLANNED, EXIT, DRY, STARVED, NDONE = range(7)


# the kinematics' own profile planner, compiled (one source for both paths)
_plan = njit(cache=True, nogil=True)(plan)


@njit(cache=True, nogil=True)
def _set_prof(F: np.ndarray, p: tuple) -> None:
    for i in range(8):
        F[PROF + i] = p[i]


@njit(cache=True, nogil=True)
def _plan_head(F: np.ndarray, I: np.ndarray, d: np.ndarray, cont: np.ndarray,  # noqa: E741
               ps: np.ndarray, pv: np.ndarray, pa: np.ndarray, pb: np.ndarray,
               pshort: np.ndarray, pvk: np.ndarray, tacc: np.ndarray, max_rate: float) -> None:
    h = I[H]
    p = ps[h]
    t0 = F[READY]
    if tacc[h] > t0:
        t0 = tacc[h]
    v0 = F[V]
    dom = 0
    for k in range(d.shape[1]):
        x = abs(d[h, k])
        if x > dom:
            dom = x
    cap = pv[p]
    length = 0.0
    if dom:
        if pvk[p]:
            x = d[h, 0]
            y = d[h, 1]
            z = d[h, 2] if d.shape[1] > 2 else 0
            length = sqrt(x * x + y * y + z * z)
            if length < dom:
                length = float(dom)
        else:
            length = float(dom)
        if max_rate:
            c = max_rate * length / dom
            if c < cap:
                cap = c
    b = pb[p]
    vj = b if b < cap else cap
    vpeak = vj if dom < pshort[p] else cap
    F[LEN] = length
    F[VJ] = vj
    F[VPEAK] = vpeak
    F[T0] = t0
    F[VSTART] = t0
    F[VIN] = v0
    I[PLANNED] = 1
    if I[DRY]:
        I[DRY] = 0
        I[STARVED] = 1 if cont[h] else 0
    else:
        I[STARVED] = 0
    a = pa[p]
    more = I[N] - h > 1
    if not cont[h]:
        ex = _REST
    elif more:
        ex = (_JOIN if tacc[h + 1] <= t0 else _PENDING) if cont[h + 1] else _REST
    else:
        ex = _PENDING
    if ex == _JOIN:
        prof = _plan(length, v0, vj, vpeak, a)
    else:
        prof = _plan(length, v0, 0.0, vpeak, a)
        if ex == _PENDING:
            tdec = t0 + prof[2] + prof[4]
            F[TDEC] = tdec
            if more:
                if tacc[h + 1] <= tdec:
                    ex = _JOIN
                    prof = _plan(length, v0, vj, vpeak, a)
                else:
                    ex = _REST
    I[EXIT] = ex
    _set_prof(F, prof)
    F[TEND] = t0 + prof[2] + prof[4] + prof[5]


@njit(cache=True, nogil=True)
def replay_vectors(ev_t: np.ndarray, ev_push: np.ndarray, d: np.ndarray, cont: np.ndarray,
                   ps: np.ndarray, tacc: np.ndarray, pv: np.ndarray, pa: np.ndarray,
                   pb: np.ndarray, pshort: np.ndarray, ppause: np.ndarray, pvk: np.ndarray,
                   max_rate: float, guard_limit: int, F: np.ndarray, I: np.ndarray  # noqa: E741
                   ) -> tuple:
    """Advance to every ``ev_t`` (pushing vector ``ev_push`` after it when >= 0, which must
    be the next index, ``I[N]``), then, if ``guard_limit`` >= 0, run the queue out as
    ``queue.replay`` does (at most ``guard_limit`` steps). Vector ``i`` arrived at
    ``tacc[i]`` and moves by ``d[i]`` with the parameters of row ``ps[i]`` of the tables
    ``pv`` (V), ``pa`` (A), ``pb`` (B), ``pshort`` ($), ``ppause`` (T) and ``pvk`` (VK).

    ``F`` and ``I`` (``new_state()``) are the executor's state, carried from one call to the
    next: a session may be replayed a chunk of events at a time, the vectors still queued
    (``I[H]`` to ``I[N]``) moved to the front of the next call's arrays.
    Returns this call's completions in order: (index, t_start, t_end, v_in, v_out, rest,
    starved).
    """
    nv = d.shape[0]
    I[NDONE] = 0
    seq = np.empty(nv, np.int64)
    t_start = np.empty(nv)
    t_end = np.empty(nv)
    v_in = np.empty(nv)
    v_out = np.empty(nv)
    rest = np.empty(nv, np.bool_)
    starved = np.empty(nv, np.bool_)
    m = len(ev_t)
    k = 0
    guard = 0
    while True:
        push = -1
        if k < m:
            t = ev_t[k]
            push = ev_push[k]
            k += 1
        else:  # the final drain: next_event_time(), then advance to it
            if guard >= guard_limit:  # also a call that is not the last (guard_limit < 0)
                break
            if not I[PLANNED]:
                if I[H] >= I[N]:
                    break
                _plan_head(F, I, d, cont, ps, pv, pa, pb, pshort, pvk, tacc, max_rate)
            t = F[TEND]
            guard += 1
        # advance(t)
        while True:
            if not I[PLANNED]:
                if I[H] < I[N]:
                    _plan_head(F, I, d, cont, ps, pv, pa, pb, pshort, pvk, tacc, max_rate)
                else:
                    break
            if I[EXIT] < 0:
                h = I[H]
                if I[N] - h > 1:
                    if cont[h + 1] and tacc[h + 1] <= F[TDEC]:
                        I[EXIT] = _JOIN
                        prof = _plan(F[LEN], F[PROF], F[VJ], F[VPEAK], F[PROF + 7])
                        _set_prof(F, prof)
                        F[TEND] = F[T0] + prof[2] + prof[4] + prof[5]
                    else:
                        I[EXIT] = _REST
                elif t >= F[TDEC]:
                    I[EXIT] = _REST
                else:
                    break
            if F[TEND] > t:
                break
            # _complete()
            h = I[H]
            I[H] = h + 1
            I[PLANNED] = 0
            tend = F[TEND]
            if I[EXIT] == _JOIN:
                F[V] = F[PROF + 6]
                F[READY] = tend
                r = False
            else:
                F[V] = 0.0
                F[READY] = tend + ppause[ps[h]]
                r = True
                if cont[h] and (I[H] >= I[N] or cont[I[H]]):
                    I[DRY] = 1
            j = I[NDONE]
            seq[j] = h
            t_start[j] = F[VSTART]
            t_end[j] = tend
            v_in[j] = F[VIN]
            v_out[j] = F[PROF + 6]
            rest[j] = r
            starved[j] = I[STARVED] != 0
            I[NDONE] = j + 1
        if push >= 0:
            I[N] += 1
    n = I[NDONE]
    return seq[:n], t_start[:n], t_end[:n], v_in[:n], v_out[:n], rest[:n], starved[:n]


def new_state() -> tuple[np.ndarray, np.ndarray]:
    """The state of an executor that has done nothing yet: (floats, integers)."""
    return np.zeros(PROF + 8), np.zeros(7, np.int64)
