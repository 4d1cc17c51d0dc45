"""The corner-state checks (conform/families/gve/conformance/corner_states.py): where they run,
that the reference passes them, and that a unit with the bug each is meant for FAILs it."""

from __future__ import annotations

from test_gve_in_motion import _keys, _run  # the in-process run of chosen checks

from conform.conformance.results import Grade
from conform.families.gve.conformance.checks import generate
from conform.families.gve.protocol.commands import Rejection
from conform.families.gve.unit import Unit
from conform.families.gve.unit.replies import OK
from conform.families.gve.unit.vectors import MIN_SPEED

MOTION_FREE = {"%/inta-answers", "L/checksum-below", "C/checksum-below", "*E/count-below",
               "*E/refused-inside", "N<axis>/counter-top", "SW/inta-twice",
               "framing/split-line", "framing/bare-address"}


class _OneCache(Unit):
    """Keeps one encoded plain answer per code and INTA, whatever the checksum state."""

    def encode(self, code, fields=()):
        if fields:
            return super().encode(code, fields)
        key = (code, self._inta)
        cache = self.__dict__.setdefault("_one", {})
        if key not in cache:
            cache[key] = super().encode(code, fields)
        return cache[key]


class _SumOneWay(Unit):
    """Takes a vector line whose checksum is below its sum (tests the sum one way)."""

    def _parse(self, line):
        if self._checksum_on and line[2:3] in (b"L", b"C") and line[-3:-2] == b",":
            try:
                tail = int(line[-2:], 16)
            except ValueError:
                tail = None
            right = sum(line[:-2]) & 0xFF
            if tail is not None and tail < right:
                line = line[:-2] + b"%02X" % right
        return super()._parse(line)


class _CountAtMost(Unit):
    """*E<n> accepted whenever n is at most the lines counted."""

    def _packet_line(self, line, t):
        pk = self._packet
        r = self._parse(line)
        if (r.name == "*E" and r.__class__ is not Rejection and pk.error is None
                and r.args[0] < pk.count):
            self._packet = None
            self._answer(line, (OK, (pk.count,)), t, "*E", None)
            return
        super()._packet_line(line, t)


class _RefusedCounts(Unit):
    """A vector refused inside a packet is counted as executed."""

    def _execute(self, cmd, t):
        reply = super()._execute(cmd, t)
        if self._packet is not None and cmd.name == "C" and reply.__class__ is int:
            return OK
        return reply


class _Wrap(Unit):
    """Position counters wrap at 2**32 - 1 instead of 2**32."""

    @property
    def position(self):
        pos = zip(self._exec.position, self._offsets, strict=True)
        return tuple(((p + o + 0x80000000) % 0xFFFFFFFF) - 0x80000000 for p, o in pos)


class _IntaToggles(Unit):
    """SW6 with INTA while INTA is set clears it and resumes."""

    def _write_st6(self, value, t):
        if value & self._bit_inta and self._inta:
            value &= ~self._bit_inta
        super()._write_st6(value, t)


class _WatchdogAtOnce(Unit):
    """The watchdog starts in the past: a line cut anywhere is answered 2 at once."""

    def _start_watchdog(self, t):
        super()._start_watchdog(t)
        if self._wd != float("inf") and self._watchdog_s is not None:
            self._wd = t % self._watchdog_s
            self._update_timers()


class _BareSilent(Unit):
    """A begun line of just '!' and its address is dropped silently by the watchdog."""

    def _watchdog(self, t):
        pending = self._splitter.unfinished
        if len(pending) - pending.rfind(b"!") <= 2:
            self._splitter.clear()
            self._partial = False
            self._wd = float("inf")
            return
        super()._watchdog(t)


class _BackOffOne(Unit):
    """W backs off one pulse whatever from_switch says."""

    def _cmd_W(self, args, t):
        axis, to_switch, speed_to, from_switch, speed_from = args
        return super()._cmd_W((axis, to_switch, speed_to, min(from_switch, 1),
                               max(speed_from, MIN_SPEED)), t)


def test_motion_free_ones_run_everywhere_back_off_only_with_motion(spec):
    for vid, v in spec.variants.items():
        quick = _keys(generate(spec, vid))
        still = _keys(generate(spec, vid, deep=True, motion=False))
        full = _keys(generate(spec, vid, deep=True, motion=True))
        want = {k for k in MOTION_FREE if k != "N<axis>/counter-top" or "N<axis>" in v.commands}
        assert want <= quick and want <= still, vid
        assert "W/back-off" in full and "W/back-off" not in quick | still, vid


def test_the_reference_passes_them(spec):
    got = _run(spec, Unit, ["*/" + k for k in (*MOTION_FREE, "W/back-off")])
    assert len(got) == len(MOTION_FREE) + 1
    assert all(c.grade is Grade.PASS for c in got.values()), {
        k: c.detail for k, c in got.items() if c.grade is not Grade.PASS}


def _fails(spec, cls, key, *passing):
    got = _run(spec, cls, ["*/" + key, *("*/" + k for k in passing)])
    assert got[key].grade is Grade.FAIL, (key, got[key].grade, got[key].detail)
    for k in passing:
        assert got[k].grade is Grade.PASS, (k, got[k].detail)


def test_one_answer_cache_for_both_checksum_states_fails_inta_answers(spec):
    _fails(spec, _OneCache, "%/inta-answers", "%/valid")


def test_a_checksum_tested_one_way_fails_checksum_below(spec):
    _fails(spec, _SumOneWay, "L/checksum-below", "L/bad-checksum")
    _fails(spec, _SumOneWay, "C/checksum-below", "C/bad-checksum")


def test_a_count_taken_as_at_most_fails_count_below(spec):
    _fails(spec, _CountAtMost, "*E/count-below", "*E/valid")


def test_a_refused_vector_counted_fails_refused_inside(spec):
    _fails(spec, _RefusedCounts, "*E/refused-inside", "*E/valid")


def test_a_counter_wrapping_early_fails_counter_top(spec):
    _fails(spec, _Wrap, "N<axis>/counter-top", "N<axis>/read-back")


def test_inta_written_twice_clearing_it_fails_inta_twice(spec):
    _fails(spec, _IntaToggles, "SW/inta-twice", "SW/st6-bits")


def test_a_watchdog_firing_at_once_fails_split_line(spec):
    _fails(spec, _WatchdogAtOnce, "framing/split-line")


def test_a_bare_begun_line_dropped_fails_watchdog_bare(spec):
    _fails(spec, _BareSilent, "framing/bare-address", "timing/watchdog")


def test_a_short_back_off_fails_w_back_off(spec):
    _fails(spec, _BackOffOne, "W/back-off", "W/valid")
