"""The speed-planning read-backs (conform/families/gve/conformance/planning.py): where they run,
the reference passes them, and a unit with the planning bug each is meant for FAILs it
in-process while the checks that read at rest pass it."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from test_gve_in_motion import _run  # the checks of `patterns` against a unit of class `cls`

from conform.conformance.results import Grade
from conform.families.gve.conformance.checks import generate
from conform.families.gve.unit import Unit, kinematics, motion
from tests import emulated


class _NoMaxRate(Unit):
    """The max rate caps nothing: XM above 100 % drives an axis past it."""

    def _power_up(self, t: float) -> None:
        super()._power_up(t)
        self._exec.max_rate = 0.0


class _NoPause(Unit):
    """T is answered and kept, but the vectors never pause after a stop."""

    def _rebuild_params(self) -> None:
        super()._rebuild_params()
        self._exec.params = self._exec.params.replace(pause=0.0)


class _EuclidSpillExecutor(motion.MotionExecutor):
    __slots__ = ()

    def halt(self, t: float) -> float:
        # the vectors a brake runs on into measured along X, Y, Z even under VN
        kept = motion.path_length
        motion.path_length = lambda d, _vk: kinematics.path_length(d, True)
        try:
            return super().halt(t)
        finally:
            motion.path_length = kept


class _EuclidSpill(Unit):
    """HALT's brake runs on into the queued C vectors along their Euclidean length under VN."""

    def _power_up(self, t: float) -> None:
        super()._power_up(t)
        ex = self._exec
        self._exec = _EuclidSpillExecutor(axes=ex.axes, capacity=ex.capacity,
                                          max_rate=ex.max_rate, params=ex.params)
        self._exec.advance(t)


def test_planning_checks_only_in_full_with_motion(spec):
    quick = {c.key for c in generate(spec, "gve64-v19")}
    still = {c.key for c in generate(spec, "gve64-v19", deep=True, motion=False)}
    full = {c.key for c in generate(spec, "gve64-v19", deep=True, motion=True)}
    planning = {k for k in full if "/planning/" in k}
    assert {"C/planning/short-from-rest", "T/planning/pause", "H/planning/spill-diagonal",
            "XM/planning/max-rate", "H/planning/while-braking"} <= planning
    assert not {k for k in quick | still if "/planning/" in k}


def test_the_reference_passes_every_planning_check(spec):
    got = _run(spec, Unit, ["*/planning/*"])
    assert len(got) >= 7
    assert all(c.grade is Grade.PASS for c in got.values()), {k: c.detail for k, c in got.items()}


def test_no_max_rate_fails_the_max_rate_check(spec):
    got = _run(spec, _NoMaxRate, ["*/XM/planning/max-rate", "*/L/position-1"])
    assert got["XM/planning/max-rate"].grade is Grade.FAIL, got["XM/planning/max-rate"].detail
    assert got["L/position-1"].grade is Grade.PASS


def test_no_pause_after_a_stop_fails_the_pause_check(spec):
    got = _run(spec, _NoPause, ["*/T/planning/pause"])
    assert got["T/planning/pause"].grade is Grade.FAIL, got["T/planning/pause"].detail


def test_a_brake_measuring_vn_vectors_euclidean_fails_spill_diagonal(spec):
    got = _run(spec, _EuclidSpill, ["*/H/planning/spill-diagonal", "*/H/in-motion/brake-spill"])
    assert got["H/planning/spill-diagonal"].grade is Grade.FAIL, got["H/planning/spill-diagonal"].detail
    assert got["H/in-motion/brake-spill"].grade is Grade.PASS  # along X only: both lengths agree


@pytest.mark.slow
@pytest.mark.long(71)
def test_the_motion_checks_pass_over_a_pty(tmp_path):
    """`conform run` of every in-motion and planning check (full profile, --allow-motion)
    against `conform emulate serve` on a pty: none FAILs on a correct unit, though where a
    brake ends follows when H arrived, which a link does not fix to the pulse (brake-spill
    and while-braking read that only under way, or where it does not depend on it)."""
    proc, path, _ = emulated.serve("serve", "gve64-v19", "--baud", "115200")
    try:
        p = subprocess.run([sys.executable, "-m", "conform", "run", "--target", path, "--variant",
                            "gve64-v19", "--baud", "115200", "--report", str(tmp_path), "-q",
                            "--profile", "full", "--allow-motion", "--max-steps", "250000",
                            "--check", "*/in-motion*", "--check", "*/planning/*"],
                           capture_output=True, text=True, timeout=600)
    finally:
        emulated.stop(proc)
    assert p.returncode == 0, p.stdout + p.stderr
    checks = json.loads((tmp_path / "results.json").read_text())["checks"]
    assert len(checks) >= 14
    assert [(c["id"], c["grade"]) for c in checks if c["grade"] != "PASS"] == []
