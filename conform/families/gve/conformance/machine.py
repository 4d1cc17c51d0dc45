"""Random command sequences: a hypothesis ``RuleBasedStateMachine`` with one rule per command
family of the tables, run on the target and on the reference unit side by side.

Every answer of the target is compared with the reference's (positions while moving within a
tolerance on a real unit). A difference that a one-question change of dialect reproduces over
the whole sequence so far is a DEVIATION and the machine adopts that dialect from then on; any
other difference fails the example, hypothesis shrinks it, and the shrunk sequence, its tx/rx log
and the seed that replays it become the finding.
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from hypothesis import HealthCheck, Phase, Verbosity, settings
from hypothesis import strategies as st
from hypothesis.errors import HypothesisException
from hypothesis.stateful import RuleBasedStateMachine, get_state_machine_test, rule

from conform.conformance.results import INFO, CheckResult, Grade, LogEntry
from conform.conformance.target import HarnessError, Reply
from conform.errors import LinkError
from conform.families.gve.conformance.checks import Check, answer_kind, answer_shape, clause_number
from conform.families.gve.conformance.expect import (
    answers_differ,
    first_mismatch,
    reply_mismatch,
    show,
    tolerance_of,
)
from conform.families.gve.conformance.safety import SafetyRefusal, hazards
from conform.families.gve.conformance.script import ENVIRONMENT, Step
from conform.families.gve.conformance.target import POLL_LINE, GveEmuTarget
from conform.families.gve.protocol import encode_command
from conform.families.gve.protocol.checksum import append_checksum

PROFILES = {"quick": (100, 40), "full": (600, 80)}  # examples, steps per example
SHRINK_SECONDS = {"quick": 8.0, "full": 60.0}  # wall-clock budget for shrinking a failure
_SPEEDS = (10, 100, 1000, 5000, 20000)


def machine_check(spec: Any, variant_id: str) -> Check:
    v = spec.variant(variant_id)
    first = v.commands["?"].clause_for(v.manual)
    clause = first.rsplit(".", 1)[0]
    return Check(f"{v.id}/{clause_number(clause)}/sequences", v.id, clause,
                 "random command sequences agree with the reference unit", (), INFO,
                 (), None, "machine")


@dataclass
class _Shared:
    """What survives from one hypothesis example to the next."""

    dialect: Any
    deviations: dict[tuple[str, str], list[str]] = field(default_factory=dict)
    failure: dict[str, Any] | None = None
    examples: int = 0
    steps: int = 0
    deadline: float | None = None  # perf_counter() after which examples send nothing (a link)
    cut: int = 0  # examples left out by the deadline


def _arg_strategy(p: Any, v: Any, max_travel: int) -> st.SearchStrategy[list[Any]]:
    """Values for one parameter: mostly valid, sometimes at or past an edge."""
    if p.kind == "sign":
        return st.sampled_from(p.choices).map(lambda c: [c])
    if p.kind == "axis":
        return st.sampled_from(v.axes).map(lambda a: [a])
    if p.kind == "float":
        return st.sampled_from([0.5, 1.5, 100.0, 2500.25]).map(lambda x: [x])
    lo, hi = p.lo, p.hi
    if p.range_name == "pulses":
        one = st.integers(-max_travel, max_travel)
    elif p.range_name == "travel":  # W's travels: inside the envelope (issue: --max-steps)
        one = st.integers(0, max_travel)
    elif p.range_name == "velocity":
        one = st.one_of(st.sampled_from([s for s in _SPEEDS if lo <= s <= hi]),
                        st.sampled_from([lo, hi, lo - 1, hi + 1]))
    elif lo is not None and hi is not None:
        one = st.one_of(st.integers(lo, min(hi, lo + 255)), st.sampled_from([lo, hi, hi + 1]))
    else:
        one = st.integers(0, 100)
    if p.per_axis:
        n = len(v.axes)
        need = p.min_count or n
        return st.lists(one, min_size=need, max_size=n)
    return one.map(lambda x: [x])


W_SECONDS = 2.0  # the longest leg of a generated reference move (W answers when it is done)


def _short_reference_move(args: list[Any]) -> list[Any]:
    """W's travels cut to what its speeds cover in W_SECONDS: a unit answers nothing else until
    W is done, so a slow, long move would stall a run on a link for minutes."""
    axis, to_switch, speed_to, from_switch, speed_from = args
    if isinstance(speed_to, int) and isinstance(to_switch, int) and speed_to > 0:
        cap = int(speed_to * W_SECONDS)
        to_switch = max(-cap, min(cap, to_switch))
    if isinstance(speed_from, int) and isinstance(from_switch, int) and speed_from > 0:
        from_switch = min(int(speed_from * W_SECONDS), from_switch)
    return [axis, to_switch, speed_to, from_switch, speed_from]


def _families(v: Any, allowed: set[str], emulated: bool) -> dict[str, list[Any]]:
    out: dict[str, list[Any]] = defaultdict(list)
    for cmd in v.commands.values():
        if cmd.id in ("*S", "*E"):
            continue  # the packet rule builds whole packets
        out[cmd.family].append(cmd)
    if "motion" not in allowed:
        out.pop("vector", None)
        out.pop("reference", None)
        out["mpg"] = []
    return {k: vs for k, vs in out.items() if vs}


def build_machine(runner: Any, shared: _Shared, examples: int, steps: int) -> type:
    """The state machine class for one runner (target, variant, reference)."""
    target = runner.target
    v = runner.variant
    spec = runner.spec
    guard = target.guard
    allowed = {"reset"} | ({"motion", "actuator"} if guard.allow_motion else set()) \
        | ({"eeprom"} if guard.allow_eeprom else set())
    max_travel = min(guard.max_steps or 5000, 5000)
    families = _families(v, allowed, target.emulated)
    unit_cls = runner.ref.unit_cls
    loose = runner.loose
    tol_of = tolerance_of(float(v.max_rate), loose)

    class Sequences(RuleBasedStateMachine):
        def __init__(self) -> None:
            super().__init__()
            d = shared.dialect
            self.ref = GveEmuTarget(lambda: unit_cls(v, d), "reference")
            self.script: list[Step] = [Step(reset=True)]
            self.actual: list[Reply | None] = [None]
            self.off = (shared.deadline is not None and shared.failure is None
                        and time.perf_counter() > shared.deadline)
            if self.off:
                shared.cut += 1
                return
            # J and its readiness polled with @ (on a link the unit's deaf time is measured,
            # never guessed); the reference gets the same @
            poll = target.reset_polled()
            target.begin_log()
            self.script.append(Step(line=POLL_LINE))
            self.actual.append(poll)
            self.ref.exchange(POLL_LINE)
            shared.examples += 1

        # -- sending -------------------------------------------------------------------------
        def _frame(self, body: bytes) -> bytes:
            on = self.ref.unit.checksum_on
            return (append_checksum(body) if on else body) + b"\r"

        def _send(self, step: Step) -> None:
            if self.off:
                return
            risks = hazards(step.line)
            if risks - allowed:
                return
            if step.line and guard.max_steps is not None:
                try:
                    guard.check(step.line)
                except SafetyRefusal:
                    return  # drawn outside the envelope: not sent (the draws stay inside)
            self.script.append(step)
            shared.steps += 1
            if step.wait:
                target.wait(target.ready_wait(step.wait) if step.ready else step.wait)
                self.ref.wait(step.wait)
            if not target.emulated:  # keep the reference on the target's timeline
                lag = (target.now() - target.t_log0) - self.ref.now()
                if lag > 0:
                    self.ref.wait(lag)
            if step.answer:
                a = target.exchange(step.line, step.timeout, step.lines)
                e = self.ref.exchange(step.line, step.timeout, step.lines)
            else:
                t, stray = target.send(step.line)
                a = Reply(step.line, t - target.t_log0, stray=stray)
                t, stray = self.ref.send(step.line)
                e = Reply(step.line, t, stray=stray)
            self.actual.append(a)
            why = reply_mismatch(step, e, a, loose, tol_of(e, a))
            if why is not None:
                self._differs(len(self.script) - 1, why, e, a)

        def _differs(self, index: int, why: str, e: Reply, a: Reply) -> None:
            script = tuple(self.script)
            ref = runner.ref
            if shared.failure is None:
                questions = ref.candidate_questions(script)
            else:  # shrinking a known failure: only the failing command's own questions
                questions = ref.candidate_questions(script[index:index + 1], (), False)
            base = shared.dialect

            for q in questions:
                for alt in spec.questions[q].alternatives:
                    if alt == base[q]:
                        continue
                    d = spec.dialect(base.changed() | {q: alt})
                    other = ref.transcript(script, d)
                    if not answers_differ(script[index], e, other[index] if index < len(other) else None):
                        continue  # the alternative leaves this answer as it is: not its question's
                    if first_mismatch(script, other, self.actual, loose, tol_of) is None:
                        shared.dialect = d
                        shared.deviations.setdefault((q, alt), [s.describe() for s in script])
                        self._rebuild(d)
                        return
            step = script[index]
            shared.failure = {
                "index": index, "why": why, "sequence": [s.describe() for s in script],
                "expected": f"{step.describe()} → {show(step, e)}",
                "actual": f"{step.describe()} → {show(step, a)}",
                "log": list(target.log), "command": (ref.command_ids([step]) or [""])[0],
            }
            raise AssertionError(f"{step.describe()}: {why}")

        def _rebuild(self, d: Any) -> None:
            """A reference in the state the adopted dialect reaches after the same steps."""
            self.ref = GveEmuTarget(lambda: unit_cls(v, d), "reference")
            for step in self.script[1:]:
                if step.wait:
                    self.ref.wait(step.wait)
                if step.answer:
                    self.ref.exchange(step.line, step.timeout, step.lines)
                elif step.line:
                    self.ref.send(step.line)

        def _command(self, cmd: Any, args: list[Any]) -> None:
            address = v.spindle_address if cmd.id == "7V" else (
                v.interpolator_address if 0 in cmd.addresses else v.spindle_address)
            try:
                line = encode_command(v, cmd, args, address=address)
            except ValueError:
                return
            line = self._frame(line[:-1])
            kind = answer_kind(cmd.id)
            self._send(Step(line=line, kind=kind, timeout=cmd.answer_within,
                            lines=2 if cmd.id == ">" else 1,
                            shape=answer_shape(cmd) if kind == ENVIRONMENT else ()))
            if cmd.id == "J":
                self._send(Step(line=self._frame(b"!0F"), wait=2.2, ready=True))

        # -- rules: one per family, added below -----------------------------------------------
        @rule(seconds=st.sampled_from([0.01, 0.1, 0.5, 2.0]))
        def wait(self, seconds: float) -> None:
            """Let time pass: vectors progress and end."""
            self._send(Step(line=self._frame(b"!0F"), wait=seconds))

        @rule(junk=st.sampled_from([b"!0ZZ", b"!0V", b"!0V1,2", b"!0L1", b"!0SR9", b"!0v100",
                                    b"!3V100", b"!0 V100"]))
        def malformed(self, junk: bytes) -> None:
            """Lines the unit must reject (unknown, syntax, range, other address)."""
            self._send(Step(line=self._frame(junk)))

        if "motion" in allowed:
            @rule(n=st.integers(0, 4), data=st.data())
            def packet(self, n: int, data: Any) -> None:
                """A packet of n C/B lines (GVE64 §13.3.3)."""
                self._send(Step(line=self._frame(b"!0*S"), answer=False))
                for _ in range(n):
                    if data.draw(st.booleans()):
                        vec = data.draw(_arg_strategy(v.commands["C"].params[0], v, max_travel))
                        self._command_silent(v.commands["C"], vec)
                    else:
                        self._command_silent(v.commands["B"], [data.draw(st.sampled_from(_SPEEDS))])
                count = data.draw(st.sampled_from([n, n + 1]))
                self._send(Step(line=self._frame(b"!0*E%d" % count)))

        def _command_silent(self, cmd: Any, args: list[Any]) -> None:
            line = encode_command(v, cmd, args)
            self._send(Step(line=self._frame(line[:-1]), answer=False))

    def make_rule(fam: str, cmds: list[Any]) -> Any:
        def family_rule(self: Any, data: Any) -> None:
            cmd = data.draw(st.sampled_from(cmds), label="command")
            args: list[Any] = []
            for p in cmd.params:
                args += data.draw(_arg_strategy(p, v, max_travel), label=p.name)
            if cmd.id == "Y" and "motion" not in allowed:
                args = ["-"]
            if cmd.id == "W":
                args = _short_reference_move(args)
            if cmd.id in ("EW", "EFW", "EUW") and "eeprom" not in allowed:
                return
            self._command(cmd, args)

        family_rule.__name__ = f"family_{fam}"
        family_rule.__doc__ = f"A command of family {fam!r}: " + ", ".join(c.id for c in cmds)
        return rule(data=st.data())(family_rule)

    for fam, cmds in families.items():
        setattr(Sequences, f"family_{fam}", make_rule(fam, cmds))
    Sequences.__name__ = f"Sequences_{v.id.replace('-', '_')}"
    return Sequences


@contextmanager
def _shrink_budget(seconds: float) -> Iterator[None]:
    """Bound hypothesis's shrinking by wall time (its engine's own cap is 300 s)."""
    from hypothesis.internal.conjecture import engine

    old = getattr(engine, "MAX_SHRINKING_SECONDS", None)
    if old is None:
        yield
        return
    engine.MAX_SHRINKING_SECONDS = seconds
    try:
        yield
    finally:
        engine.MAX_SHRINKING_SECONDS = old


def run_machine(runner: Any, check: Check) -> CheckResult:
    """Run the state machine for ``check`` on the runner's target; one graded result."""
    opts = runner.options
    examples, steps = PROFILES.get(opts.profile, PROFILES["quick"])
    examples = opts.examples or examples
    steps = opts.steps or steps
    seed = int(opts.seed)
    shared = _Shared(runner.ref.dialect)
    budget = runner.machine_budget() if hasattr(runner, "machine_budget") else None
    if budget is not None:
        shared.deadline = time.perf_counter() + budget
    machine = build_machine(runner, shared, examples, steps)
    machine.TestCase.settings = settings(max_examples=examples, stateful_step_count=steps)
    conf = settings(max_examples=examples, stateful_step_count=steps, deadline=None,
                    database=None, derandomize=False, verbosity=Verbosity.quiet,
                    print_blob=False, suppress_health_check=list(HealthCheck),
                    report_multiple_bugs=False,
                    phases=[Phase.generate, Phase.shrink])
    test = get_state_machine_test(machine, settings=conf)
    test._hypothesis_internal_use_seed = seed  # what @hypothesis.seed(n) sets
    base = dict(id=check.id, clause=check.clause, level=check.level, title=check.title,
                variant=runner.variant.id, target=runner.target.name, seed=seed,
                replay=f"{check.id}@{seed}")
    t0 = time.perf_counter()
    try:
        with _shrink_budget(SHRINK_SECONDS.get(opts.profile, 8.0)):
            test()
    except AssertionError:
        f = shared.failure or {}
        cid = f.get("command") or ""
        cmd = runner.spec.commands.get(cid)
        clause = cmd.clause_for(runner.variant.manual) if cmd else check.clause
        return CheckResult(grade=Grade.FAIL, expected=f.get("expected", ""),
                           actual=f.get("actual", ""),
                           detail=f"{f.get('why', 'answers differ')}; shrunk to "
                                  f"{len(f.get('sequence', [])) - 1} commands after "
                                  f"{shared.examples} examples",
                           sequence=f.get("sequence", []), log=f.get("log", []),
                           duration=time.perf_counter() - t0,
                           **(base | {"clause": clause}))
    except (HarnessError, LinkError, HypothesisException) as exc:
        from conform.families.gve.conformance.target import could_not

        return CheckResult(grade=Grade.ERROR, detail=could_not(exc),
                           log=list(runner.target.log), duration=time.perf_counter() - t0,
                           **base)
    summary = (f"{shared.examples} sequences, {shared.steps} commands "
               f"({examples} examples × up to {steps} steps)")
    if shared.cut:
        summary += (f"; {shared.cut} examples left out by the link's time budget of "
                    f"{budget:g} s")
    if shared.deviations:
        (q, alt), seq = next(iter(shared.deviations.items()))
        others = ", ".join(f"{a}={b}" for a, b in list(shared.deviations)[1:])
        meaning = runner.spec.questions[q].alternatives[alt]
        return CheckResult(grade=Grade.DEVIATION, question=q, alternative=alt,
                           detail=f"{q}={alt}: {meaning}" + (f"; also {others}" if others else "")
                                  + f"; {summary}",
                           sequence=seq, duration=time.perf_counter() - t0, **base)
    return CheckResult(grade=Grade.PASS, detail=summary, duration=time.perf_counter() - t0,
                       log=[LogEntry(0.0, "note", summary.encode())], **base)
