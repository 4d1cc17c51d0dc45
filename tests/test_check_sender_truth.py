"""The emulator's ground truth: what the unit accepted and executed, as facts."""

from __future__ import annotations

import json

from conform.families.gve.unit.model import Unit, run_until_idle
from conform.families.gve.unit.truth import GroundTruth, dumps


def _unit(spec, variant="gve64-v19"):
    u = Unit(spec.variant(variant), spec.dialect())
    return u, GroundTruth(u)


def test_vectors_packets_and_queue_full(spec):
    u, g = _unit(spec, "gve124")
    t = 0.0
    for line in (b"!0V20000\r", b"!0C100,0,0\r", b"!0L0,50,0\r",  # L refused: queue not empty
                 b"!0*S\r!0C1,2,3\r!0C4,5,6\r!0*E2\r"):
        u.receive(line, t)
        t += 0.001
    run_until_idle(u, t)
    d = g.to_dict()
    assert [a["vector"] for a in d["accepted"]] == [[100, 0, 0], [1, 2, 3], [4, 5, 6]]
    assert all(a["executed"] is not None and not a["deleted"] for a in d["accepted"])
    assert d["final"]["position"] == [105, 7, 9] and d["final"]["executed"] == 3


def test_delete_and_reset_mark_the_queue_deleted(spec):
    u, g = _unit(spec)
    u.receive(b"!0V100\r", 0.0)
    u.receive(b"!0C10000,0,0,0\r", 0.001)
    u.receive(b"!0C10000,0,0,0\r", 0.002)
    u.receive(b"!0H\r", 0.01)
    t = run_until_idle(u, 0.01)
    u.poll(t + 1.0)
    u.receive(b"!0D\r", t + 1.0)
    u.poll(t + 1.1)
    d = g.to_dict()
    assert [a["deleted"] for a in d["accepted"]] == [True, True]
    assert [e["command"] for e in d["events"]] == ["H", "D"]
    assert d["final"]["queue"] == 0 and not d["final"]["inta"]
    json.loads(dumps(d))  # the file format is JSON


def test_refused_vectors_are_not_accepted(spec):
    u, g = _unit(spec)
    for k in range(spec.variant("gve64-v19").queue + 5):
        u.receive(b"!0C1000,0,0,0\r", k * 1e-6)
    assert len(g.accepted) == spec.variant("gve64-v19").queue  # the rest answered 1


def test_unit_answers_5_to_numbers_of_thousands_of_digits(spec):
    """A sender's garbage never kills the emulator (Python refuses int() of 4300+ digits)."""
    u, g = _unit(spec)
    for line in (b"!0C" + b"1" * 1000 + b",0,0\r", b"!0V" + b"9" * 1000 + b"\r"):
        assert u.exchange(line, 0.0)[1] == b"5\r"
    # past the unit's 4 096-byte line the rest is dropped: what is left is answered, never run
    assert u.exchange(b"!0C" + b"1" * 5000 + b",0,0\r", 0.0)[1] in (b"4\r", b"5\r")
    assert g.accepted == []
