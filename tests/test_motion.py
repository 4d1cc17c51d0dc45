"""Motion/timing model: kinematics equations and the lazy executor (GVE64 §13.5.2-13.5.9)."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from conform.families.gve.unit.kinematics import (
    brake,
    braking_distance,
    braking_time,
    distance_at,
    duration,
    length_of,
    path_length,
    plan,
    progress,
    speed_at,
    speed_cap,
)
from conform.families.gve.unit.motion import (
    MotionExecutor,
    MotionParams,
    MotionStateError,
    speed_xd,
    speed_xm,
    speed_xu,
)

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
REL = 1e-9


def close(a: float, b: float, tol: float = 1e-7) -> bool:
    return abs(a - b) <= tol * max(1.0, abs(a), abs(b))


def run_to_end(ex: MotionExecutor, limit: int = 100_000) -> float:
    """Advance event by event until the queue is empty; return the final time."""
    for _ in range(limit):
        t = ex.next_event_time()
        if t is None:
            return ex.now
        ex.advance(max(t, ex.now))
    raise AssertionError("executor did not drain")


# ---------------------------------------------------------------- kinematics

speeds = st.floats(min_value=0.0, max_value=200_000.0)
peaks = st.floats(min_value=10.0, max_value=200_000.0)
accels = st.floats(min_value=1_000.0, max_value=2_000_000.0)
lengths = st.floats(min_value=0.0, max_value=1e7)


def test_trapezoid_by_hand():
    # 10000 pulses at V1000 A20 from rest to rest: 0.05 s ramps of 25 pulses each.
    p = plan(10_000, 0.0, 0.0, 1000.0, 20_000.0)
    assert p[2] == pytest.approx(0.05) and p[5] == pytest.approx(0.05)
    assert duration(p) == pytest.approx(10.05)
    assert distance_at(p, 0.05) == pytest.approx(25.0)
    assert speed_at(p, 5.0) == 1000.0


def test_triangle_by_hand():
    # 100 pulses, a = 20000: peak sqrt(a*L) = sqrt(2e6), never reaching V.
    p = plan(100, 0.0, 0.0, 10_000.0, 20_000.0)
    vm = math.sqrt(20_000.0 * 100)
    assert p[3] == pytest.approx(vm) and p[4] == 0.0
    assert duration(p) == pytest.approx(2 * vm / 20_000.0)


def test_unreachable_exit_is_what_is_reachable():
    # Too short to brake from 10000 to 0: it ends at sqrt(v0^2 - 2aL).
    p = plan(100, 10_000.0, 0.0, 10_000.0, 100_000.0)
    assert p[6] == pytest.approx(math.sqrt(1e8 - 2e7))
    # Too short to speed up to the exit speed from rest.
    p = plan(10, 0.0, 5000.0, 5000.0, 100_000.0)
    assert p[6] == pytest.approx(math.sqrt(2e6))


def test_braking_helpers():
    assert braking_distance(1000.0, 20_000.0) == pytest.approx(25.0)
    assert braking_time(1000.0, 20_000.0) == pytest.approx(0.05)
    assert brake(1000.0, 20_000.0, 100.0)[6] == 0.0
    assert brake(1000.0, 20_000.0, 9.0)[6] == pytest.approx(math.sqrt(1e6 - 2 * 20_000 * 9))


def test_path_length_and_caps():
    assert path_length((3000, 4000, 0, 0), False) == (4000.0, 4000)
    assert path_length((3000, 4000, 0, 0), True) == (5000.0, 4000)
    # A is outside the Euclidean sum but never outruns the path speed.
    assert path_length((10, 0, 0, 1000), True) == (1000.0, 1000)
    # VL: the X axis may do 500 pulses/s, so a 45-degree VN vector is capped at 500.
    assert speed_cap((1000, 1000), 1000.0, 1000, 5000.0, (500.0, 10_000.0)) == 500.0
    assert speed_cap((1000, 10), 1000.0, 1000, 5000.0, None, 2000.0) == 2000.0


def test_progress_rounds_toward_start():
    assert progress((1000, 333, -333, 0), 1000, 1000.0, 500.0) == [500, 166, -166, 0]
    assert progress((1000, 333, -333, 0), 1000, 1000.0, 1000.0) == [1000, 333, -333, 0]
    assert progress((0, 0, 0, 0), 0, 0.0, 0.0) == [0, 0, 0, 0]


@SETTINGS
@given(lengths, speeds, speeds, peaks, accels)
def test_profile_is_consistent(length, v0, ve, vp, a):
    p = plan(length, v0, ve, vp, a)
    assert all(x >= 0.0 for x in (p[2], p[4], p[5]))
    assert close(length_of(p), length, 1e-6) or length_of(p) == pytest.approx(length, abs=1e-6)
    ve_target = min(ve, vp)
    # The exit speed is the target unless the length did not allow reaching it.
    if not close(p[6], ve_target, 1e-6):
        assert length < abs(v0 * v0 - ve_target * ve_target) / (2 * a) * (1 + 1e-6) + 1e-6
    assert distance_at(p, duration(p) + 1.0) == pytest.approx(length_of(p))
    # Speed stays within [0, max(v0, vp)].
    for k in range(11):
        v = speed_at(p, duration(p) * k / 10)
        assert -1e-6 <= v <= max(v0, vp) * (1 + 1e-9) + 1e-6


@SETTINGS
@given(lengths, st.floats(min_value=0.0, max_value=1e6), speeds, speeds, peaks, accels)
def test_longer_never_faster(length, extra, v0, ve, vp, a):
    short = duration(plan(length, v0, ve, vp, a))
    long_ = duration(plan(length + extra, v0, ve, vp, a))
    assert long_ >= short * (1 - 1e-9) - 1e-12


@SETTINGS
@given(lengths, speeds, speeds, peaks, st.floats(min_value=1.0, max_value=4.0), accels)
def test_higher_peak_never_slower(length, v0, ve, vp, k, a):
    slow = duration(plan(length, v0, ve, vp, a))
    fast = duration(plan(length, v0, ve, vp * k, a))
    assert fast <= slow * (1 + 1e-9) + 1e-12


# ---------------------------------------------------------------- executor basics

def ex_with(**kw) -> MotionExecutor:
    log = kw.pop("log", [])
    axes = kw.pop("axes", 4)
    cap = kw.pop("capacity", 420)
    mr = kw.pop("max_rate", 0.0)
    return MotionExecutor(axes=axes, capacity=cap, max_rate=mr, params=MotionParams(**kw),
                          log=log)


def test_single_line_timing_and_position():
    ex = ex_with(v=1000, a=20_000)
    ex.push((10_000, 5000, 0, 0), cont=False)
    assert ex.queue_len == 1 and ex.running
    assert ex.next_event_time() == pytest.approx(10.05)
    assert ex.position_at(5.025) == (5000, 2500, 0, 0)
    assert ex.advance(10.0) == 0 and ex.queue_len == 1
    assert ex.advance(10.05) == 1
    assert ex.position == (10_000, 5000, 0, 0) and not ex.running and ex.queue_len == 0
    assert ex.next_event_time() is None


def test_t_pause_between_lines_not_between_c():
    ex = ex_with(v=1000, a=20_000, pause=0.010)
    ex.push((1000, 0, 0, 0), cont=False)
    ex.push((1000, 0, 0, 0), cont=False)
    run_to_end(ex)
    a, b = ex.log
    assert b.t_start == pytest.approx(a.t_end + 0.010)
    ex = ex_with(v=1000, a=20_000, pause=0.010)
    ex.push((1000, 0, 0, 0))
    ex.push((1000, 0, 0, 0))
    run_to_end(ex)
    a, b = ex.log
    assert b.t_start == a.t_end and not a.rest and b.rest


def test_vk_vn_speed_metric():
    vn = ex_with(v=1000, a=1e9, vk=False)
    vn.push((3000, 4000, 0, 0), cont=False)
    vk = ex_with(v=1000, a=1e9, vk=True)
    vk.push((3000, 4000, 0, 0), cont=False)
    assert vn.next_event_time() == pytest.approx(4.0, rel=1e-4)
    assert vk.next_event_time() == pytest.approx(5.0, rel=1e-4)


def test_vl_caps_path_speed():
    ex = ex_with(v=5000, a=1e9, vl=(500.0, 10_000.0, 10_000.0, 10_000.0))
    ex.push((1000, 1000, 0, 0), cont=False)
    assert ex.next_event_time() == pytest.approx(2.0, rel=1e-4)


def test_short_vector_aims_at_b_long_at_v():
    # B below V: a short C vector never exceeds B, a long one reaches V.
    ex = ex_with(v=10_000, a=1e6, b=1000, short=512)
    for _ in range(3):
        ex.push((511, 0, 0, 0))
    run_to_end(ex)
    assert max(c.v_out for c in ex.log) <= 1000.0 + 1e-9
    assert ex.log[1].t_end - ex.log[1].t_start == pytest.approx(0.511)
    ex = ex_with(v=10_000, a=1e6, b=1000, short=512)
    for _ in range(3):
        ex.push((5000, 0, 0, 0))
    run_to_end(ex)
    mid = ex.log[1]
    assert mid.v_in == pytest.approx(1000.0) and mid.v_out == pytest.approx(1000.0)
    assert mid.t_end - mid.t_start < 5000 / 1000 / 2   # it went well above B in between


def test_c_followed_by_l_stops():
    ex = ex_with(v=1000, a=20_000, pause=0.005)
    ex.push((1000, 0, 0, 0))
    ex.push((1000, 0, 0, 0), cont=False)
    run_to_end(ex)
    assert ex.log[0].rest and ex.log[0].v_out == 0.0
    assert ex.starvations == 0


def test_zero_length_line_takes_no_time_then_pause():
    ex = ex_with(pause=0.002)
    ex.push((0, 0, 0, 0), cont=False)
    ex.push((100, 0, 0, 0), cont=False)
    run_to_end(ex)
    assert ex.log[0].t_end == 0.0 and ex.log[1].t_start == pytest.approx(0.002)


def test_three_axes():
    ex = ex_with(axes=3, capacity=128, vk=True)
    ex.push((300, 400, 0))
    ex.push((-300, -400, 0))
    run_to_end(ex)
    assert ex.position == (0, 0, 0)


def test_time_must_not_go_back():
    ex = ex_with()
    ex.advance(1.0)
    with pytest.raises(ValueError):
        ex.advance(0.5)


# ---------------------------------------------------------------- junctions and starvation

def test_successor_in_time_joins():
    ex = ex_with(v=1000, a=20_000, b=800)
    ex.push((1000, 0, 0, 0))
    ex.advance(0.5)              # well before the stop ramp of the first vector
    ex.push((1000, 0, 0, 0))
    run_to_end(ex)
    first = ex.log[0]
    assert not first.rest and first.v_out == pytest.approx(800.0)
    assert ex.starvations == 0


def test_late_successor_starves():
    ex = ex_with(v=1000, a=20_000, b=800, pause=0.005)
    ex.push((1000, 0, 0, 0))
    # The stop ramp from 1000 to 0 takes 0.05 s and must start at 1.0 (end 1.05).
    ex.advance(1.02)
    assert ex.queue_len == 1
    ex.push((1000, 0, 0, 0))
    run_to_end(ex)
    first, second = ex.log
    assert first.rest and first.t_end == pytest.approx(1.05)
    assert second.t_start == pytest.approx(1.055) and second.starved
    assert ex.starvations == 1


def test_queue_capacity_counts_running_vector():
    ex = ex_with(capacity=3)
    for _ in range(3):
        ex.push((1000, 0, 0, 0))
    ex.advance(0.1)
    assert ex.queue_len == ex.capacity == 3 and ex.running


# ---------------------------------------------------------------- HALT, G, D, K, R

def test_halt_brakes_on_a_ramp_and_resume_finishes():
    ex = ex_with(v=1000, a=20_000)
    ex.push((10_000, 1000, 0, 0), cont=False)
    t_stop = ex.halt(5.0)
    assert t_stop == pytest.approx(5.05)
    assert ex.braking and ex.running
    ex.advance(t_stop)
    assert ex.interrupted and not ex.running and ex.queue_len == 1
    # Distance at 5.0 s is 4975; 25 more while braking.
    assert ex.position == (5000, 500, 0, 0)
    assert ex.speed_at(6.0) == 0.0 and ex.next_event_time() is None
    assert ex.resume(7.0)
    run_to_end(ex)
    assert ex.position == (10_000, 1000, 0, 0)
    assert ex.log[-1].t_start == pytest.approx(7.0)


def test_halt_ramp_runs_into_queued_c_vectors():
    # 200 x 100 pulses at V10000 A10: 1 s ramp up (5000 pulses), cruise, ramp down.
    ex = ex_with(v=10_000, a=10_000, b=10_000, short=1)
    for _ in range(200):
        ex.push((100, 0, 0, 0))
    ex.advance(1.45)                     # at full speed, 9500 pulses done
    assert ex.completed == 95
    t_stop = ex.halt(1.45)               # the ramp needs 5000 pulses: 50 more vectors
    assert t_stop == pytest.approx(2.45)
    ex.advance(t_stop)
    assert ex.completed == 145 and ex.queue_len == 55
    assert ex.position == (14_500, 0, 0, 0)
    ex.resume(3.0)
    run_to_end(ex)
    assert ex.position == (20_000, 0, 0, 0) and ex.completed == 200


def test_halt_when_idle_and_double_halt():
    ex = ex_with()
    assert ex.halt(1.0) == 1.0 and ex.interrupted
    assert ex.halt(2.0) == 2.0
    assert ex.resume(3.0) and not ex.interrupted
    assert not ex.resume(3.0)


def test_resume_during_ramp_waits_for_the_stop():
    ex = ex_with(v=1000, a=20_000)
    ex.push((10_000, 0, 0, 0), cont=False)
    t_stop = ex.halt(2.0)
    assert ex.resume(2.01)
    run_to_end(ex)
    assert ex.position[0] == 10_000 and ex.log[-1].t_start == pytest.approx(t_stop)


def test_halt_in_the_t_pause_stops_nothing_and_g_restarts():
    ex = ex_with(v=1000, a=20_000, pause=0.010)
    ex.push((1000, 0, 0, 0), cont=False)
    ex.push((1000, 0, 0, 0), cont=False)
    t1 = ex.next_event_time()
    ex.advance(t1)
    assert ex.halt(t1 + 0.005) == t1 + 0.005
    assert ex.position == (1000, 0, 0, 0) and ex.queue_len == 1 and not ex.running
    assert ex.next_event_time() is None
    ex.resume(t1 + 1.0)
    run_to_end(ex)
    assert ex.position == (2000, 0, 0, 0) and ex.log[-1].t_start == pytest.approx(t1 + 1.0)


def test_speed_change_before_the_vector_starts():
    ex = ex_with(v=1000, a=1e9, pause=0.010)
    ex.push((1000, 0, 0, 0), cont=False)
    ex.push((1000, 0, 0, 0), cont=False)
    t1 = ex.next_event_time()
    ex.advance(t1)
    ex.apply_speed(t1, speed_xm(1000, 200))
    assert ex.next_event_time() == pytest.approx(t1 + 0.010 + 0.5, abs=1e-5)


def test_push_checks_the_axis_count():
    with pytest.raises(ValueError):
        ex_with(axes=3).push((1, 2, 3, 4))


def test_delete_keeps_position():
    ex = ex_with(v=1000, a=20_000)
    ex.push((10_000, 0, 0, 0))
    ex.push((10_000, 0, 0, 0))
    with pytest.raises(MotionStateError):
        ex.clear()
    t = ex.halt(3.0)
    ex.advance(t)
    pos = ex.position
    ex.clear()
    assert ex.queue_len == 0 and ex.position == pos and not ex.interrupted


def test_keep_restore_like_the_manual_example():
    # §13.5.9: H, K, L0,0,-1000, L0,0,1000, R, V500, XA, G.
    ex = ex_with(v=1000, a=20_000)
    for _ in range(5):
        ex.push((1000, 200, 0, 0))
    t = ex.halt(2.3)
    ex.advance(t)
    held = ex.queue_len
    ex.park()
    assert ex.parked and ex.queue_len == 0 and not ex.interrupted
    with pytest.raises(MotionStateError):
        ex.park()
    ex.push((0, 0, -1000, 0), cont=False)
    ex.advance(run_to_end(ex))
    assert ex.position[2] == -1000
    ex.push((0, 0, 1000, 0), cont=False)
    run_to_end(ex)
    ex.restore()
    assert ex.queue_len == held and ex.interrupted
    ex.params = ex.params.replace(v=500)
    ex.apply_speed(ex.now, lambda _v: 500.0)
    assert ex.resume(ex.now)
    run_to_end(ex)
    assert ex.position == (5000, 1000, 0, 0)


def test_state_errors():
    ex = ex_with()
    with pytest.raises(MotionStateError):
        ex.restore()
    ex.push((1000, 0, 0, 0))
    for op in (ex.park, ex.zero, lambda: ex.set_position(0, 5)):
        with pytest.raises(MotionStateError):
            op()
    run_to_end(ex)
    ex.set_position(1, 77)
    assert ex.position == (1000, 77, 0, 0)
    ex.zero()
    assert ex.position == (0, 0, 0, 0)


# ---------------------------------------------------------------- XA / XU / XD / XM

def test_xu_xd_change_the_running_vector():
    base = ex_with(v=1000, a=20_000)
    base.push((10_000, 0, 0, 0), cont=False)
    t_base = base.next_event_time()
    up = ex_with(v=1000, a=20_000)
    up.push((10_000, 0, 0, 0), cont=False)
    up.apply_speed(2.0, speed_xu)
    assert up.next_event_time() < t_base
    down = ex_with(v=1000, a=20_000)
    down.push((10_000, 0, 0, 0), cont=False)
    down.apply_speed(2.0, speed_xd)
    assert down.next_event_time() > t_base
    run_to_end(up)
    assert up.position == (10_000, 0, 0, 0)


def test_xm_is_capped_by_vl():
    ex = ex_with(v=1000, a=1e9, vl=(1500.0, 1500.0, 1500.0, 1500.0))
    ex.push((3000, 0, 0, 0), cont=False)
    ex.apply_speed(0.0, speed_xm(1000, 200))
    assert ex.next_event_time() == pytest.approx(2.0, rel=1e-4)


# ---------------------------------------------------------------- properties of jobs

vec = st.tuples(st.integers(-3000, 3000), st.integers(-3000, 3000),
                st.integers(-300, 300), st.integers(-100, 100))
params_st = st.builds(
    MotionParams,
    v=st.integers(10, 125_000).map(float),
    a=st.integers(1, 500).map(lambda x: x * 1000.0),
    b=st.integers(10, 125_000).map(float),
    short=st.integers(1, 2000),
    pause=st.integers(1, 24).map(lambda x: x / 1000.0),
    vk=st.booleans(),
)
jobs = st.lists(st.tuples(vec, st.booleans()), min_size=1, max_size=25)


def reference_drain_time(job, p: MotionParams, max_rate: float = 0.0) -> float:
    """Eager, straightforward timing of a job queued all at once at t = 0."""
    t = 0.0
    v_in = 0.0
    for i, (d, cont) in enumerate(job):
        length, dom = path_length(d, p.vk)
        cap = speed_cap(d, length, dom, p.v, p.vl, max_rate)
        vj = min(p.b, cap)
        vpeak = vj if dom < p.short else cap
        join = cont and i + 1 < len(job) and job[i + 1][1]
        prof = plan(length, v_in, vj if join else 0.0, vpeak, p.a)
        t += duration(prof)
        if join:
            v_in = prof[6]
        else:
            v_in = 0.0
            if i + 1 < len(job):
                t += p.pause
    return t


def run_job(job, p: MotionParams) -> MotionExecutor:
    ex = MotionExecutor(params=p, log=[])
    for d, cont in job:
        ex.push(d, cont)
    run_to_end(ex)
    return ex


@SETTINGS
@given(jobs, params_st)
def test_job_final_position_and_drain_time(job, p):
    ex = run_job(job, p)
    assert ex.position == tuple(sum(d[i] for d, _ in job) for i in range(4))
    assert ex.completed == len(job) and ex.queue_len == 0
    assert close(ex.log[-1].t_end, reference_drain_time(job, p), 1e-9)
    ends = [c.t_end for c in ex.log]
    assert ends == sorted(ends)
    assert ex.starvations == 0


@SETTINGS
@given(jobs, params_st, st.floats(min_value=1.0, max_value=3.0))
def test_higher_v_never_slower_when_queued_up_front(job, p, k):
    slow = run_job(job, p).log[-1].t_end
    fast = run_job(job, p.replace(v=p.v * k)).log[-1].t_end
    assert fast <= slow * (1 + 1e-9) + 1e-12


@SETTINGS
@given(vec, params_st, st.floats(min_value=0.0, max_value=1.0))
def test_braking_stops_between_start_and_end(d, p, frac):
    assume(any(d))
    ex = MotionExecutor(params=p)
    ex.push(d, cont=False)
    t_end = ex.next_event_time()
    t = t_end * frac
    t_stop = ex.halt(t)
    assert t_stop >= t
    ex.advance(t_stop)
    assert ex.speed_at(t_stop) == 0.0 and not ex.running
    pos = ex.position
    for x, dx in zip(pos, d, strict=True):
        assert min(0, dx) <= x <= max(0, dx)


@SETTINGS
@given(jobs, params_st, st.floats(min_value=0.0, max_value=1.0),
       st.floats(min_value=0.0, max_value=0.5))
def test_halt_then_resume_reaches_the_same_place(job, p, frac, wait):
    reference = run_job(job, p)
    ex = MotionExecutor(params=p, log=[])
    for d, cont in job:
        ex.push(d, cont)
    t = reference.log[-1].t_end * frac
    t_stop = ex.halt(t)
    ex.advance(t_stop)
    ex.resume(t_stop + wait)
    run_to_end(ex)
    assert ex.position == reference.position and ex.queue_len == 0
    # A halt can only delay the job (up to sqrt(eps)-level rounding of the ramp's end).
    assert ex.log[-1].t_end >= reference.log[-1].t_end * (1 - 1e-6) - 1e-9


@SETTINGS
@given(jobs, params_st, st.lists(st.floats(min_value=0.0, max_value=0.05), min_size=25,
                                 max_size=25))
def test_trickle_feed_time_is_monotone(job, p, gaps):
    """Pushing at arbitrary later times: positions move, time and completions stay ordered."""
    ex = MotionExecutor(params=p, log=[])
    t = 0.0
    for (d, cont), gap in zip(job, gaps, strict=False):
        t += gap
        ex.advance(t)
        nxt = ex.next_event_time()
        assert nxt is None or nxt >= ex.now
        ex.push(d, cont)
    run_to_end(ex)
    assert ex.position == tuple(sum(d[i] for d, _ in job) for i in range(4))
    assert ex.starvations == sum(c.starved for c in ex.log)
    ends = [c.t_end for c in ex.log]
    starts = [c.t_start for c in ex.log]
    assert ends == sorted(ends) and all(s <= e for s, e in zip(starts, ends, strict=True))
