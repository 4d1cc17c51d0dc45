"""grbl conformance checks, generated from specs/grbl and graded per clause.

The checks produce the engine's own result objects (:class:`CheckResult` in a
:class:`TargetRun`), so ``conform run`` writes the same reports (results.json, index.html,
summary.md, junit.xml) for grbl as for GVE. A check id reads
``<variant>/<source>/<group>/<name>``, e.g. ``grbl-1.1f/error_codes/error/22``.

Groups: ``example`` (the documented exchanges, specs/grbl/examples.toml), ``error`` (every
code with a provoking line in codes.toml), ``alarm``, ``setting`` (every $x at each
documented edge: lo, lo-1, hi, hi+1, a fraction, a stray letter, no number;
:func:`setting_edges`), ``realtime`` (status, hold/resume, reset, overrides, jog cancel),
``buffer`` (the line limit and the receive ring), ``state`` (check mode, unlock, sleep).

A real unit is driven only as far as it is allowed: checks that move the machine need
``allow_motion``, checks that write settings (EEPROM) need ``allow_eeprom``; otherwise they are
SKIPPED. The checks run in the engine's runner (:class:`GrblRunner`), like every family's:
the estimate and ETA on a link, the abort after consecutive link failures, and the halt on
Ctrl-C — here feed hold then a soft reset, retried until the banner acknowledges it.
"""

from __future__ import annotations

import fnmatch
import time
from collections.abc import Callable, Sequence
from typing import Any

from conform.conformance.results import INFO, CheckResult, Grade, TargetRun
from conform.conformance.runner import Estimate, Runner, RunOptions
from conform.conformance.target import HarnessError
from conform.families.grbl.conformance.session import (  # noqa: F401 - re-exported
    _NUM,
    _SETTING,
    _WRITE,
    ALARM_DELAY,
    REALTIME_GAP,
    SEQUENCES,
    STOP,
    GrblCheck,
    Outcome,
    Session,
    Talk,
    _count,
)
from conform.families.grbl.spec.load import GrblSpec, Setting, load_grbl


def _setup(s: Session, setup: Sequence[bytes]) -> None:
    for item in setup:
        s.talk(item, timeout=1.0)


def _example(ex: Any) -> Callable[[Session], Outcome]:
    def run(s: Session) -> Outcome:
        _setup(s, ex.setup)
        got = s.talk(ex.send)
        want = list(ex.expect)
        passed: bool | None = got.lines == want
        if not passed and ex.power_up and not s.target.emulated and (
                [_NUM.sub("#", x) for x in got.lines] == [_NUM.sub("#", x) for x in want]):
            passed = None   # only positions/offsets differ: the unit is not at power-up state
        return passed, " | ".join(want), " | ".join(got.lines) or "(silence)"
    return run


def _error(code: int, send: bytes, setup: Sequence[bytes]) -> Callable[[Session], Outcome]:
    def run(s: Session) -> Outcome:
        _setup(s, setup)
        got = s.talk(send)
        answers = [x for x in got.lines if x == "ok" or x.startswith("error:")]
        actual = answers[-1] if answers else "(no answer)"
        return actual == f"error:{code}", f"error:{code}", actual
    return run


def _setting(number: int, text: str) -> Callable[[Session], Outcome]:
    def run(s: Session) -> Outcome:
        a = s.talk(f"${number}={text}\n".encode())
        listing = s.talk(b"$$\n")
        row = next((x for x in listing.lines if x.startswith(f"${number}=")), "(missing)")
        want = f"${number}={text}"
        ok = a.lines[-1:] == ["ok"] and row == want
        return ok, f"ok, then {want} in $$", f"{' | '.join(a.lines)}; {row}"
    return run


def _edge(number: int, send: str, want: str, setup: Sequence[bytes]) -> Callable[[Session],
                                                                               Outcome]:
    """``$n=send`` answers ``want`` (``ok`` then ``$n=shown`` in ``$$``, or ``error:N``)."""
    def run(s: Session) -> Outcome:
        _setup(s, setup)
        a = s.talk(f"${number}={send}\n".encode())
        if not want.startswith("$"):
            return a.lines[-1:] == [want], want, " | ".join(a.lines) or "(silence)"
        row = next((x for x in s.talk(b"$$\n").lines if x.startswith(f"${number}=")),
                   "(missing)")
        return (a.lines[-1:] == ["ok"] and row == want, f"ok, then {want} in $$",
                f"{' | '.join(a.lines)}; {row}")
    return run


def setting_edges(st: Setting) -> list[tuple[str, str, str]]:
    """(edge, value sent, what grbl answers) at every documented edge of one setting, from
    its table row: lo, lo - 1 (``below`` or 4 when negative), hi and hi + 1 for the integer
    kinds (kept as a truncated uint8_t, settings.c), 259 and 65535 (wrapped to 8 bits), for a
    float 99999.9 (stored in single precision: 99999.904 in ``$$``), a fraction (truncated,
    or kept to ``decimals`` places), a value with a stray letter after it (error:3, system.c)
    and no number at all (error:2, read_float)."""
    def expect(value: float) -> str:
        if value < 0:
            return "error:4"
        if st.type != "float" and (int(value) & 0xFF) < st.lo:
            return f"error:{st.below}"
        return f"${st.number}={st.text(st.coerce(value))}"

    def text(value: float) -> str:
        return f"{value:.{st.decimals}f}" if st.type == "float" else f"{value:g}"

    out = [("min", text(st.lo), expect(st.lo)), ("min-1", text(st.lo - 1), expect(st.lo - 1))]
    if st.type != "float":          # a float setting has no documented maximum
        out += [("max", text(st.hi), expect(st.hi)), ("max+1", text(st.hi + 1), expect(st.hi + 1))]
        # past 8 bits the value wraps (recorded: $0=259 stores 3, $26=65535 stores 255)
        out += [("wrap", "259", expect(259)), ("uint16-max", "65535", expect(65535))]
    else:                           # kept in single precision, printed as printFloat rounds
        out += [("single-precision", "99999.9", expect(99999.9))]
    frac = st.lo + 1.75
    out += [("fraction", f"{frac:.2f}", expect(frac)),
            ("trailing-letter", f"{text(st.default)}x", "error:3"),
            ("not-a-number", "x", "error:2")]
    return out


def _status_has(s: Session, *, timeout: float = 0.5) -> str:
    got = s.talk(b"?", timeout=timeout)
    return next((x for x in got.lines if x.startswith("<")), "(no status report)")


def _state(report: str) -> str:
    return report[1:].split("|", 1)[0] if report.startswith("<") else report


def _rt_status_no_ok(s: Session) -> Outcome:
    got = s.talk(b"?", linger=0.1)
    kinds = got.kinds(s.spec)
    return kinds == ["status"], "one status report, no ok", " | ".join(got.lines) or "(silence)"


def _far_x(s: Session) -> bytes:
    """An X in machine coordinates (G53) at least 10 mm from where the machine stands: grbl
    keeps its position across the soft reset before a check, so a fixed target may be
    where an earlier check left it (and a move there moves nothing)."""
    report = _status_has(s)
    mpos = next((f[5:] for f in report.strip("<>").split("|") if f.startswith("MPos:")), "0")
    try:
        x = float(mpos.split(",")[0])
    except ValueError:
        x = 0.0
    return b"G53X-20" if x > -10.0 else b"G53X0"


def _rt_hold_resume(s: Session) -> Outcome:
    s.talk(b"G1" + _far_x(s) + b"F300\n")
    s.wait(0.3)
    s.talk(b"!", status=0, linger=0.0)
    s.wait(1.5)
    held = _status_has(s)
    s.talk(b"~", status=0, linger=0.0)
    s.wait(0.2)
    resumed = _status_has(s)
    ok = _state(held) == "Hold:0" and _state(resumed) == "Run"
    s.talk(b"!", status=0, linger=0.0)
    return ok, "Hold:0 after '!', Run after '~'", f"{_state(held)}, {_state(resumed)}"


def _rt_reset_banner_in_motion(s: Session) -> Outcome:
    s.talk(b"G1" + _far_x(s) + b"F300\n")
    s.wait(0.3)
    got = s.talk(b"\x18", linger=0.1)
    want = ["ALARM:3", "", s.v.banner, "[MSG:'$H'|'$X' to unlock]"]
    return got.lines == want, " | ".join(want), " | ".join(got.lines)


def _rt_feed_override(s: Session) -> Outcome:
    s.talk(b"?")
    s.talk(b"?")   # WCO: then Ov: after a reset; now the counters are running
    s.target.send(b"\x91")
    s.wait(REALTIME_GAP)   # two realtime bytes in one main-loop pass: the report would go first
    report = _status_has(s)
    ov = next((f for f in report.strip("<>").split("|") if f.startswith("Ov:")), "(no Ov:)")
    return ov == "Ov:110,100,100", "Ov:110,100,100 in the next report", ov


def _rt_jog_cancel(s: Session) -> Outcome:
    s.talk(b"$J=" + _far_x(s) + b"F300\n")
    s.wait(0.3)
    s.target.send(b"\x85")
    s.wait(1.5)
    report = _status_has(s)
    return _state(report) == "Idle", "Idle after 0x85", _state(report)


def _line_limit(s: Session) -> Outcome:
    n = s.v.line_max
    fit = b"N" + b"0" * (n - 2) + b"1\n"
    over = b"N" + b"0" * (n - 1) + b"1\n"
    a, b = s.talk(fit), s.talk(over)
    actual = f"{' | '.join(a.lines)}; {' | '.join(b.lines)}"
    return a.lines == ["ok"] and b.lines == ["error:11"], f"{n} characters ok; {n + 1} error:11", actual


def _rx_ring(s: Session) -> Outcome:
    """While grbl dwells, the ring fills; what does not fit is lost (serial.c). The bytes
    are 4-byte lines up to the ring's size, then empty lines (each answered ok, protocol.c):
    the ring's last free byte holds one of them, the next is lost, so a ring one byte larger
    or smaller answers one ok more or fewer."""
    size = s.v.rx_buffer
    filler = b"G90\n" * (size // 4) + b"\n" * (size % 4 + 4)
    s.target.send(b"G4P0.5\n" + filler)
    want = 1 + size // 4 + size % 4
    got = s.collect(answers=want, timeout=3.0, linger=0.5)
    oks = sum(1 for x in got.lines if x == "ok")
    return oks == want, (f"{want} ok (the dwell + {size} bytes of lines, the last of them "
                         "empty; the rest lost)"), f"{oks} ok"


def _check_mode(s: Session) -> Outcome:
    a = s.talk(b"$C\n")
    b = s.talk(b"G1X-5F100\n")
    report = _status_has(s)
    c = s.talk(b"$C\n", linger=0.1)
    ok = (a.lines == ["[MSG:Enabled]", "ok"] and b.lines == ["ok"]
          and _state(report) == "Check" and c.lines[:2] == ["[MSG:Disabled]", "ok"]
          and s.v.banner in c.lines)
    return ok, "enabled, ok, Check, disabled + reset", " / ".join(
        " | ".join(x) for x in (a.lines, b.lines, [report], c.lines))


def _alarm_unlock(s: Session) -> Outcome:
    s.talk(b"$SLP\n", linger=0.1)
    r = s.talk(b"\x18")
    g = s.talk(b"G0X0\n")
    x = s.talk(b"$X\n")
    ok = ("[MSG:'$H'|'$X' to unlock]" in r.lines and g.lines == ["error:9"]
          and x.lines == ["[MSG:Caution: Unlocked]", "ok"])
    return ok, "locked after reset, error:9, unlocked", " / ".join(
        " | ".join(y) for y in (r.lines, g.lines, x.lines))


def _sleep(s: Session) -> Outcome:
    a = s.talk(b"$SLP\n", linger=0.1)
    report = _status_has(s)
    r = s.talk(b"\x18")
    ok = (a.lines == ["ok", "[MSG:Sleeping]"] and _state(report) == "Sleep"
          and "[MSG:'$H'|'$X' to unlock]" in r.lines)
    s.talk(b"$X\n")
    return ok, "ok, [MSG:Sleeping], Sleep, reset into Alarm", " / ".join(
        " | ".join(y) for y in (a.lines, [report], r.lines))


def _alarm_soft_limit(s: Session) -> Outcome:
    """ALARM:2, half a second of silence (report.c report_alarm_message delay_ms(500)), then
    [MSG:Reset to continue]; the critical loop takes nothing but a reset (protocol.c), and the
    G0 line grbl was inside is answered ok after the reset, before the banner."""
    _setup(s, [b"$22=1\n", b"$20=1\n", b"\x18", b"$X\n"])
    first = s.talk(b"G0X10\n", answers=0, timeout=ALARM_DELAY / 2, linger=ALARM_DELAY / 2)
    later = s.wait(ALARM_DELAY + 0.5)
    got = Talk(first.lines + later, first.t)
    after = _status_has(s)
    reset = s.talk(b"\x18", timeout=2.0)
    s.talk(b"$X\n")
    s.talk(b"$20=0\n")
    s.talk(b"$22=0\n")
    want = ["ALARM:2", "[MSG:Reset to continue]"]
    want_reset = ["ok", "", s.v.banner]
    ok = (first.lines == want[:1] and got.lines == want and after == "(no status report)"
          and reset.lines[:3] == want_reset)
    return ok, "ALARM:2 | (0.5 s) " + want[1] + "; '?' ignored; " + " | ".join(want_reset), \
        " | ".join(got.lines) + f"; {after}; " + " | ".join(reset.lines[:3])


def _alarm_probe(s: Session) -> Outcome:
    """ALARM:5, then (after report.c's 0.5 s) [PRB:…:0] with the last probe position kept
    (motion_control.c mc_probe_cycle, MESSAGE_PROBE_COORDINATES), then the line's ok. The
    probe moves 1 mm down from wherever the machine stands (G91): grbl keeps its position
    across the soft reset before the check, and a target it already stands at is error:33."""
    before = next((x for x in s.talk(b"$#\n").lines if x.startswith("[PRB:")), "(no PRB)")
    got = s.talk(b"G91G38.2Z-1F100\n", timeout=3.0 + ALARM_DELAY)
    kept = before[:-3] + ":0]" if before.startswith("[PRB:") else "[PRB:…:0]"
    want = ["ALARM:5", kept, "ok"]
    return got.lines == want, " | ".join(want), " | ".join(got.lines)


def _sequences(s: Session) -> Outcome:
    """Random sequences drawn from the tables, on the target and on the reference unit side
    by side (:mod:`.machine`); a difference is shrunk and given as its replay."""
    from conform.conformance.target import EmuTarget
    from conform.families.grbl.conformance.machine import link_budget, replay_text, run_sequences
    from conform.families.grbl.unit.model import GrblUnit

    opts = s.options
    budget = None if s.target.emulated else link_budget(opts)
    reference = EmuTarget(lambda: GrblUnit(s.v, s.spec), f"emu:{s.v.id}", baud=s.target.baud)
    try:
        out = run_sequences(s, Session(reference, s.spec, s.v), s.spec, s.v,
                            emulated=s.target.emulated, profile=opts.profile, seed=opts.seed,
                            budget=budget, max_steps=s.max_steps)
    finally:
        reference.close()
    want = "every answer as the reference unit's"
    notes = out.note
    if out.cut:
        notes += f"; {out.cut} examples left out by the link's time budget of {budget:g} s"
    if out.beyond:
        notes += (f"; {out.beyond} examples ended before a line that would move an axis more "
                  f"than --max-steps {s.max_steps} steps (never sent to the target), the first: "
                  f"{out.first_beyond}")
    if out.unconfirmed:
        notes += (f"; {len(out.unconfirmed)} differences not seen again on a replay, the first: "
                  f"{out.unconfirmed[0]}")
    if not out.steps:
        return True, want, f"{out.examples} random sequences agreed (seed {opts.seed}){notes}"
    return False, want, f"{out.why}; replay: {replay_text(out.steps)} (seed {opts.seed}){notes}"


def _crlf(s: Session) -> Outcome:
    got = s.talk(b"G90\r\n", answers=2 if s.v.crlf_is_two_lines else 1, linger=0.1)
    want = ["ok", "ok"] if s.v.crlf_is_two_lines else ["ok"]
    return got.lines == want, " | ".join(want), " | ".join(got.lines)


def generate(spec: GrblSpec, vid: str) -> list[GrblCheck]:
    """Every check of a grbl variant, generated from its tables."""
    v = spec.variant(vid)
    out: list[GrblCheck] = []
    for ex in spec.examples:
        writes = any(b"=" in x and x.startswith(b"$") for x in (*ex.setup, ex.send))
        out.append(GrblCheck(f"{vid}/{_src(ex.cite)}/example/{ex.id}", ex.cite,
                             f"documented exchange: {ex.id}", _example(ex), eeprom=writes))
    for n, c in spec.errors.items():
        if c.send is None:
            continue
        every = (*c.setup, c.send)
        moves = any(x.startswith((b"G1", b"$J", b"G0", b"G2")) for x in c.setup)
        writes = any(x.startswith(b"$") and b"=" in x and not x.startswith(b"$J") for x in every)
        out.append(GrblCheck(f"{vid}/error_codes/error/{n}", c.cite, f"error:{n} {c.name}",
                             _error(n, c.send, c.setup), motion=moves, eeprom=writes))
    out += [
        GrblCheck(f"{vid}/alarm_codes/alarm/2", spec.alarms[2].cite, "soft limit alarm",
                  _alarm_soft_limit, eeprom=True),
        GrblCheck(f"{vid}/alarm_codes/alarm/3", spec.alarms[3].cite,
                  "reset in motion: ALARM:3, banner, locked", _rt_reset_banner_in_motion,
                  motion=True),
        GrblCheck(f"{vid}/alarm_codes/alarm/5", spec.alarms[5].cite, "probe without contact",
                  _alarm_probe, motion=True),
    ]
    for n, st in spec.settings.items():
        out.append(GrblCheck(f"{vid}/setting_codes/setting/{n}", st.cite,
                             f"${n} ({st.name}) takes its default", _setting(n, st.text(st.default)),
                             eeprom=True))
        setup = tuple(f"${k}=1\n".encode() for k in st.needs)
        for edge, send, want in setting_edges(st):
            out.append(GrblCheck(f"{vid}/setting_codes/setting/{n}/{edge}", st.cite,
                                 f"${n}={send} at its {edge} edge: {want}",
                                 _edge(n, send, want, setup), eeprom=True))
    rt = {r.effect: r.cite for r in spec.realtime.values()}
    out += [
        GrblCheck(f"{vid}/realtime_cmds/realtime/status", rt["status"],
                  "'?' answers a status report and no ok", _rt_status_no_ok),
        GrblCheck(f"{vid}/realtime_cmds/realtime/hold-resume", rt["hold"],
                  "'!' holds to Hold:0, '~' resumes", _rt_hold_resume, motion=True),
        GrblCheck(f"{vid}/realtime_cmds/realtime/feed-override", rt["feed+10"],
                  "0x91 raises the feed override 10%", _rt_feed_override),
        GrblCheck(f"{vid}/jogging/realtime/jog-cancel", rt["jog-cancel"],
                  "0x85 ends a jog", _rt_jog_cancel, motion=True),
        GrblCheck(f"{vid}/protocol/buffer/line-limit", v.cite.get("line_max", ""),
                  f"a line of {v.line_max} characters fits, one more is error:11", _line_limit),
        GrblCheck(f"{vid}/serial/buffer/receive-ring", v.cite.get("rx_buffer", ""),
                  f"bytes beyond the {v.rx_buffer}-byte receive buffer are lost", _rx_ring),
        GrblCheck(f"{vid}/protocol/line/crlf", v.cite.get("crlf_is_two_lines", ""),
                  "CR LF ends two lines (the empty one answered ok)", _crlf, level=INFO),
        GrblCheck(f"{vid}/commands/state/check-mode", spec.commands["$C"].cite,
                  "$C toggles check mode; leaving it resets", _check_mode),
        GrblCheck(f"{vid}/commands/state/alarm-unlock", spec.commands["$X"].cite,
                  "locked after a reset from sleep; error:9; $X unlocks", _alarm_unlock),
        GrblCheck(f"{vid}/commands/state/sleep", spec.commands["$SLP"].cite,
                  "$SLP sleeps; a reset wakes into Alarm", _sleep),
        GrblCheck(f"{vid}{SEQUENCES}", "src:gcode.c gc_execute_line; "
                  "protocol.c; system.c; settings.c (the reference unit models them)",
                  "random lines, $ commands, settings and realtime bytes agree with the "
                  "reference unit", _sequences, motion=True, eeprom=True),
    ]
    from conform.families.grbl.conformance import from_state

    out += from_state.generate(spec, vid)
    from conform.families.grbl.conformance import in_motion

    out += in_motion.generate(spec, vid)
    from conform.families.grbl.conformance import answer_timing

    out += answer_timing.generate(spec, vid)
    from conform.families.grbl.conformance import system_effects

    out += system_effects.generate(spec, vid)
    return out


def _src(cite: str) -> str:
    head = cite.split(";")[0].split("§")[0].strip()
    if head.startswith("src:"):                      # src:gcode.c:783 ... -> gcode.c
        return head[4:].split(":")[0].split()[0]
    return {"iface": "interface", "guide": "guide", "rt": "realtime_cmds", "cmds": "commands",
            "jog": "jogging"}.get(head, head.rsplit("/", 1)[-1].split("#")[0].removesuffix(".csv")
                                  .removesuffix(".md") or "grbl")


def select(checks: list[GrblCheck], patterns: Sequence[str]) -> list[GrblCheck]:
    if not patterns:
        return checks
    return [c for c in checks if any(fnmatch.fnmatchcase(c.id, p) for p in patterns)]


RESET_COST = 0.15  # s a check's fresh start takes on a link beyond the model: Ctrl-X, banner


class GrblRunner(Runner):
    """grbl's part of the engine's runner: a fresh unit per check (soft reset), grading by the
    check's own comparison, checks beyond what the run may do SKIPPED, and the halt."""

    def __init__(self, target: Any, vid: str, *, spec: GrblSpec | None = None,
                 allow_motion: bool = False, allow_eeprom: bool = False,
                 options: RunOptions | None = None, max_steps: int | None = None) -> None:
        super().__init__(target, vid, options)
        self.spec = spec or load_grbl()
        self.session = Session(target, self.spec, self.spec.variant(vid))
        self.session.options = self.options
        self.session.max_steps = max_steps
        self.motion_ok = allow_motion or target.emulated
        self.eeprom_ok = allow_eeprom or target.emulated

    def run_check(self, check: GrblCheck) -> CheckResult:
        bound = self.session.max_steps
        far = self._farthest(check) if bound is not None and check.motion and \
            self.motion_ok and not check.id.endswith(SEQUENCES) else 0
        if bound is not None and far > bound:
            result = CheckResult(id=check.id, clause=check.clause, level=check.level,
                                 title=check.title, grade=Grade.SKIPPED,
                                 detail=f"moves an axis {far} steps, beyond --max-steps {bound} "
                                        f"(the reference unit from power-up; enable with "
                                        f"--max-steps {far})")
        else:
            result = _one(self.session, check, self.motion_ok, self.eeprom_ok)
        result.variant, result.target = self.variant_id, self.target.name
        if check.id.endswith(SEQUENCES):
            result.seed = self.options.seed
            result.replay = f"{check.id}@{self.options.seed}"
        return result

    def _farthest(self, check: GrblCheck) -> int:
        """The most whole steps a block of ``check`` takes an axis, on the reference unit
        started at power-up (the random sequences weigh each line themselves)."""
        from conform.conformance.target import EmuTarget
        from conform.families.grbl.conformance.machine import Weighed

        units: list[Weighed] = []

        def make() -> Weighed:
            units.append(Weighed(self.session.v, self.spec))
            return units[-1]

        sim = EmuTarget(make, "weigh", baud=self.target.baud)
        try:
            s = Session(sim, self.spec, self.session.v)
            s.fresh()
            check.run(s)
        except HarnessError:
            pass
        finally:
            sim.close()
        return max(u.farthest for u in units)

    def halt(self, after_silence: bool = False) -> str:
        return stop_unit(self.target)

    def stop_at_end(self) -> bool:
        return not self.target.emulated and self.motion_ok

    def machine_budget(self) -> float | None:
        """Wall time of the random sequences' examples on a link (None: in-process)."""
        from conform.families.grbl.conformance.machine import link_budget

        return None if self.target.emulated else link_budget(self.options)

    def estimate_run(self, checks: Sequence[GrblCheck]) -> Estimate:
        """Each check as long as it takes the reference unit on its virtual clock at the
        target's baud, plus the soft reset before it."""
        from conform.conformance.target import EmuTarget
        from conform.families import family

        vid = self.variant_id
        sim = EmuTarget(lambda: family("grbl").make_unit(vid), "estimate", baud=self.target.baud)
        s = Session(sim, self.spec, self.session.v)
        est = Estimate()
        for c in checks:
            cost = 0.0
            if c.id.endswith(SEQUENCES) and self.motion_ok and self.eeprom_ok:
                cost = (self.machine_budget() or 0.0) + RESET_COST
            elif not (c.motion and not self.motion_ok) and not (c.eeprom and not self.eeprom_ok):
                s.fresh()
                t0 = sim.now()
                try:
                    c.run(s)
                except HarnessError:
                    pass
                cost = sim.now() - t0 + RESET_COST
            est.per_check[c.id] = cost
            est.total += cost
        return est


def run_checks(target: Any, vid: str, *, patterns: Sequence[str] = (), profile: str = "quick",
               allow_motion: bool = False, allow_eeprom: bool = False, notes: list[str] | None = None,
               progress: Callable[[CheckResult], None] | None = None,
               spec: GrblSpec | None = None,
               announce: Callable[[str], None] | None = None, sequences: bool = True,
               seed: int = 1, max_steps: int | None = None) -> TargetRun:
    """Run the checks on an open target (EmuTarget or LinkTarget) in the engine's runner; an
    interrupted run comes back with ``aborted`` saying what was sent to stop the unit.
    ``sequences=False`` leaves the random sequences out (the mutant run, as GVE's); ``seed``
    draws them (the command line's default, 1); ``max_steps`` bounds their moves."""
    from conform.conformance.runner import RunAborted

    runner = GrblRunner(target, vid, spec=spec, allow_motion=allow_motion,
                        allow_eeprom=allow_eeprom, max_steps=max_steps,
                        options=RunOptions(profile=profile, seed=seed, notes=list(notes or []),
                                           announce=announce))
    try:
        checks = [c for c in generate(runner.spec, vid)
                  if sequences or not c.id.endswith(SEQUENCES)]
        return runner.run(select(checks, patterns), progress)
    except RunAborted as exc:
        return exc.run


def _one(s: Session, c: GrblCheck, motion_ok: bool, eeprom_ok: bool) -> CheckResult:
    base = dict(id=c.id, clause=c.clause, level=c.level, title=c.title)
    if c.motion and not motion_ok:
        return CheckResult(grade=Grade.SKIPPED, detail="moves the machine: needs --allow-motion",
                           **base)
    if c.eeprom and not eeprom_ok:
        return CheckResult(grade=Grade.SKIPPED, detail="writes settings: needs --allow-eeprom",
                           **base)
    t0 = time.perf_counter()
    try:
        s.fresh()
        passed, expected, actual = c.run(s)
        grade = Grade.PASS if passed else (Grade.DEVIATION if c.level == INFO else Grade.FAIL)
        detail = ""
        if passed is None:
            grade, detail = Grade.NOT_APPLICABLE, (
                actual if actual.startswith("not applicable:")
                else "the unit is not in its power-up position")
        if not s.target.emulated:
            s.restore()
    except HarnessError as exc:
        grade, expected, actual, detail = Grade.ERROR, "", "", f"HarnessError: {exc}"
    if grade is not Grade.PASS and not s.target.emulated and c.motion:
        detail = (detail + "; " if detail else "") + stop_unit(s.target)
    return CheckResult(grade=grade, expected=expected, actual=actual, detail=detail,
                       log=list(s.target.log), duration=time.perf_counter() - t0, **base)


def _until_still(target: Any, seconds: float) -> None:
    """Ask '?' until grbl reports Hold:0, Idle, Alarm or Door:0 (or the time is up)."""
    deadline = target.now() + seconds
    while target.now() < deadline:
        target.send(b"?")
        buf = b""
        end = min(deadline, target.now() + 0.2)
        while target.now() < end:
            buf += target.receive(end)
        if any(s in buf for s in (b"<Hold:0|", b"<Idle|", b"<Alarm|", b"<Door:0|")):
            return


def stop_unit(target: Any, attempts: int = 3) -> str:
    """Feed hold, then a soft reset, until grbl acknowledges with its banner: the machine
    stands and the planner and receive buffer are empty."""
    notes = []
    for _ in range(attempts):
        try:
            target.send(b"!")
            _until_still(target, 5.0)   # a reset after the stop keeps the position (no ALARM:3)
            target.send(b"\x18")
            deadline = target.now() + 2.0
            buf = b""
            while target.now() < deadline and b"for help]" not in buf:
                buf += target.receive(deadline)
            if b"for help]" in buf:
                return "stopped: feed hold and soft reset, acknowledged by the banner"
            notes.append("no banner after the reset")
        except Exception as exc:  # noqa: BLE001 - report, try again
            notes.append(f"not sent ({exc})")
    return "stop NOT acknowledged: " + "; ".join(notes)


