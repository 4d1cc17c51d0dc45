"""M0/M1 on the reference unit: compiled only with HAS_RESUME_CONTINUE (Conditionals_adv.h;
with no display that is EMERGENCY_PARSER), a wait of P ms or S s after the planner empties,
``echo:busy: paused for user`` while it lasts (gcode.cpp host_keepalive, PAUSED_FOR_USER), and
ended at once by M108 through the emergency parser (M0_M1.cpp, MarlinCore.cpp
wait_for_user_response)."""

from __future__ import annotations

from conform.families import family
from conform.families.marlin.protocol.codec import frame


def run(variant: str, script: list[tuple[float, bytes]], until: float) -> list[tuple[float, str]]:
    u = family("marlin").make_unit(variant)
    u.poll(0.5)
    out = []
    for t, data in script:
        out += u.poll(t)
        u.receive(data, t)
    out += u.poll(until)
    return [(round(t, 2), d.decode().strip()) for t, d in out if t >= 1.0]


def test_without_the_emergency_parser_m0_is_unknown() -> None:
    assert run("marlin-2.1", [(1.0, frame(1, "M0 S3"))], 5.0) == [
        (1.0, 'echo:Unknown command: "M0 S3"'), (1.0, "ok")]


def test_m0_waits_its_time_saying_it_is_paused_for_the_user() -> None:
    got = run("marlin-2.1-adv", [(1.0, frame(1, "M0 S3"))], 6.0)
    assert [d for _, d in got] == ["echo:busy: paused for user", "ok N1 P15 B3"]
    assert got[0][0] == 3.0 and 4.0 <= got[1][0] < 4.01        # keepalive 2 s; S3 from 1 s


def test_m108_ends_the_wait_as_its_bytes_arrive() -> None:
    got = run("marlin-2.1-adv", [(1.0, frame(1, "M0 S30")), (1.5, b"M108\n")], 3.0)
    # M108 is read during the wait and queued behind M0: B2 in M0's ok (queue.cpp ok_to_send)
    assert got == [(1.5, "ok N1 P15 B2"), (1.5, "ok P15 B3")]


def test_m0_without_a_time_waits_for_m108() -> None:
    got = run("marlin-2.1-adv", [(1.0, frame(1, "M0")), (9.0, b"M108\n")], 10.0)
    assert [d for _, d in got] == ["echo:busy: paused for user"] * 4 + ["ok N1 P15 B2",
                                                                        "ok P15 B3"]
