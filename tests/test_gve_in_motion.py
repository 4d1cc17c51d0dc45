"""The read-backs added from the mutation triage (conform/families/gve/conformance/in_motion.py):
where they run, and a unit with the bug each is meant for FAILs it in-process while the checks
that read at rest pass it."""

from __future__ import annotations

from conform.conformance.results import Grade
from conform.conformance.runner import RunOptions
from conform.families.gve.conformance.checks import generate
from conform.families.gve.conformance.runner import Runner
from conform.families.gve.conformance.suite import suite
from conform.families.gve.conformance.target import GveEmuTarget
from conform.families.gve.unit import Unit


class _Intcom(Unit):
    """SW6 sets INTCOM whenever it writes INTA."""

    def _write_st6(self, value: int, t: float) -> None:
        super()._write_st6(value | (self._bit_intcom if value & self._bit_inta else 0), t)


class _Ramp(Unit):
    """A's value taken one step too high: every ramp is steeper, every end point the same."""

    def _cmd_A(self, args: tuple, t: float) -> object:
        return self._set_modal("_A", args[0] + 1)


class _Port2Polarity(Unit):
    """Port 2's inputs read as active low whatever ST3 says."""

    def _polarity_bit(self, port: int, bit: int) -> bool:
        return False if port == 2 else super()._polarity_bit(port, bit)


def _run(spec, cls, patterns):
    variant = spec.variant("gve64-v19")
    dialect = spec.dialect()
    target = GveEmuTarget(lambda: cls(variant, dialect), "emu")
    checks = suite(spec, "gve64-v19", patterns=patterns, profile="full", machine=False)
    return {c.key: c for c in Runner(spec, target, "gve64-v19", options=RunOptions()).run(checks).checks}


def _keys(checks):
    return {c.key for c in checks}


def test_st6_bits_runs_everywhere_the_in_motion_reads_only_in_full_with_motion(spec):
    quick = _keys(generate(spec, "gve64-v19"))
    still = _keys(generate(spec, "gve64-v19", deep=True, motion=False))
    full = _keys(generate(spec, "gve64-v19", deep=True, motion=True))
    assert {"SW/st6-bits", "I1/inputs-polarity"} <= quick & still
    moving = {k for k in full if "/in-motion" in k}
    assert {"L/in-motion/profile", "H/in-motion/brake-spill", "C/in-motion/chain"} <= moving
    assert not {k for k in quick | still if "/in-motion" in k}


def test_intcom_set_with_inta_fails_st6_bits(spec):
    got = _run(spec, _Intcom, ["*/SW/st6-bits", "*/G/nothing-left"])
    assert got["SW/st6-bits"].grade is Grade.FAIL, got["SW/st6-bits"].detail
    assert got["G/nothing-left"].grade is Grade.PASS  # SW6,80 alone: its answer shows nothing


def test_a_steeper_ramp_fails_the_reads_under_way_not_those_at_rest(spec):
    got = _run(spec, _Ramp, ["*/L/in-motion/profile", "*/L/position-1", "*/L/position-2"])
    assert got["L/in-motion/profile"].grade is Grade.FAIL, got["L/in-motion/profile"].detail
    assert got["L/position-1"].grade is Grade.PASS
    assert got["L/position-2"].grade is Grade.PASS


def test_port_2_polarity_ignored_fails_inputs_polarity(spec):
    got = _run(spec, _Port2Polarity, ["*/I1/inputs-polarity", "*/I1/inputs", "*/SR/interrupt"])
    assert got["I1/inputs-polarity"].grade is Grade.FAIL, got["I1/inputs-polarity"].detail
    assert got["I1/inputs"].grade is Grade.PASS  # port 1 at its reset polarity shows nothing
    assert got["SR/interrupt"].grade is Grade.PASS
