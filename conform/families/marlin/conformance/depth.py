"""Marlin checks for every G/M code a host sees in the linux_native build beyond the line
protocol: settings set and read back (M92, M201, M203, M204, M205, M206, M301, M304, M220,
M221), the EEPROM (M500-M504), reports (M503, M119, M31, M111), tools (T0-T7), messages
(M117, M118), units and unknown words, dwell, modes and moves, heater targets.

How a settings check tells a command from its neighbour: it first sets every setting to a
value neither the default nor any other setting's (``BASE``), runs the command, then reads
back everything the command may and must not touch (M503's whole report, M220, M221) and
compares all of it with what the source says the command does. A unit that writes M201's
values for M203, X's for Y, or resets the others to their defaults fails it.

On a real unit every settings check puts back the values M503 showed before it (and M220,
M221, M111); the EEPROM checks (``--allow-eeprom``) end by storing those values with M500,
so the EEPROM then holds what the unit had in RAM at the start of the check.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from copy import deepcopy
from dataclasses import dataclass

from conform.families.marlin.conformance.check import MarlinCheck, Outcome
from conform.families.marlin.conformance.check import ok_kind as _ok_kind
from conform.families.marlin.conformance.session import Session, Talk
from conform.families.marlin.spec import MarlinSpec
from conform.families.marlin.unit import settings as st

Values = dict[str, list[float]]
# a starting state unlike the defaults and unlike each other, every value exact at 2 decimals
BASE: Values = {"M92": [81.25, 82.5, 401.75, 502.5], "M203": [201.5, 202.5, 4.5, 21.5],
                "M201": [2001.0, 2002.0, 91.0, 9001.0], "M204": [2101.0, 2102.0, 2103.0],
                "M205": [10001.0, 1.25, 2.5, 0.02], "M206": [1.5, 2.5, 3.5],
                "M301": [20.5, 1.25, 100.5], "M304": [11.5, 0.25, 300.5]}
NEW: Values = {"M92": [87.5, 88.25, 402.5, 505.75], "M203": [210.5, 220.5, 6.5, 30.5],
               "M201": [2500.0, 2600.0, 110.0, 9500.0], "M204": [2200.0, 2300.0, 2400.0],
               "M205": [15000.0, 2.25, 3.75, 0.05], "M206": [-4.5, 5.25, -0.75],
               "M301": [25.5, 1.5, 120.25], "M304": [12.5, 0.5, 310.75]}
MORE: Values = {"M92": [100.0, 0.5, 1600.0, 93.0], "M203": [0.5, 1000.0, 0.25, 99.0],
                "M201": [1.0, 50000.0, 7.0, 123.0], "M204": [1.0, 99999.0, 0.5],
                "M205": [1.0, 0.0, 100.0, 0.3], "M206": [0.0, -100.25, 50.0],
                "M301": [0.0, 0.01, 999.5], "M304": [1.0, 2.0, 0.0]}
BASE_FR, BASE_FLOW = 110, 95
STORED = re.compile(r"^echo:Settings Stored \(\d+ bytes; crc \d+\)$")
RETRIEVED = re.compile(r"^echo:V\d+ stored settings retrieved \(\d+ bytes; crc \d+\)$")
_REPORT = re.compile(r"^echo:  (M\d+) (.*)$")
_POS = re.compile(r"^X:(-?[\d.]+) Y:(-?[\d.]+) Z:(-?[\d.]+) E:(-?[\d.]+) Count X:(-?\d+) "
                  r"Y:(-?\d+) Z:(-?\d+)$")


@dataclass
class State:
    """What a settings check reads back: M503's values, M220's and M221's percentages."""

    values: Values
    fr: str
    flow: str

    def show(self) -> str:
        return "; ".join(st.report_line(c, v).strip() for c, v in self.values.items()) + \
            f"; {self.fr}; {self.flow}"


def _file(cite: str) -> str:
    """The source file a citation starts with (``gcode/config/M92.cpp ...`` -> M92.cpp)."""
    return cite.split(" ")[0].split("/")[-1].rstrip(";,")


def _line(code: str, values: list[float]) -> bytes:
    return (st.report_line(code, values).strip() + "\n").encode()


def read_values(s: Session) -> Values:
    """M503's setting lines (its ok ends the answer: nothing is waited for after it)."""
    got = s.talk(b"M503\n", linger=0.0)
    out: Values = {}
    for line in got.lines:
        m = _REPORT.match(line)
        if m and m.group(1) in st.ORDER:
            try:
                out[m.group(1)] = [float(w[1:]) for w in m.group(2).split()]
            except ValueError:
                continue
    return out


def _only(got: Talk, s: Session) -> list[str]:
    """The answer's lines before its ok."""
    return [x for x in got.lines if not _ok_kind(s, x)]


def read_state(s: Session) -> State:
    fr = _only(s.talk(b"M220\n", linger=0.0), s)
    flow = _only(s.talk(b"M221\n", linger=0.0), s)
    return State(read_values(s), fr[0] if len(fr) == 1 else " | ".join(fr),
                 flow[0] if len(flow) == 1 else " | ".join(flow))


def put(s: Session, state: State) -> None:
    """Set the unit to ``state`` (what read_state gave, or a wanted one). Each line's ok is
    its only answer, so nothing is waited for after it (a stray line after an ok still
    shows in the next exchange)."""
    for code, values in state.values.items():
        s.talk(_line(code, values), linger=0.0)
    for cmd, text in (("M220", state.fr), ("M221", state.flow)):
        m = re.search(r"(\d+)%", text)
        if m:
            s.talk(f"{cmd} S{m.group(1)}\n".encode(), linger=0.0)


def base_state() -> State:
    return State(deepcopy(BASE), f"FR:{BASE_FR}%", f"echo:E0 Flow: {BASE_FLOW}%")


def restoring(body: Callable[[Session], Outcome], *, store: bool = False
              ) -> Callable[[Session], Outcome]:
    """``body`` run from BASE, the unit's own settings put back after (and stored again with
    M500 when ``store``: the EEPROM checks)."""
    def run(s: Session) -> Outcome:
        before = read_state(s)
        try:
            put(s, base_state())
            return body(s)
        finally:
            put(s, before)
            if store:
                s.talk(b"M500\n")
    run.__doc__ = body.__doc__
    return run


def _compare(want: State, got: State, printed_want: list[str], printed: list[str]) -> Outcome:
    problems = []
    if printed != printed_want:
        problems.append(f"printed {' | '.join(printed) or '(nothing)'}")
    for code in st.ORDER:       # as printed: two decimals
        have = got.values.get(code)
        shown = st.report_line(code, have).strip() if have else f"{code} missing"
        if shown != st.report_line(code, want.values[code]).strip():
            problems.append(f"M503 {shown}")
    if got.fr != want.fr:
        problems.append(f"M220: {got.fr}")
    if got.flow != want.flow:
        problems.append(f"M221: {got.flow}")
    expected = (" | ".join(printed_want) or "nothing printed") + "; then " + want.show()
    return not problems, expected, "; ".join(problems) or "as expected"


def set_case(command: str, effect: Callable[[State], None],
             printed: Callable[[State], list[str]] | list[str] = ()
             ) -> Callable[[Session], Outcome]:
    """From BASE send ``command``: it prints ``printed`` and then the settings are BASE with
    ``effect`` applied, nothing else changed."""
    def body(s: Session) -> Outcome:
        want = base_state()
        printed_want = printed(want) if callable(printed) else list(printed)
        got = s.talk(f"{command}\n".encode())
        effect(want)
        return _compare(want, read_state(s), printed_want, _only(got, s))
    return restoring(body)


def _assign(code: str, i: int, value: float) -> Callable[[State], None]:
    def effect(w: State) -> None:
        w.values[code][i] = value
    return effect


def _assign_all(code: str, values: list[float]) -> Callable[[State], None]:
    def effect(w: State) -> None:
        w.values[code] = list(values)
    return effect


def _nothing(w: State) -> None:
    return None


def _word(code: str, letter: str, value: float) -> str:
    return f"{code} {letter}{st.number(value)}"


def m206_set(s: Session, letter: str, i: int, value: float) -> Outcome:
    """M206 <axis>: the offset set, and report_current_position shows the logical position
    moved by the change (Count, the steppers, unchanged)."""
    pos = _position(s)
    got = s.talk(f"{_word('M206', letter, value)}\n".encode())
    printed = _only(got, s)
    want = base_state()
    want.values["M206"][i] = value
    state = read_state(s)
    if pos is None:
        return False, "a position from M114", "no X: Y: Z: line from M114"
    shifted = list(pos)
    shifted[i] = round(pos[i] + value - BASE["M206"][i], 2)
    line = (f"X:{shifted[0]:.2f} Y:{shifted[1]:.2f} Z:{shifted[2]:.2f} E:{shifted[3]:.2f} "
            f"Count X:{int(pos[4])} Y:{int(pos[5])} Z:{int(pos[6])}")
    return _compare(want, state, [line], printed)


def _position(s: Session) -> list[float] | None:
    got = s.talk(b"M114\n")
    for x in got.lines:
        m = _POS.match(x)
        if m:
            return [float(g) for g in m.groups()]
    return None


def settings_checks(spec: MarlinSpec, vid: str, profile: str) -> list[MarlinCheck]:
    v = spec.variant(vid)
    tab = st.table()
    cmd = {k: x.cite for k, x in spec.commands.items()}
    out: list[MarlinCheck] = []

    def add(code: str, name: str, title: str, run: Callable[[Session], Outcome],
            cite: str = "", **kw: object) -> None:
        out.append(MarlinCheck(f"{vid}/{_file(cmd[code])}/settings/{name}", cite or cmd[code], title,
                               run, **kw))  # type: ignore[arg-type]

    values_sets = [("", NEW)] + ([("-more", MORE)] if profile == "full" else [])
    for code in st.ORDER:
        letters = tab.words[code]
        low = code.lower()
        for suffix, table in values_sets:
            for i, letter in enumerate(letters):
                value = table[code][i]
                if code == "M206":
                    add(code, f"{low}-{letter.lower()}{suffix}",
                        f"{code} {letter}: only {letter}'s offset changes; the position moves "
                        "with it", restoring(lambda s, li=letter, j=i, x=value:
                                             m206_set(s, li, j, x)))
                    continue
                if code == "M205" and letter == "J" and suffix:
                    continue                  # J has its own range checks
                add(code, f"{low}-{letter.lower()}{suffix}",
                    f"{code} {letter}{st.number(value)}: only {letter} changes, nothing else",
                    set_case(_word(code, letter, value), _assign(code, i, value)))
        if code != "M206":
            whole = " ".join(f"{w}{st.number(x)}" for w, x in zip(letters, NEW[code],
                                                                    strict=True))
            add(code, f"{low}-all", f"{code} with every word: all of them, nothing else",
                set_case(f"{code} {whole}", _assign_all(code, NEW[code])))
        add(code, f"{low}-report", f"{code} without a value: its report line (no heading, "
            "no echo:), nothing changed",
            set_case(code, _nothing, lambda w, c=code: [st.report_line(c, w.values[c])]))

    def small_e(w: State) -> None:
        w.values["M203"][3] = round(BASE["M203"][3] * BASE["M92"][3] / 10.0, 2)
        w.values["M92"][3] = 10.0

    def legacy_s(w: State) -> None:
        w.values["M204"][0] = w.values["M204"][2] = 1800.0

    add("M92", "m92-e-below-20", "M92 E10: E's max feedrate grows by old/new steps",
        set_case("M92 E10", small_e))
    add("M204", "m204-s-legacy", "M204 S: print and travel acceleration, not retract",
        set_case("M204 S1800", legacy_s))
    add("M205", "m205-j-out-of-range", "M205 J0.5: Error:?J out of range, J unchanged",
        set_case("M205 J0.5", _nothing, ["Error:?J out of range (0.01 to 0.3)"]))
    add("M205", "m205-j-low", "M205 J0.005: Error:?J out of range, J unchanged",
        set_case("M205 J0.005", _nothing, ["Error:?J out of range (0.01 to 0.3)"]))
    add("M205", "m205-j-edge", "M205 J0.3 (the upper bound) is taken",
        set_case("M205 J0.3", _assign("M205", 3, 0.3)))
    if profile == "full":
        add("M205", "m205-b-integer", "M205 B12345.7: B is read as a whole number",
            set_case("M205 B12345.7", _assign("M205", 0, 12345.0)))
    for code in ("M92", "M201", "M203"):
        add(code, f"{code.lower()}-t{v.extruders}", f"{code} T{v.extruders} E1: echo:{code} "
            "Invalid extruder, nothing set", set_case(
                f"{code} T{v.extruders} E1", _nothing,
                [f"echo:{code} Invalid extruder {v.extruders}"]),
            cite=cmd[code] + "; gcode.cpp GcodeSuite::get_target_extruder_from_command")

    def fr(p: int) -> Callable[[State], None]:
        def effect(w: State) -> None:
            w.fr = f"FR:{p}%"
        return effect

    def flow(p: int) -> Callable[[State], None]:
        def effect(w: State) -> None:
            w.flow = f"echo:E0 Flow: {p}%"
        return effect

    add("M220", "m220-set", "M220 S150: the feedrate percentage, not the flow",
        set_case("M220 S150", fr(150)))
    add("M220", "m220-report", "M220: FR:<n>% (no echo:), nothing changed",
        set_case("M220", _nothing, [f"FR:{BASE_FR}%"]))
    add("M221", "m221-set", "M221 S80: the flow percentage, not the feedrate",
        set_case("M221 S80", flow(80)))
    add("M221", "m221-report", "M221: echo:E0 Flow: <n>%, nothing changed",
        set_case("M221", _nothing, [f"echo:E0 Flow: {BASE_FLOW}%"]))
    add("M221", f"m221-t{v.extruders}", f"M221 T{v.extruders} S50: echo:M221 Invalid "
        "extruder, nothing set", set_case(f"M221 T{v.extruders} S50", _nothing,
                                          [f"echo:M221 Invalid extruder {v.extruders}"]),
        cite=cmd["M221"] + "; gcode.cpp GcodeSuite::get_target_extruder_from_command")
    if profile == "full":
        add("M220", "m220-s-other", "M220 S75, another value", set_case("M220 S75", fr(75)))
        add("M221", "m221-t0", "M221 T0 S70: extruder 0's flow", set_case("M221 T0 S70",
                                                                            flow(70)))

    def defaults(w: State) -> None:
        w.values = st.defaults(v)

    add("M502", "m502-defaults", "M502: every setting back to the build's defaults (the "
        "feedrate and flow percentages are not settings)", set_case(
            "M502", defaults, ["echo:Hardcoded Default Settings Loaded"]),
        cite=cmd["M502"] + "; the defaults: spec/tables/settings.toml and the variant's "
        "steps_per_mm, max_feedrate")
    return out


def eeprom_checks(spec: MarlinSpec, vid: str) -> list[MarlinCheck]:
    """M500/M501/M504 (``--allow-eeprom`` on a real unit)."""
    v = spec.variant(vid)
    if not v.on("EEPROM_SETTINGS"):
        return []
    cmd = {k: x.cite for k, x in spec.commands.items()}
    out = []

    def stored(s: Session) -> Outcome:
        got = _only(s.talk(b"M500\n"), s)
        ok = len(got) == 1 and bool(STORED.match(got[0]))
        return ok, "echo:Settings Stored (<n> bytes; crc <n>)", " | ".join(got) or "(nothing)"

    def back(change: str | None, between: bytes = b"") -> Callable[[Session], Outcome]:
        def body(s: Session) -> Outcome:
            s.talk(b"M500\n")
            codes = st.ORDER if change is None else (change,)
            for code in codes:
                s.talk(_line(code, NEW[code]))
            if between:
                s.talk(between)
            got = _only(s.talk(b"M501\n", timeout=4.0), s)
            want_report = st.Settings(v, now=deepcopy(BASE)).report()
            state = read_values(s)
            problems = []
            if not got or not RETRIEVED.match(got[0]):
                problems.append(f"first line {got[0] if got else '(nothing)'}")
            if got[1:] != want_report:
                problems.append("the report after it differs: " + " | ".join(
                    x for x in got[1:] if x not in want_report)[:200])
            for code in st.ORDER:
                if state.get(code) != BASE[code]:
                    problems.append(f"M503 {code} {state.get(code)}")
            return not problems, "echo:V<n> stored settings retrieved (...), the stored " \
                "report, M503 = what M500 stored", "; ".join(problems) or "as expected"
        return body

    def validate(s: Session) -> Outcome:
        s.talk(b"M500\n")
        got = _only(s.talk(b"M504\n"), s)
        return got == ["echo:EEPROM OK"], "echo:EEPROM OK", " | ".join(got) or "(nothing)"

    def add(code: str, name: str, title: str, body: Callable[[Session], Outcome]) -> None:
        out.append(MarlinCheck(f"{vid}/M500-M504.cpp/eeprom/{name}", cmd[code], title,
                               restoring(body, store=True), eeprom=True))

    add("M500", "m500-stored", "M500: Settings Stored (bytes; crc)", stored)
    add("M501", "m501-restores", "M501 after changing every setting: the stored ones back, "
        "reported", back(None))
    add("M501", "m501-after-m502", "M502 does not write the EEPROM: M501 brings the stored "
        "back", back(None, b"M502\n"))
    add("M504", "m504-valid", "M504 after M500: echo:EEPROM OK", validate)
    for code in st.ORDER:
        add("M501", f"m501-{code.lower()}", f"M500, {code} changed, M501: {code} back",
            back(code))
    return out


def _exact(command: str, want: list[str], timeout: float = 2.0
           ) -> Callable[[Session], Outcome]:
    """``command`` prints exactly ``want`` and then ok."""
    def run(s: Session) -> Outcome:
        got = s.talk(f"{command}\n".encode(), timeout=timeout)
        ok = got.lines[:-1] == want and bool(got.lines) and _ok_kind(s, got.lines[-1])
        return ok, " | ".join([*want, "ok"]), got.text()
    return run


def _ok_temps(command: str) -> Callable[[Session], Outcome]:
    def run(s: Session) -> Outcome:
        got = s.talk(f"{command}\n".encode())
        ok = len(got.lines) == 1 and bool(s.spec.messages["ok_temp"].pattern.match(got.lines[0]))
        return ok, "ok T:<t> /<target> B:<t> /<target> @:<p> B@:<p>", got.text()
    return run


def report_checks(spec: MarlinSpec, vid: str, profile: str) -> list[MarlinCheck]:
    v = spec.variant(vid)
    cmd = {k: x.cite for k, x in spec.commands.items()}
    out: list[MarlinCheck] = []
    number = re.compile(r"-?(?:0|[1-9]\d*)\.\d\d")    # as printed: no padding

    def layout(s: Session) -> Outcome:
        got = s.talk(b"M503\n")
        want = [number.sub("#", x) for x in st.Settings(v).report()]
        have = [number.sub("#", x) for x in got.lines[:-1]]
        diff = [x for x in have if x not in want] + [f"missing {x}" for x in want if x not in have]
        return have == want and _ok_kind(s, got.lines[-1]) if got.lines else False, \
            f"{len(want)} lines, headings and words as the firmware prints them, then ok", \
            "; ".join(diff[:4]) or ("order differs" if have != want else got.text()[-60:])

    def replay(s: Session) -> Outcome:
        got = s.talk(b"M503 S0\n")
        want = [number.sub("#", x) for x in st.Settings(v).report(for_replay=True)]
        have = [number.sub("#", x) for x in got.lines[:-1]]
        return have == want, " | ".join(want[:3]) + " ... (no headings, no echo:)", \
            " | ".join(have[:3]) + f" ... ({len(have)} lines)"

    def endstops(s: Session) -> Outcome:
        got = s.talk(b"M119\n")
        body = got.lines[:-1]
        ok = body[:1] == ["Reporting endstop status"] and [x.split(":")[0] for x in body[1:]] \
            == ["x_min", "y_min", "z_min"] and all(x.split(": ")[-1] in ("open", "TRIGGERED")
                                                   for x in body[1:])
        return ok, "Reporting endstop status | x_min: open|TRIGGERED | y_min: .. | z_min: ..", \
            got.text()

    def print_time(s: Session) -> Outcome:
        got = s.talk(b"M31\n")
        # libs/duration_t.h toString: the largest unit first, none that is 0 before it
        ok = len(got.lines) == 2 and bool(re.fullmatch(
            r"echo:Print time: ([1-9]\d*[ydhm] (\d+[dhm] )*)?\d+s", got.lines[0]))
        return ok, "echo:Print time: [<n>h ][<n>m ]<n>s | ok", got.text()

    def timer(restart: bool) -> Callable[[Session], Outcome]:
        def run(s: Session) -> Outcome:
            s.talk(b"M75\n")
            s.talk(b"G4 S1\n" if restart else b"G4 S2\n", timeout=4.0)
            s.talk(b"M77\n")
            if restart:
                s.talk(b"M75\n")
                s.talk(b"G4 S1\n", timeout=4.0)
                s.talk(b"M77\n")
            s.talk(b"G4 S1\n", timeout=4.0)
            got = s.talk(b"M31\n")
            want = "echo:Print time: 1s" if restart else "echo:Print time: 2s"
            return got.lines[:1] == [want], want + (" (M75 after M77 starts again at 0)"
                                                    if restart else " (M77 stopped it)"), \
                got.text()
        return run

    def add(code: str, group: str, name: str, title: str, run: Callable[[Session], Outcome],
            **kw: object) -> None:
        where = _file(cmd[code]) if code in cmd else "gcode.cpp"
        cite = str(kw.pop("cite", "") or cmd[code])
        out.append(MarlinCheck(f"{vid}/{where}/{group}/{name}", cite, title, run,
                               **kw))  # type: ignore[arg-type]

    add("M503", "report", "m503-layout", "M503: every heading and setting line as the "
        "firmware prints them", layout)
    add("M503", "report", "m503-s0", "M503 S0: the setting lines for replay, no headings",
        replay)
    add("M119", "report", "m119", "M119: the endstops configured, open or TRIGGERED",
        endstops)
    add("M31", "report", "m31", "M31: echo:Print time: …s", print_time)
    add("M77", "timer", "m75-m77", "M75 starts the print timer, M77 stops it, M31 reads it",
        timer(False))
    add("M75", "timer", "m75-restarts", "M75 after M77 starts the timer from 0", timer(True))

    def debug(flags: int, names: str) -> Callable[[Session], Outcome]:
        def run(s: Session) -> Outcome:
            try:
                return _exact(f"M111 S{flags}", [f"echo:DEBUG:{names}"])(s)
            finally:
                s.talk(b"M111 S0\n")
        return run

    for flags, names in ((0, "off"), (1, "ECHO"), (2, "INFO"), (4, "ERRORS"), (8, "DRYRUN"),
                         (16, "COMMUNICATION"), (7, "ECHO,INFO,ERRORS")):
        add("M111", "debug", f"m111-s{flags}", f"M111 S{flags}: echo:DEBUG:{names}",
            debug(flags, names))

    def query(s: Session) -> Outcome:
        try:
            s.talk(b"M111 S4\n")
            return _exact("M111", ["echo:DEBUG:ERRORS"])(s)
        finally:
            s.talk(b"M111 S0\n")

    def echo(s: Session) -> Outcome:
        try:
            s.talk(b"M111 S1\n")
            got = s.talk(b"M105\n")
            ok = got.lines[:1] == ["echo:M105"] and len(got.lines) == 2
            return ok, "echo:M105 | ok T:..", got.text()
        finally:
            s.talk(b"M111 S0\n")

    add("M111", "debug", "m111-query", "M111 without S: the flags set before, unchanged", query)
    add("M111", "debug", "m111-echo", "M111 S1: every command echoed before it runs", echo)

    for n in range(8):
        want = [] if n < v.extruders else [f"echo:T{n} Invalid extruder"]
        add("T0", "tool", f"t{n}", f"T{n}: " + ("ok" if not want else want[0]),
            _exact(f"T{n}", want))
    add("M117", "message", "m117", "M117 <text>: to the display, only ok on the serial",
        _exact("M117 hello there", []))
    for name, args, want in (("plain", "hello", "hello"), ("e1", "E1 hello", "echo:hello"),
                             ("a1", "A1 hello", "//hello"), ("p0", "P0 hello", "hello"),
                             ("e1-a1", "E1 A1 hello", "echo://hello")) + (
            (("e0-kept", "E0 hello", "E0 hello"), ("three", "A1 E1 P0 x y", "echo://x y"))
            if profile == "full" else ()):
        add("M118", "message", f"m118-{name}", f"M118 {args}: {want}",
            _exact(f"M118 {args}", [want]))
    add("G21", "units", "g21", "G21 (mm): a plain ok", _exact("G21", []))
    for text in ("M106 S0", "M107"):
        add(text.split()[0], "reply", f"{text.split()[0].lower()}-ok", f"{text}: the fan, a "
            "plain ok", _exact(text, []))
    for text in ("M17", "M18", "M84"):
        add(text, "reply", f"{text.lower()}-ok", f"{text}: the steppers on / off, a plain ok",
            _exact(text, []), motion=True)
    unknown = ["G20", "M149 C", "M149 F", "G999", "X10"] + (["M9999 S1 P2", "G29"]
                                                           if profile == "full" else [])
    for text in unknown:
        add("", "reply", "unknown-" + text.lower().replace(" ", "-"), f"{text}: not in this "
            "build, Unknown command", _exact(text, [f'echo:Unknown command: "{text}"']),
            cite="gcode.cpp GcodeSuite::process_parsed_command default: unknown_command_warning"
            " (G20 needs INCH_MODE_SUPPORT, M149 TEMPERATURE_UNITS_SUPPORT, G29 bed levelling;"
            " a line without G/M/T is unknown too)")
    for text, name in (("M105 ; a comment", "comment"), ("M105;comment", "comment-tight"),
                       ("M105 X", "stray-word")):
        add("M105", "reply", f"m105-{name}", f"{text!r}: the temperatures", _ok_temps(text),
            cite=cmd["M105"] + "; queue.cpp process_stream_char (';' ends the command)")
    return out


def _timed(s: Session, command: str, timeout: float = 10.0) -> float:
    """Seconds from sending ``command`` and M400 to M400's ok."""
    s.talk(f"{command}\n".encode())
    got = s.talk(b"M400\n", timeout=timeout)
    return got.t - got.t0


def motion_checks(spec: MarlinSpec, vid: str) -> list[MarlinCheck]:
    cmd = {k: x.cite for k, x in spec.commands.items()}
    out: list[MarlinCheck] = []

    def moves(setup: list[str], want: str, title: str, name: str, cite: str,
              cold_lines: int = 0) -> None:
        def run(s: Session) -> Outcome:
            try:
                s.talk(b"G92 X0 Y0 Z0 E0\n")
                printed: list[str] = []
                for line in setup:
                    printed += _only(s.talk(f"{line}\n".encode(), timeout=10.0), s)
                s.talk(b"M400\n", timeout=10.0)
                got = s.talk(b"M114\n")
                pos = next((x for x in got.lines if _POS.match(x)), "")
                cold = [x for x in printed if x == "echo: cold extrusion prevented"]
                other = [x for x in printed if x not in cold]
                ok = pos.startswith(want) and len(cold) == cold_lines and not other
                return ok, f"{want} ...; {cold_lines} x 'echo: cold extrusion prevented'", \
                    f"{pos or got.text()}; printed {' | '.join(printed) or 'nothing'}"
            finally:
                s.talk(b"G90\n")
                s.talk(b"M82\n")
        out.append(MarlinCheck(f"{vid}/{name}", cite, title, run, motion=True))

    g91, m82 = cmd["G91"], cmd["M82"]
    moves(["G91", "G1 X2 Y3 F3000", "G1 X2 Y3"], "X:4.00 Y:6.00 Z:0.00",
          "G91: X and Y moves add up", "gcode.cpp/modes/g91-relative", g91)
    moves(["G91", "G90", "G1 X2 Y3 F3000", "G1 X2 Y3"], "X:2.00 Y:3.00 Z:0.00",
          "G90 after G91: absolute again", "gcode.cpp/modes/g90-absolute", cmd["G90"])
    moves(["G91", "G1 E1 F3000", "G1 E1"], "X:0.00 Y:0.00 Z:0.00 E:2.00",
          "G91 makes E relative too (a cold hotend: nothing extruded, the position counts)",
          "gcode.cpp/modes/g91-e-relative", g91 + "; planner.cpp PREVENT_COLD_EXTRUSION",
          cold_lines=2)
    moves(["M83", "G1 X1 E1 F3000", "G1 X1 E1"], "X:1.00 Y:0.00 Z:0.00 E:2.00",
          "M83: E relative, X still absolute", "gcode.cpp/modes/m83-e-relative", cmd["M83"],
          cold_lines=2)
    moves(["M83", "M82", "G1 E1 F3000", "G1 E1"], "X:0.00 Y:0.00 Z:0.00 E:1.00",
          "M82 after M83: E absolute again", "gcode.cpp/modes/m82-e-absolute", m82,
          cold_lines=1)
    moves(["M83", "G90", "G1 E1 F3000", "G1 E1"], "X:0.00 Y:0.00 Z:0.00 E:1.00",
          "G90 clears M83 as well (set_relative_mode)", "gcode.cpp/modes/g90-clears-m83",
          cmd["G90"] + "; motion.h set_relative_mode", cold_lines=1)
    moves(["G0 X3 Y4 F3000"], "X:3.00 Y:4.00 Z:0.00", "G0 moves like G1",
          "G0_G1.cpp/motion/g0", cmd["G0"])
    if spec.command("G2", spec.variant(vid)) is not None:
        moves(["G1 X10 Y10 F3000", "G2 X20 Y10 I5 J0"], "X:20.00 Y:10.00 Z:0.00",
              "G2: a clockwise arc ends at its X Y", "G2_G3.cpp/motion/g2", cmd["G2"])
        moves(["G1 X10 Y10 F3000", "G3 X10 Y20 I0 J5"], "X:10.00 Y:20.00 Z:0.00",
              "G3: a counter-clockwise arc ends at its X Y", "G2_G3.cpp/motion/g3", cmd["G3"])
    moves(["G92 X7 Y8"], "X:7.00 Y:8.00 Z:0.00 E:0.00",
          "G92 sets the position", "G92.cpp/motion/g92", cmd["G92"])

    def with_settings(setup: list[str], after: list[str], check: Callable[[str], bool],
                      want: str) -> Callable[[Session], Outcome]:
        def body(s: Session) -> Outcome:
            put(s, State(st.defaults(s.v), "FR:100%", "echo:E0 Flow: 100%"))
            s.talk(b"G28\n", timeout=30.0)
            for line in setup:
                s.talk(f"{line}\n".encode(), timeout=10.0)
            s.talk(b"M400\n", timeout=10.0)
            for line in after:
                s.talk(f"{line}\n".encode(), timeout=10.0)
            got = s.talk(b"M114\n")
            pos = next((x for x in got.lines if _POS.match(x)), got.text())
            return check(pos), want, pos
        return restoring(body)

    out.append(MarlinCheck(f"{vid}/M92.cpp/motion/m92-x-count", cmd["M92"] + "; " +
                           cmd["M114"], "M92 X160: a move of 1 mm is 160 steps on X, Y keeps 80",
                           with_settings(["M92 X160", "G1 X1 Y1 F3000"], [],
                                         lambda p: p.endswith("Count X:160 Y:80 Z:0"),
                                         "... Count X:160 Y:80 Z:0"), motion=True))
    out.append(MarlinCheck(f"{vid}/M92.cpp/motion/m92-y-count", cmd["M92"] + "; " +
                           cmd["M114"], "M92 Y40: a move of 1 mm is 40 steps on Y, X keeps 80",
                           with_settings(["M92 Y40", "G1 X1 Y1 F3000"], [],
                                         lambda p: p.endswith("Count X:80 Y:40 Z:0"),
                                         "... Count X:80 Y:40 Z:0"), motion=True))
    out.append(MarlinCheck(f"{vid}/M206_M428.cpp/motion/m206-logical", cmd["M206"],
                           "M206 X5: G1 X10 goes to logical 10, native 5 (Count 400)",
                           with_settings(["M206 X5", "G1 X10 F3000"], [],
                                         lambda p: p.startswith("X:10.00 ") and
                                         "Count X:400 " in p, "X:10.00 ... Count X:400 ..."),
                           motion=True))

    def speed(setup: list[str], lo: float, hi: float, title: str, name: str, cite: str) -> None:
        def body(s: Session) -> Outcome:
            put(s, State(st.defaults(s.v), "FR:100%", "echo:E0 Flow: 100%"))
            s.talk(b"G92 X0 Y0 Z0\n")
            for line in setup:
                s.talk(f"{line}\n".encode())
            took = _timed(s, "G1 X10 F600")
            s.talk(b"G1 X0 F3000\n")
            s.talk(b"M400\n", timeout=10.0)
            return lo <= took <= hi, f"G1 X10 F600 done in {lo:.2f} .. {hi:.2f} s", \
                f"{took:.2f} s"
        out.append(MarlinCheck(f"{vid}/{name}", cite, title, restoring(body), motion=True))

    speed([], 0.95, 1.5, "G1 X10 F600: 1 s (and the ramps)", "G0_G1.cpp/motion/feedrate",
          cmd["G1"])
    speed(["M220 S200"], 0.45, 0.8, "M220 S200: the move takes half the time",
          "M220.cpp/motion/m220-speeds-up", cmd["M220"] + "; motion.h MMS_SCALED")
    speed(["M221 S50"], 0.95, 1.5, "M221 S50: the flow, not the speed of an X move",
          "M221.cpp/motion/m221-not-speed", cmd["M221"])
    speed(["M203 X5"], 1.95, 2.6, "M203 X5: X at 5 mm/s at most (2 s)",
          "M200-M205.cpp/motion/m203-limits", cmd["M203"] + "; planner.cpp _populate_block")
    speed(["M203 Y5"], 0.95, 1.5, "M203 Y5: an X move keeps its speed",
          "M200-M205.cpp/motion/m203-y-not-x", cmd["M203"])

    def home(s: Session) -> Outcome:
        got = s.talk(b"G28\n", timeout=30.0)
        pos = next((x for x in s.talk(b"M114\n").lines if _POS.match(x)), "")
        want = "X:1.50 Y:2.50 Z:3.50"
        return pos.startswith(want) and s.oks(got.lines) == 1, \
            f"{want} (home is where the M206 offset says)", pos or got.text()
    out.append(MarlinCheck(f"{vid}/G28.cpp/motion/g28-m206", cmd["G28"] + "; " + cmd["M206"],
                           "G28 with an M206 offset: M114 shows the offset", restoring(home),
                           motion=True))
    return out


def dwell_checks(spec: MarlinSpec, vid: str) -> list[MarlinCheck]:
    cite = spec.commands["G4"].cite + "; G4.cpp: P ms, S s, S wins when both are given"
    out = []
    for text, lo, hi, name in (("G4 P500", 0.45, 0.9, "g4-p"), ("G4 S1", 0.95, 1.5, "g4-s"),
                               ("G4 P2000 S1", 0.95, 1.6, "g4-s-wins"),
                               ("G4 P0", 0.0, 0.4, "g4-zero")):
        def run(s: Session, text: str = text, lo: float = lo, hi: float = hi) -> Outcome:
            got = s.talk(f"{text}\n".encode(), timeout=5.0)
            took = got.t - got.t0 if got.lines else 99.0
            if got.lines and got.times:
                took = next((t for t, x in zip(got.times, got.lines, strict=True)
                             if _ok_kind(s, x)), got.t) - got.t0
            return lo <= took <= hi and s.oks(got.lines) == 1, \
                f"ok after {lo:.2f} .. {hi:.2f} s", f"{took:.2f} s: {got.text()[-40:]}"
        out.append(MarlinCheck(f"{vid}/G4.cpp/dwell/{name}", cite, f"{text}: ok after "
                               f"{lo:g} .. {hi:g} s", run))
    return out


def heat_checks(spec: MarlinSpec, vid: str) -> list[MarlinCheck]:
    cmd = {k: x.cite for k, x in spec.commands.items()}
    temps = re.compile(r"T:[\d.]+ /([\d.]+) B:[\d.]+ /([\d.]+)")

    def target(command: str, want: tuple[str, str]) -> Callable[[Session], Outcome]:
        def run(s: Session) -> Outcome:
            try:
                s.talk(f"{command}\n".encode())
                got = s.talk(b"M105\n")
                m = temps.search(got.lines[0]) if got.lines else None
                have = (m.group(1), m.group(2)) if m else None
                return have == want, f"targets hotend /{want[0]} bed /{want[1]}", got.text()
            finally:
                s.talk(b"M104 S0\n")
                s.talk(b"M140 S0\n")
        return run

    return [MarlinCheck(f"{vid}/M104_M109.cpp/heat/m104-target", cmd["M104"],
                        "M104 S35: the hotend's target, not the bed's",
                        target("M104 S35", ("35.00", "0.00")), heat=True),
            MarlinCheck(f"{vid}/M140_M190.cpp/heat/m140-target", cmd["M140"],
                        "M140 S35: the bed's target, not the hotend's",
                        target("M140 S35", ("0.00", "35.00")), heat=True),
            MarlinCheck(f"{vid}/M104_M109.cpp/heat/m104-off", cmd["M104"],
                        "M104 S0 after S35: the target back to 0",
                        target("M104 S35\nM104 S0", ("0.00", "0.00")), heat=True)]


_FILAMENT = re.compile(r"^echo:; Filament settings(?: \(Disabled\):)?$")
_M200 = re.compile(r"^echo:  M200 S([01]) D(-?[\d.]+)$")


def _filament(s: Session) -> tuple[list[str], str]:
    """M503's filament group (heading and line) and the M200 line that sets it again."""
    got = s.talk(b"M503\n")
    group = [x for x in got.lines if _FILAMENT.match(x) or _M200.match(x)]
    m = next((_M200.match(x) for x in group if _M200.match(x)), None)
    return group, (f"M200 S{m.group(1)} D{m.group(2)}" if m else "M200 S0 D1.75")


def _filament_want(on: bool, dia: float) -> list[str]:
    return ["echo:; Filament settings" + ("" if on else " (Disabled):"),
            f"echo:  M200 S{int(on)} D{st.number(dia)}"]


def m200_case(command: str, on: bool, dia: float, printed: list[str] | None = None
              ) -> Callable[[Session], Outcome]:
    """From ``M200 S0 D1.60`` (off, a diameter unlike the default) and the BASE settings,
    ``command``: M503's filament heading and line are then ``on``/``dia``, every other
    setting as it was (a unit that writes another setting, or resets the rest, fails)."""
    def body(s: Session) -> Outcome:
        _, before = _filament(s)
        try:
            s.talk(b"M200 S0 D1.60\n")
            got = _only(s.talk(f"{command}\n".encode()), s)
            group, _ = _filament(s)
            ok, expected, actual = _compare(base_state(), read_state(s), printed or [], got)
            want = _filament_want(on, dia)
            if group != want:
                ok, actual = False, f"M503 {' | '.join(group) or 'no filament group'}; {actual}"
            return ok, f"{' | '.join(want)}; {expected}", actual
        finally:
            s.talk(f"{before}\n".encode())
    return restoring(body)


def _state_line(command: str, read: bytes, want: Callable[[Session], list[str]],
                restore: Callable[[list[str]], bytes], *, before: bytes = b""
                ) -> Callable[[Session], Outcome]:
    """``command`` prints nothing but its ok; ``read`` then prints ``want``; ``restore``
    (given what ``read`` printed before) puts the unit back."""
    def run(s: Session) -> Outcome:
        was = _only(s.talk(read), s)
        try:
            if before:
                s.talk(before)
            printed = _only(s.talk(f"{command}\n".encode()), s)
            got = _only(s.talk(read), s)
            wanted = want(s)
            ok = printed == [] and got == wanted
            return ok, f"{command}: ok alone; then {read.decode().strip()}: " + \
                " | ".join(wanted), f"{' | '.join(printed) or 'ok alone'}; then " + \
                (" | ".join(got) or "nothing")
        finally:
            s.talk(restore(was))
    return run


def _m302_restore(was: list[str]) -> bytes:
    m = re.match(r"echo:Cold extrudes are (en|dis)abled \(min temp (-?\d+)C\)", was[0]) \
        if was else None
    if not m:
        return b"M302 S170 P0\n"
    return f"M302 S{m.group(2)} P{int(m.group(1) == 'en')}\n".encode()


def _m113_restore(was: list[str]) -> bytes:
    m = re.match(r"echo:M113 S(\d+)$", was[0]) if was else None
    return f"M113 S{m.group(1) if m else 2}\n".encode()


def _m211_restore(was: list[str]) -> bytes:
    return b"M211 S0\n" if was and was[0].startswith("  M211 S0") else b"M211 S1\n"


def command_checks(spec: MarlinSpec, vid: str) -> list[MarlinCheck]:
    """The commands of the linux_native build a host may send besides the settings above:
    M85, M113, M120/M121, M200, M211, M302, M303, M428, M575, M999 (gcode.cpp
    process_parsed_command compiles each of them in this configuration)."""
    v = spec.variant(vid)
    cmd = {k: x.cite for k, x in spec.commands.items()}
    out: list[MarlinCheck] = []

    def add(code: str, group: str, name: str, title: str, run: Callable[[Session], Outcome],
            **kw: object) -> None:
        if spec.command(code, v) is None:
            return
        cite = str(kw.pop("cite", "") or cmd[code])
        out.append(MarlinCheck(f"{vid}/{_file(cmd[code])}/{group}/{name}", cite, title, run,
                               **kw))  # type: ignore[arg-type]

    # M113: the keepalive interval, read back and seen in a dwell's busy: lines
    add("M113", "keepalive", "m113-report", f"M113: echo:M113 S{v.keepalive} (the interval "
        "in force)", _exact("M113", [f"echo:M113 S{v.keepalive}"]))

    def busy_every(s: Session) -> Outcome:
        was = _only(s.talk(b"M113\n"), s)
        try:
            s.talk(b"M113 S1\n")
            got = s.talk(b"G4 P2500\n", timeout=5.0)
            busy = [round(t - got.t0, 1) for t, x in zip(got.times, got.lines, strict=True)
                    if x == "echo:busy: processing"]
            now = _only(s.talk(b"M113\n"), s)
            ok = len(busy) == 2 and now == ["echo:M113 S1"]
            return ok, "G4 P2500 after M113 S1: busy: processing twice (1 s apart, not " \
                "the 2 s default); M113 then echo:M113 S1", f"busy: at {busy} s; M113: " + \
                " | ".join(now)
        finally:
            s.talk(_m113_restore(was))
    add("M113", "keepalive", "m113-interval", "M113 S1: busy: every second during a dwell, "
        "and M113 reads it back", busy_every)
    add("M113", "keepalive", "m113-at-most-60", "M113 S99: the interval is held at 60 s "
        "(NOMORE)", _state_line("M113 S99", b"M113\n", lambda s: ["echo:M113 S60"],
                                _m113_restore))

    # M85, M120, M121: known, no output
    add("M85", "reply", "m85-s0", "M85 S0 (no inactivity timeout): a plain ok, not Unknown "
        "command", _exact("M85 S0", []))
    add("M120", "reply", "m120-ok", "M120 (endstops on): a plain ok", _exact("M120", []))

    def endstops_off_on(s: Session) -> Outcome:
        try:
            got = s.talk(b"M121\n")
            ok = len(got.lines) == 1 and _ok_kind(s, got.lines[0])
            return ok, "M121: ok alone (M120 after it)", got.text()
        finally:
            s.talk(b"M120\n")
    add("M121", "reply", "m121-ok", "M121 (endstops off outside homing): a plain ok; M120 "
        "turns them back on", endstops_off_on)

    # M200: the volumetric switch and the filament diameter, read back in M503
    add("M200", "settings", "m200-report", "M200 alone: its line (no heading), nothing changed",
        m200_case("M200", False, 1.6, ["  M200 S0 D1.60"]))
    add("M200", "settings", "m200-d", "M200 D2.85: the diameter, and volumetric on (the "
        "heading loses '(Disabled)')", m200_case("M200 D2.85", True, 2.85))
    add("M200", "settings", "m200-s1", "M200 S1: volumetric on, the diameter kept",
        m200_case("M200 S1", True, 1.6))
    add("M200", "settings", "m200-d0", "M200 S1 D0: D0 turns it off whatever S says",
        m200_case("M200 S1 D0", False, 1.6))
    add("M200", "settings", "m200-s0-d", "M200 S0 D3: the diameter set, volumetric off",
        m200_case("M200 S0 D3", False, 3.0))
    add("M200", "settings", f"m200-t{v.extruders}", f"M200 T{v.extruders} D2: echo:M200 "
        "Invalid extruder, nothing set", m200_case(f"M200 T{v.extruders} D2", False, 1.6,
                                                   [f"echo:M200 Invalid extruder {v.extruders}"]),
        cite=cmd["M200"] + "; gcode.cpp GcodeSuite::get_target_extruder_from_command")

    def m502_filament(s: Session) -> Outcome:
        _, before = _filament(s)
        try:
            s.talk(b"M200 S1 D2.5\n")
            s.talk(b"M502\n")
            group, _ = _filament(s)
            want = _filament_want(False, 1.75)
            return group == want, " | ".join(want), " | ".join(group) or "no filament group"
        finally:
            s.talk(f"{before}\n".encode())
    add("M502", "settings", "m502-m200", "M502 puts M200 back: off, D1.75 "
        "(DEFAULT_NOMINAL_FILAMENT_DIA)", restoring(m502_filament),
        cite=cmd["M502"] + "; settings.cpp reset: volumetric_enabled, filament_size")

    # M211: software endstops, the bounds shown in logical coordinates
    def bounds(s: Session) -> list[str]:
        off = BASE["M206"]
        lo = " ".join(f"{a}{st.number(x + off[i])}" for i, (a, x) in enumerate(
            zip("XYZ", st.SOFT_MIN, strict=True)))
        hi = " ".join(f"{a}{st.number(x + off[i])}" for i, (a, x) in enumerate(
            zip("XYZ", st.SOFT_MAX, strict=True)))
        return [f"  Min:  {lo}   Max:  {hi}"]

    def m211_report(s: Session) -> Outcome:
        got = _only(s.talk(b"M211\n"), s)
        want = ["  M211 S1 ; ON", *bounds(s)]
        return got == want, " | ".join(want) + " (the M206 offset of the BASE settings added)", \
            " | ".join(got) or "ok alone"
    add("M211", "settings", "m211-report", "M211: on, and the bounds moved by the M206 offset "
        "(asLogical)", restoring(m211_report))
    add("M211", "settings", "m211-s0", "M211 S0: ok alone, then M211 reports OFF, the bounds "
        "unchanged", restoring(_state_line("M211 S0", b"M211\n",
                                           lambda s: ["  M211 S0 ; OFF", *bounds(s)],
                                           _m211_restore, before=b"M211 S1\n")))

    # M302: cold extrusion
    add("M302", "settings", "m302-report", "M302: echo:Cold extrudes are disabled (min temp "
        f"{st.EXTRUDE_MINTEMP}C)", _exact("M302", [f"echo:Cold extrudes are disabled (min temp "
                                                  f"{st.EXTRUDE_MINTEMP}C)"]))
    for command, state, low in (("M302 P1", "en", 170), ("M302 S0", "en", 0),
                                ("M302 S180", "dis", 180), ("M302 S180 P1", "en", 180)):
        add("M302", "settings", command.lower().replace(" ", "-"), f"{command}: cold extrusion "
            f"{state}abled, the minimum {low}C", _state_line(
                command, b"M302\n", lambda s, e=state, n=low: [
                    f"echo:Cold extrudes are {e}abled (min temp {n}C)"], _m302_restore,
                before=b"M302 S170 P0\n"))

    def cold(s: Session) -> Outcome:
        was = _only(s.talk(b"M302\n"), s)
        try:
            s.talk(b"M302 S170 P0\nG92 E0\nM82\n", timeout=4.0)
            s.talk(b"M302 P1\n")
            printed = _only(s.talk(b"G1 E1 F600\n"), s)
            s.talk(b"M400\n", timeout=10.0)
            pos = next((x for x in s.talk(b"M114\n").lines if _POS.match(x)), "")
            ok = printed == [] and " E:1.00 " in pos
            return ok, "no 'cold extrusion prevented'; E:1.00", \
                f"{' | '.join(printed) or 'nothing printed'}; {pos}"
        finally:
            s.talk(_m302_restore(was))
            s.talk(b"G92 E0\n")
    add("M302", "motion", "m302-p1-extrudes", "M302 P1: G1 E1 with a cold hotend extrudes "
        "(no 'cold extrusion prevented'; on a printer: 1 mm of filament into a cold nozzle)", cold,
        motion=True,
        cite=cmd["M302"] + "; planner.cpp _populate_block")

    # M303: only the error form (a valid one heats for minutes)
    add("M303", "heat", "m303-bad-heater", "M303 E5: PID Autotune failed! Bad heater id "
        "(nothing heats)", _exact("M303 E5", ["PID Autotune failed! Bad heater id"]))

    # M428: the home offsets from where the axes are (after homing)
    def m428(target: str, want_printed: Callable[[], list[str]],
             offset: list[float]) -> Callable[[Session], Outcome]:
        def body(s: Session) -> Outcome:
            s.talk(b"G28\n", timeout=30.0)
            s.talk(f"G1 {target} F3000\n".encode(), timeout=10.0)
            s.talk(b"M400\n", timeout=10.0)
            got = _only(s.talk(b"M428\n"), s)
            want = base_state()
            want.values["M206"] = list(offset)
            printed = [x.split(" Count")[0] for x in got]
            return _compare(want, read_state(s), want_printed(), printed)
        return restoring(body)
    # from BASE (M206 1.5 2.5 3.5): G1 to logical 6.5 8.5 5.5 is native 5 6 2
    add("M428", "motion", "m428-offsets", "M428 at native X5 Y6 Z2: the offsets -5 -6 -2, "
        "the position then 0 0 0; nothing else changed", m428(
            "X6.5 Y8.5 Z5.5", lambda: ["X:0.00 Y:0.00 Z:0.00 E:0.00"], [-5.0, -6.0, -2.0]),
        motion=True)
    add("M428", "motion", "m428-too-far", "M428 at native X30: Error:Too far from reference "
        "point, no offset changed", m428("X31.5 Y2.5 Z3.5", lambda: [
            "Error:Too far from reference point"], list(BASE["M206"])), motion=True)

    # M575: only the forms that leave the link as it is
    add("M575", "reply", "m575-implausible", "M575 B1234: echo:?(B)aud rate implausible.",
        _exact("M575 B1234", ["echo:?(B)aud rate implausible."]))
    add("M575", "reply", "m575-no-b", "M575 without B: echo:?(B)aud rate implausible.",
        _exact("M575", ["echo:?(B)aud rate implausible."]))

    # M999: a resend of the next line, its own ok after
    def m999(s: Session) -> Outcome:
        s.talk(b"M110 N41\n")
        got = s.talk(b"M999\n", answers=2)
        want = ["Resend: 42", "ok"]
        ok = got.lines[:2] == want and len(got.lines) == 3 and _ok_kind(s, got.lines[2])
        return ok, "Resend: 42 | ok | ok (M110 N41 before it)", got.text()
    add("M999", "line", "m999-resend", "M999: Resend: last+1 and ok (flush_and_request_resend), "
        "then its own ok", m999)
    add("M999", "line", "m999-s1", "M999 S1: ok alone (no resend)", _exact("M999 S1", []))
    return out


def generate(spec: MarlinSpec, vid: str, profile: str = "quick") -> list[MarlinCheck]:
    """Every depth check of ``vid`` (``profile`` ``full``: more values per setting)."""
    return (settings_checks(spec, vid, profile) + eeprom_checks(spec, vid) +
            report_checks(spec, vid, profile) + dwell_checks(spec, vid) +
            motion_checks(spec, vid) + heat_checks(spec, vid) + command_checks(spec, vid))
