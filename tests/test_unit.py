"""The reference unit model (conform.families.gve.unit): golden examples, state machine, open questions."""

from __future__ import annotations

import pytest

from conform.families.gve.protocol import append_checksum
from conform.families.gve.unit import Unit, run_until_idle
from conform.families.gve.unit.given import drive_given

VARIANTS = ["gve64-v10", "gve64-v19", "gve64-phantom", "gve124"]


def make(spec, vid="gve64-v19", **choices):
    return Unit(spec.variant(vid), spec.dialect(choices))


def ex(unit, line, t):
    """Exchange a line given without its CR; return the answer without its final CR."""
    t2, ans = unit.exchange(line.encode() + b"\r", t)
    return t2, ans.decode()[:-1] if ans else ""


def ans(unit, line, t=None):
    return ex(unit, line, unit.now if t is None else t)[1]


def cs(line: str) -> str:
    return append_checksum(line.encode()).decode()


# ---------------------------------------------------------------- manual examples (§13.3, §13.7)

@pytest.mark.parametrize("vid", VARIANTS)
def test_manual_examples(spec, vid):
    for example in spec.examples:
        if example.kind == "checksum":
            continue
        unit = Unit(spec.variant(vid))
        t = drive_given(unit, example.given, 0.0)
        got = []
        for line in example.send:
            t, a = unit.exchange(line.encode() + b"\r", t)
            if a:
                got.extend(a.decode().split("\r")[:-1])
        assert got == list(example.expect), example.id


def test_checksum_example_line_is_accepted(spec):
    unit = make(spec)
    assert ans(unit, "!0%+") == "0,5C"
    assert ans(unit, "!0A100,4F") == "0,5C"
    assert unit.modal["A"] == 100


def test_wrong_and_missing_checksum(spec):
    unit = make(spec)
    ans(unit, "!0%+")
    assert ans(unit, "!0A100,4E") == "4,60"  # "4," sums to 0x60
    assert ans(unit, "!0A100") == "4,60"
    assert unit.modal["A"] == 20
    unit = make(spec, A11="watchdog-2")
    ans(unit, "!0%+")
    assert ans(unit, "!0A100,4E") == "2,5E"
    unit = make(spec, A11="lenient")
    ans(unit, "!0%+")
    assert ans(unit, "!0A100") == "0,5C"
    assert ans(unit, "!0A100,4E") == "4,60"


def test_checksum_off_answers_have_none(spec):
    unit = make(spec)
    assert ans(unit, "!0A100,4F") == "4"  # a checksum while off is a syntax error


# ---------------------------------------------------------------- packets (§13.3.3, A12)

def packet(unit, lines, t=0.0, with_sum=True):
    out = ""
    for line in lines:
        t, a = ex(unit, cs(line) if with_sum else line, t)
        out += a
    return out


def test_packet_without_checksums(spec):
    unit = make(spec)
    assert packet(unit, ["!0*S", "!0B500", "!0C10,0,0", "!0C10,0,0", "!0*E3"], with_sum=False) \
        == "0,3"
    assert unit.queue_len >= 1 and unit.modal["B"] == 500


def test_packet_count_mismatch_and_foreign_command(spec):
    unit = make(spec)
    assert packet(unit, ["!0*S", "!0C10,0,0", "!0*E2"], with_sum=False) == "4,1"
    unit = make(spec)
    assert packet(unit, ["!0*S", "!0C10,0,0", "!0V100", "!0C10,0,0", "!0*E3"],
                  with_sum=False) == "4,1"
    assert unit.modal["V"] == 1000 and unit.queue_len == 1
    unit = make(spec, A12="skip-bad")
    assert packet(unit, ["!0*S", "!0C10,0,0", "!0V100", "!0C10,0,0", "!0*E3"],
                  with_sum=False) == "4,2"
    unit = make(spec, A12="accept-any")
    assert packet(unit, ["!0*S", "!0C10,0,0", "!0V100", "!0C10,0,0", "!0*E3"],
                  with_sum=False) == "0,3"
    assert unit.modal["V"] == 100


def test_packet_queue_fills(spec):
    unit = make(spec, "gve124")
    ans(unit, "!0V10")
    lines = ["!0*S"] + ["!0C100,0,0"] * 130 + ["!0*E130"]
    assert packet(unit, lines, with_sum=False) == "1,128"
    assert unit.queue_len == 128


def test_end_without_start(spec):
    assert ans(make(spec), "!0*E0") == "4"


# ---------------------------------------------------------------- vectors, queue (§13.5.2, A4, A5)

@pytest.mark.parametrize("vid", VARIANTS)
def test_queue_full_at_capacity_and_flag(spec, vid):
    unit = make(spec, vid)
    cap = spec.variant(vid).queue
    ans(unit, "!0V10")
    accepted = 0
    while ans(unit, "!0C100,0,0") == "0":
        accepted += 1
        assert accepted <= cap
    assert accepted == cap
    assert int(ans(unit, "!0F").split(",")[1], 16) & 0x20
    # one vector ends: room for exactly one more
    t = unit.next_deadline()
    unit.poll(t)
    assert not int(ans(unit, "!0F", t).split(",")[1], 16) & 0x20
    assert ans(unit, "!0C100,0,0", t) == "0"
    assert ans(unit, "!0C100,0,0", t) == "1"


def test_queue_excludes_running(spec):
    unit = make(spec, "gve124", A5="excludes-running")
    ans(unit, "!0V10")
    n = 0
    while ans(unit, "!0C100,0,0") == "0":
        n += 1
    assert n == 129


def test_end_of_queue_trick(spec):
    unit = make(spec)
    ans(unit, "!0V5000")
    total = [0, 0, 0, 0]
    for i in range(20):
        v = (300 + i, 100 - i, i % 3, 0)
        assert ans(unit, "!0C%d,%d,%d" % v[:3]) == "0"
        total = [a + b for a, b in zip(total, v, strict=True)]
    t = unit.now
    answers = []
    while True:
        t += 0.01
        a = ans(unit, "!0L0,0,0", t)
        answers.append(a)
        if a == "0":
            break
    assert answers[0] == "1" and answers[-1] == "0"
    assert list(unit.position) == total
    assert ans(unit, "!0P4") == "0,%d,%d,%d,%d" % tuple(total)


def test_l_waits_c_follows(spec):
    unit = make(spec)
    assert ans(unit, "!0L1000,0,0") == "0"
    assert ans(unit, "!0L1000,0,0") == "1"  # A4 idle-only
    assert ans(unit, "!0C10,0,0") == "0"  # C may follow L
    unit = make(spec, A4="queued")
    assert ans(unit, "!0L1000,0,0") == "0"
    assert ans(unit, "!0L1000,0,0") == "0"
    t = run_until_idle(unit, unit.now)
    assert unit.position[0] == 2000 and t > 2.0


def test_vector_syntax_and_range(spec):
    unit = make(spec)
    assert ans(unit, "!0L1,2") == "4"  # fewer than 3 fields
    assert ans(unit, "!0L1,2,3,4,5") == "4"
    assert ans(unit, "!0C2147483648,0,0") == "5"
    assert ans(unit, "!0C+1,0,0") == "4"
    assert ans(make(spec, A22="lenient"), "!0C+1,,0") == "0"
    assert ans(make(spec, "gve124"), "!0C1,2,3,4") == "4"


def test_position_interpolates_while_moving(spec):
    unit = make(spec)
    ans(unit, "!0L10000,5000,0", 0.0)
    xs = []
    for k in range(1, 12):
        x, y = map(int, ans(unit, "!0P", k * 1.0).split(",")[1:])
        xs.append(x)
        assert 0 <= y <= x // 2 + 1
    assert xs == sorted(xs) and xs[0] > 0 and xs[-1] == 10000


# ---------------------------------------------------------------- halt, keep, restore, go (§13.5.9)

def test_halt_keep_lift_restore_go(spec):
    unit = make(spec, "gve64-v19")
    ans(unit, "!0V2000")
    job = [(400 + 3 * i, 200 - 5 * i, 0) for i in range(40)]
    for v in job:
        assert ans(unit, "!0C%d,%d,%d" % v) == "0"
    total = [sum(c) for c in zip(*job, strict=True)]
    t = 1.0
    t, a = ex(unit, "!0H", t)
    assert a == "8" and t > 1.0  # answers after the braking ramp
    x, y = map(int, ans(unit, "!0P").split(",")[1:])
    assert 0 < x < total[0]
    assert ans(unit, "!0SR4") == "8,00" and ans(unit, "!0SR5") == "8,00"
    assert ans(unit, "!0SR6") == "8,D0"  # INTA, RUN, INTCOM
    assert ans(unit, "!0SW0,1A") == "8" and ans(unit, "!0SW1,3F") == "8"
    assert ans(unit, "!0K") == "0"  # ST4..ST6 cleared
    assert ans(unit, "!0SR6") == "0,00"
    assert ans(unit, "!0C1,0,0") == "1"  # only L after K
    assert ans(unit, "!0L0,0,-1000") == "0"
    assert ans(unit, "!0R") == "7"  # not while the lift runs
    t = unit.now
    a = "1"
    while a != "0":  # the slot frees when the lift ends
        t += 0.05
        a = ans(unit, "!0L0,0,1000", t)
    t = run_until_idle(unit, t)
    assert ans(unit, "!0R", t) == "8"  # restored: INTA again
    assert ans(unit, "!0SR6") == "8,D0"
    assert ans(unit, "!0V500") == "8" and ans(unit, "!0XA") == "8"
    assert ans(unit, "!0SW0,A2") == "8" and ans(unit, "!0SW1,78") == "8"
    assert ans(unit, "!0G") == "0"
    assert ans(unit, "!0SR6") == "0,40"
    t = run_until_idle(unit, unit.now)
    assert list(unit.position[:3]) == total
    assert ans(unit, "!0SR6", t) == "0,00"


def test_k_twice_r_without_k_d_and_g(spec):
    unit = make(spec)
    assert ans(unit, "!0R") == "0"
    assert ans(unit, "!0K") == "0"
    assert ans(unit, "!0K") == "7"
    assert ans(unit, "!0R") == "0"
    assert ans(unit, "!0G") == "6"  # A15: nothing to start
    assert ans(make(spec, A15="no-effect-0"), "!0G") == "0"
    ans(unit, "!0L5000,0,0")
    assert ans(unit, "!0D") == "7" and ans(unit, "!0N") == "7" and ans(unit, "!0K") == "7"
    assert ans(unit, "!0NX5") == "0"  # A27: N<axis> allowed while running
    t, a = ex(unit, "!0H", 0.5)
    assert a == "8"
    assert ans(unit, "!0D") == "0"
    assert unit.queue_len == 0 and not unit.inta
    assert ans(unit, "!0G") == "6"


def test_halt_when_idle_and_go_after_finished(spec):
    unit = make(spec)
    assert ans(unit, "!0H") == "8"
    assert ans(unit, "!0SR6") == "8,90"  # INTA, INTCOM, no RUN
    assert ans(unit, "!0L100,0,0") == "8"  # accepted, waits for G
    t = unit.now + 1.0
    assert unit.poll(t) == [] and unit.position[0] == 0
    assert ans(unit, "!0G", t) == "0"
    run_until_idle(unit, t)
    assert unit.position[0] == 100
    assert ans(unit, "!0H") == "8"
    assert ans(unit, "!0G") == "6"  # INTA=1 but nothing left: still 6, flags cleared
    assert not unit.inta


def test_halt_time_is_the_ramp(spec):
    unit = make(spec)
    ans(unit, "!0V10000")
    ans(unit, "!0A10")  # 10 000 pulses/s²
    ans(unit, "!0L1000000,0,0", 0.0)
    t, a = ex(unit, "!0H", 5.0)  # cruising at 10 000/s
    assert a == "8" and t == pytest.approx(6.0)


# ---------------------------------------------------------------- A16: bytes while HALT/W pending

@pytest.mark.parametrize("mode,expect", [("buffered", "8\r8,IP64MPG v19 10.9.2010\r"),
                                         ("discarded", "8\r")])
def test_bytes_while_answer_pending(spec, mode, expect):
    unit = make(spec, A16=mode)
    ans(unit, "!0L100000,0,0", 0.0)
    unit.receive(b"!0H\r", 1.0)
    unit.receive(b"!0?\r", 1.01)
    out = b"".join(b for _, b in unit.poll(10.0)).decode()
    assert out == expect


# ---------------------------------------------------------------- reference move (§13.5.7)

def test_reference_move(spec):
    unit = Unit(spec.variant("gve64-v10"), switches={"Y": 4000})
    t, a = ex(unit, "!0WY,-20000,1000,2000,500", 0.0)
    assert a == "0" and t > 4.0  # 4000 pulses at 1000/s, then back off
    assert unit.position == (0, -4000 + 200, 0, 0)
    t, a = ex(unit, "!0WX,1000,1000,2000,500", t)  # switch not reached in 1000 pulses
    assert a == "0" and unit.position[0] == 1000
    assert ans(unit, "!0Wq,1,10,1,10") == "5"


def test_w_refused_while_running(spec):
    unit = make(spec, "gve64-v10")
    ans(unit, "!0L100000,0,0")
    assert ans(unit, "!0WX,-20000,1000,2000,500") == "7"
    unit = make(spec, "gve64-v10", A27="all-allowed")
    ans(unit, "!0L1000,0,0", 0.0)
    t, a = ex(unit, "!0WX,-20000,1000,2000,500", 0.1)
    assert a == "0" and unit.position[0] == 1000 - 3000 + 200


# ---------------------------------------------------------------- interrupts (§13.5.12)

def test_input_interrupt_while_moving(spec):
    unit = make(spec)
    ans(unit, "!0V5000")
    for _ in range(10):
        ans(unit, "!0C2000,0,0", 0.0)
    assert ans(unit, "!0SW0,80") == "0"  # enable Intr7 (STOP button)
    assert ans(unit, "!0I1") == "0,FF"
    unit.set_input(1, 7, True, 1.0)  # press STOP
    assert unit.inta and unit.status(4) == 0x80
    assert ans(unit, "!0I1", 1.0) == "8,7F"
    assert ans(unit, "!0SR6", 1.0) == "8,C1"  # INTA, RUN, STOP while braking
    t = run_until_idle(unit, 1.0)
    t += 0.1
    unit.poll(t)
    assert ans(unit, "!0SR6", t) == "8,C0"
    x = unit.position[0]
    assert 0 < x < 20000
    unit.set_input(1, 7, False, t)
    assert ans(unit, "!0G", t) == "0"
    assert unit.status(4) == 0
    run_until_idle(unit, t)
    assert unit.position[0] == 20000


def test_disabled_polarity_and_port2(spec):
    unit = make(spec)
    unit.set_input(1, 3, True, 0.0)  # not enabled: nothing happens
    assert not unit.inta and ans(unit, "!0I1") == "0,F7"
    assert ans(unit, "!0SW3,80") == "0"  # Intr15 active high: the idle (high) pin is asserted
    unit.set_input(2, 7, False, 0.05)  # released: now low
    assert ans(unit, "!0SW1,80") == "0"
    unit.set_input(2, 7, True, 0.1)  # touch the tool sensor
    assert unit.inta and unit.status(5) == 0x80
    assert ans(unit, "!0I2") == "8,C0"
    unit = make(spec, "gve124")
    with pytest.raises(ValueError):
        unit.set_input(2, 7, True, 0.0)
    with pytest.raises(ValueError):
        unit.set_input(1, 5, True, 0.0)
    assert ans(unit, "!0I1") == "0,07"


def test_enable_while_asserted_fires(spec):
    unit = make(spec)
    unit.set_input(1, 0, True, 0.0)
    assert ans(unit, "!0SW0,01") == "8"  # the answer already shows INTA
    assert unit.status(4) == 1


# ---------------------------------------------------------------- status words (A20)

def test_status_words_per_variant(spec):
    unit = make(spec, "gve124")
    assert ans(unit, "!0SR1") == "5" and ans(unit, "!0SW3,01") == "5"
    assert ans(unit, "!0SR7") == "5"
    unit = make(spec, "gve124", A20="missing-reads-0")
    assert ans(unit, "!0SW1,FF") == "0" and ans(unit, "!0SR1") == "0,00"
    unit = make(spec)
    for n in range(6):
        assert ans(unit, "!0SW%d,%02X" % (n, 0x11 * n)) == "0"
    assert [unit.status(n) for n in range(6)] == [0x11 * n for n in range(6)]


def test_sw6_inta(spec):
    unit = make(spec)
    ans(unit, "!0L100000,0,0", 0.0)
    assert ans(unit, "!0SW6,80", 1.0) == "8"
    t = run_until_idle(unit, 1.0)
    x = unit.position[0]
    assert ans(unit, "!0SW6,00", t + 1) == "0"
    assert unit.poll(t + 2) == [] and unit.position[0] > x


# ---------------------------------------------------------------- version gating (§14.1)

def test_version_gating(spec):
    v10 = make(spec, "gve64-v10")
    v19 = make(spec, "gve64-v19")
    for line in ("!0VL1000,1000,1000,1000", "!0VK", "!0VN", "!0XM100", "!0NX100"):
        assert ans(v10, line) == "3", line
        assert ans(v19, line) == "0", line
    g124 = make(spec, "gve124")
    for line in ("!0P4", "!0Y-", "!0I2", "!0EFR10", "!0EUR10", "!0EFW10,1.5", "!0EUW10,1"):
        assert ans(g124, line) == "3", line
        assert ans(v10, line)[0] == "0", line


# ---------------------------------------------------------------- MPG (§13.5.8, A14)

def test_mpg_modes(spec):
    unit = make(spec, "gve64-v10")
    assert unit.mpg == "&"
    assert ans(unit, "!0C10,0,0") == "0"  # A14: the reset's Y& does not block
    run_until_idle(unit, 0.0)
    assert ans(unit, "!0Y+", 1.0) == "0,Y+"
    assert ans(unit, "!0C10,0,0") == "7" and ans(unit, "!0SR6") == "0,40"
    assert ans(unit, "!0Y&") == "0,Y&"
    assert ans(unit, "!0Y-") == "0,Y-"
    assert ans(unit, "!0C10,0,0") == "0"
    assert ans(unit, "!0Y+") == "7"  # A27: not while a vector runs
    unit = make(spec, "gve64-v10", A14="reset-blocks")
    assert ans(unit, "!0L10,0,0") == "7"
    assert ans(unit, "!0Y-") == "0,Y-" and ans(unit, "!0L10,0,0") == "0"


# ---------------------------------------------------------------- spindle, outputs, addresses

def test_spindle_address(spec):
    unit = make(spec)
    assert ans(unit, "!7V500") == "0"
    assert unit.spindle == 500 and unit.outputs == 0xFE and unit.modal["V"] == 1000
    assert ans(unit, "!7V0") == "0" and unit.outputs == 0xFF
    assert ans(unit, "!7V1001") == "5"
    assert ans(unit, "!7?") == "0,IP64MPG v19 10.9.2010"
    assert ans(unit, "!7L1,0,0") == "3"
    assert ans(unit, "!0O0,FB") == "0" and unit.outputs == 0xFB
    assert ans(unit, "!0O1,FB") == "5"
    assert ans(make(spec, "gve124", A19="none"), "!7V500") == ""


def test_other_address_is_silent(spec):
    unit = make(spec)
    assert ex(unit, "!3V100", 0.0) == (0.0, "")
    assert unit.modal["V"] == 1000 and unit.index == 0
    assert ans(make(spec, A23="error-3"), "!3V100") == "3"
    assert ans(unit, "hello") == ""


# ---------------------------------------------------------------- EEPROM (§13.5.10, A18, A28)

def test_eeprom(spec):
    unit = make(spec, "gve64-v10")
    assert ans(unit, "!0ER05") == "0,FF"
    assert ans(unit, "!0ER01") == "0,03"
    assert ans(unit, "!0EW01,09") == "0" and ans(unit, "!0ER01") == "0,09"
    assert ans(unit, "!0EFR20") == "0,300"
    assert ans(unit, "!0EUR48") == "0,200"
    assert ans(unit, "!0EFW40,12.5") == "0" and ans(unit, "!0EFR40") == "0,12.5"
    assert ans(unit, "!0EUW48,4294967295") == "0" and ans(unit, "!0EUR48") == "0,4294967295"
    assert ans(unit, "!0EFRFD") == "5" and ans(unit, "!0ER100") == "5"
    assert ans(unit, "!7ER01") == "0,09"
    ans(unit, "!0J", 1.0)
    assert ans(unit, "!0ER01", 4.0) == "0,09"  # survives the reset
    unit = make(spec, "gve64-v10", A18="hex-bytes")
    assert ans(unit, "!0EFW40,00004841") == "0" and ans(unit, "!0EFR40") == "0,12.5"
    assert ans(unit, "!0EUW48,10000000") == "0" and ans(unit, "!0EUR48") == "0,16"
    assert ans(unit, "!0EFW40,12.5") == "4"
    assert ans(make(spec, A28="all-ff"), "!0ER01") == "0,FF"


# ---------------------------------------------------------------- recovery: @ and > (A9, A10)

def test_index_default(spec):
    unit = make(spec)
    assert ans(unit, "!0@") == "0,0"
    ans(unit, "!0V100")
    ans(unit, "!0C1,0,0")
    ans(unit, "!0Z")  # unknown: answered 3, counts
    ans(unit, "!0%+")
    ans(unit, cs("!0V100")[:-2] + "00")  # bad checksum: does not count
    assert ans(unit, cs("!0@")) == "0,4," + "%02X" % (sum(b"0,4,") & 0xFF)
    for _ in range(300):
        ans(unit, cs("!0V100"))
    assert ans(unit, cs("!0@")).startswith("0,%d," % ((4 + 300) % 256))


def test_index_alternatives(spec):
    unit = make(spec, A10="every-line")
    ans(unit, "!0V100")
    ans(unit, "!0Z")
    assert ans(unit, "!0@") == "0,3"
    unit = make(spec, A10="executed-only", A9="hex-index")
    ans(unit, "!0V100")
    ans(unit, "!0Z")
    for _ in range(20):
        ans(unit, "!0A10")
    assert ans(unit, "!0@") == "0,15"


def test_repeat(spec):
    unit = make(spec)
    assert ans(unit, "!0>") == "0"  # nothing to repeat yet
    ans(unit, "!0PF")
    assert ans(unit, "!0>") == "!0PF\r0,0,0,0"
    assert ans(unit, "!0>") == "!0PF\r0,0,0,0"
    unit = make(spec, A9="repeat-answer-only")
    ans(unit, "!0SW8,F1")
    assert ans(unit, "!0>") == "5"


# ---------------------------------------------------------------- J (§13.4, A17)

def test_reset(spec):
    unit = make(spec)
    ans(unit, "!0V500")
    ans(unit, "!0L1000,0,0", 0.0)
    ans(unit, "!0%+")
    t, a = ex(unit, cs("!0J"), 0.5)
    assert a == "0,5C"
    assert unit.deaf
    assert ex(unit, "!0?", 1.0) == (1.0, "") and ex(unit, "!0?", 2.4) == (2.4, "")
    assert unit.next_deadline() == pytest.approx(2.5)
    assert ans(unit, "!0@", 2.6) == "0,0"
    assert unit.modal["V"] == 1000 and unit.position == (0, 0, 0, 0) and not unit.checksum_on
    assert unit.queue_len == 0
    assert unit.modal["T"] == 5 and unit.modal["B"] == 35000
    unit = make(spec, A17="silent")
    assert ans(unit, "!0J", 0.0) == ""
    assert ans(unit, "!7?", 2.1) == "0,IP64MPG v19 10.9.2010"


def test_reset_values_per_variant(spec):
    unit = make(spec, "gve124", A25="24ms", A26="vk-unlimited-100")
    m = unit.modal
    assert m["B"] == 50000 and m["T"] == 24 and m["VK"] and m["VL"] == (100000,) * 3
    assert unit.mpg == "none"


# ---------------------------------------------------------------- watchdog (A13)

def test_watchdog(spec):
    unit = make(spec)
    assert unit.exchange(b"!0V10", 1.0) == (pytest.approx(1.1), b"2\r")
    assert unit.modal["V"] == 1000  # the cut line was not executed
    unit.receive(b"!0V", 2.0)
    unit.receive(b"20\r", 2.05)
    assert unit.poll(3.0) == [(2.05, b"0\r")]
    unit = make(spec, A13="20ms")
    assert unit.exchange(b"!0V10", 0.0) == (pytest.approx(0.02), b"2\r")
    unit = make(spec, A13="off")
    assert unit.exchange(b"!0V10", 0.0) == (0.0, b"")
    assert unit.exchange(b"\r", 100.0) == (100.0, b"0\r")
    unit = make(spec)
    assert unit.exchange(b"!3V10", 0.0) == (0.0, b"")  # other address: silence


# ---------------------------------------------------------------- A1, A2, A3, A21, A6-A8

def test_terminators(spec):
    unit = make(spec)
    assert unit.exchange(b"!0V100\r\n", 0.0) == (0.0, b"0\r")
    assert unit.exchange(b"\n!0V200\r", 0.0) == (0.0, b"0\r")
    unit = make(spec, A1="cr-or-lf")
    assert unit.exchange(b"!0V100\n", 0.0) == (0.0, b"0\r")
    unit = make(spec, A1="crlf")
    assert unit.exchange(b"!0V100\r\n", 0.0) == (0.0, b"0\r")
    assert unit.exchange(b"!0V100\r", 1.0)[1] == b"2\r"  # never completes: watchdog


def test_mnemonic_aliases_and_case(spec):
    assert ans(make(spec), "!0S100") == "3"
    assert ans(make(spec, A2="s-too"), "!0S100") == "0"
    assert ans(make(spec), "!000,FF") == "3"
    assert ans(make(spec, A3="zero-too"), "!000,FB") == "0"
    assert ans(make(spec), "!0v100") == "3"
    assert ans(make(spec, A21="any-case"), "!0v100") == "0"
    assert ans(make(spec), "!0NX1") == ans(make(spec), "!0Nx1") == "0"


def test_ranges(spec):
    assert ans(make(spec), "!0A1001") == "5"
    assert ans(make(spec, A6="1-65535"), "!0A1001") == "0"
    assert ans(make(spec), "!0XM1001") == "5"
    assert ans(make(spec, A8="0-65535"), "!0XM0") == "0"
    assert ans(make(spec), "!0V125001") == "5"
    assert ans(make(spec, "gve64-phantom"), "!0V200000") == "0"
    assert ans(make(spec, "gve124"), "!0V100000") == "0"
    assert ans(make(spec, "gve124", A7="rate-limited"), "!0V50001") == "5"
    assert ans(make(spec, "gve124", A7="rate-limited"), "!0VL10,50001,10") == "5"
    assert ans(make(spec), "!0T25") == "5" and ans(make(spec), "!0T0") == "5"


# ---------------------------------------------------------------- speed changes (§13.5.5)

def job_time(spec, *extra):
    unit = make(spec)
    ans(unit, "!0V1000", 0.0)
    for _ in range(20):
        ans(unit, "!0C1000,0,0", 0.0)
    for line in extra:
        ans(unit, line, 0.5)
    return run_until_idle(unit, 0.5)


def test_exchange_commands_change_queued_speeds(spec):
    base = job_time(spec)
    assert job_time(spec, "!0XU") < base < job_time(spec, "!0XD")
    assert job_time(spec, "!0V2000", "!0XA") < base * 0.6
    assert job_time(spec, "!0XM200") < base * 0.6
    assert job_time(spec, "!0V2000") == pytest.approx(base)  # V alone: following vectors only


def test_velocity_limit_and_correction(spec):
    def duration(*setup):
        unit = make(spec)
        for line in setup:
            ans(unit, line, 0.0)
        ans(unit, "!0L10000,10000,0", 0.0)
        return run_until_idle(unit, 0.0)
    base = duration("!0V1000")
    assert duration("!0V1000", "!0VK") > base * 1.3  # Euclidean path speed
    assert duration("!0V1000", "!0VL500,1000,1000,1000") > base * 1.8


# ---------------------------------------------------------------- mutants and the fast path

def test_mutant_by_subclassing(spec):
    class WrongV(Unit):
        def _cmd_V(self, args, t):
            return 5

    class NoInta(Unit):
        def encode(self, code, fields=()):
            return super().encode(code, fields).replace(b"8", b"0")

    assert ans(WrongV(spec.variant("gve64-v19")), "!0V100") == "5"
    unit = NoInta(spec.variant("gve64-v19"))
    ans(unit, "!0H")
    assert ans(unit, "!0V1000") == "0"

    class FullEarly(Unit):
        def _cmd_C(self, args, t):
            return 1 if self.queue_len >= self.variant.queue - 1 else super()._cmd_C(args, t)

    unit = FullEarly(spec.variant("gve124"))
    ans(unit, "!0V10")
    n = 0
    while ans(unit, "!0C100,0,0") == "0":
        n += 1
    assert n == 127


def test_fast_path_matches_parser(spec):
    lines = ["!0C1,2,3", "!0C1,2,3,4", "!0L-5,0,0", "!0C2147483648,0,0", "!0C1,2",
             "!0C-0,007,1", "!0C1,2,3,4,5", "!0L0,0,0"]
    for vid in ("gve64-v19", "gve124"):
        for checksum_on in (False, True):
            fast = Unit(spec.variant(vid))
            slow = Unit(spec.variant(vid), fast_path=False)
            t = 0.0
            for u in (fast, slow):
                if checksum_on:
                    u.exchange(b"!0%+\r", 0.0)
            for line in lines * 3:
                raw = (cs(line) if checksum_on else line).encode() + b"\r"
                t += 0.001
                assert fast.exchange(raw, t) == slow.exchange(raw, t), (vid, line)
                assert fast.position == slow.position and fast.index == slow.index
            if checksum_on:
                bad = cs("!0C1,2,3")[:-2] + "00"
                assert fast.exchange(bad.encode() + b"\r", t) == (t, b"4,60\r")


@pytest.mark.parametrize(("choice", "repeats"), [("valid-only", "vector"), ("every-line", "damaged")])
def test_repeat_after_a_damaged_line_a29(spec, choice, repeats):
    """A29: a line rejected for its checksum does (every-line) or does not (valid-only)
    become the line that `>` repeats."""
    u = make(spec, A29=choice)
    assert ans(u, "!0%+") == "0,5C"
    vector = cs("!0C1,0,0")
    assert ans(u, vector) == "0,5C"
    assert ans(u, "!0>,00") == "4,60"  # a `>` damaged on the way
    echo = ans(u, cs("!0>"))
    if repeats == "vector":
        assert echo == f"{vector}\r0,5C"
    else:
        assert echo == "!0>,00\r4,60"
