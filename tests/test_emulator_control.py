"""The control requests every family's emulator shares (conform.emulator.control.FaultControl)
and what grbl and Marlin add, called as the emulator's loop calls them (no socket)."""

from __future__ import annotations

import json

import pytest

from conform.families import family
from conform.families.grbl.unit.control import GrblControl
from conform.families.grbl.unit.faults import GrblFaults
from conform.families.marlin.unit.control import MarlinControl
from conform.families.marlin.unit.faults import MarlinFaults


def both():
    yield GrblControl(GrblFaults()), family("grbl").make_unit("grbl-1.1f")
    yield MarlinControl(MarlinFaults()), family("marlin").make_unit("marlin-2.1")


@pytest.mark.parametrize(("control", "unit"), list(both()), ids=["grbl", "marlin"])
def test_the_shared_requests(control, unit) -> None:
    assert control(unit, "help", 0.0).startswith("ok commands:")
    state = json.loads(control(unit, "state", 0.0)[3:])
    assert state["variant"] == unit.v.id
    assert control(unit, "fault lose 2", 0.0).startswith("ok")
    assert control.faults.lose_next == 2
    assert control(unit, "fault line corrupt=1e-3", 0.0) == "ok line faults: corrupt=1e-3"
    assert control.faults.config.active
    assert control(unit, "fault line", 0.0) == "ok line faults: none"
    for bad, says in (("", "error: empty command"),
                      ("fault lose 2.5", "expected a count"),
                      ("fault lose x", "'x' is not a number"),
                      ("fault lose 1 2", "takes one number"),
                      ("fault unplug 0", "expected 0..3600 seconds"),
                      ("fault melt 1", "unknown fault 'melt'"),
                      ("dance", "cannot parse 'dance'")):
        reply = control(unit, bad, 0.0)
        assert reply.startswith("error:") and says in reply, (bad, reply)


def test_what_only_grbl_has() -> None:
    control, unit = next(both())
    assert control(unit, "fault garble 3", 0.0).startswith("ok") and control.faults.garble_next == 3
    unit.poll(1.0)
    assert control(unit, "press door", 1.0).startswith("ok Door")
    assert control(unit, "press nose", 1.0).startswith("error:")


def test_what_only_marlin_has() -> None:
    control, unit = list(both())[1]
    assert "unknown fault 'garble'" in control(unit, "fault garble 1", 0.0)
    assert control(unit, "fault busy 2", 0.0) == "ok busy for 2 s"
    assert json.loads(control(unit, "truth", 0.0)[3:]) is not None
    assert control(unit, "reset", 0.0).startswith("ok reset")
    assert control(unit, "fault unplug 1", 0.5) == "ok cable pulled for 1 s"
    assert unit.halted                       # powered through the cable
