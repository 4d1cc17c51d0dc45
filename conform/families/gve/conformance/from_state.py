"""Every command run from a state that is not the reset state, with everything a host can read
back read after it (GVE64 §13.5.6, §13.5.9, §13.5.12): a command that should leave a status
word, a position counter or another axis alone, or clear, park or restore them, shows what it
really did only when they hold something other than their reset values. The reference unit
says what each read must answer; nothing here moves an axis, drives an output or writes the
EEPROM beyond what the command itself does (the run's guard skips those as for any check).
"""

from __future__ import annotations

from typing import Any

from conform.families.gve.conformance.motion_free import _read_position
from conform.families.gve.conformance.script import Step

# status words written before the command: polarities and interrupt causes, never the enables
# (ST0/ST1: an enabled input could fire) nor ST6 (the system flags, SW6 discouraged, §13.5.12)
_WORDS = {2: "5A", 3: "A5", 4: "0F", 5: "F0"}
# position counters set before the command, one distinct value per axis
_COUNTERS = (123, -456, 789, -12)


def state_setup(b: Any) -> list[Step]:
    """Status words and position counters away from their reset values (when the variant has
    the commands that set them without motion)."""
    steps = [b.raw(f"!0SW{w},{value}") for w, value in _WORDS.items() if w in b.v.status_words]
    if "N<axis>" in b.v.commands:
        steps += [b.raw(f"!0N{axis}{value}") for axis, value in zip(b.v.axes, _COUNTERS, strict=False)]
    return steps


def read_back(b: Any) -> list[Step]:
    """Every status word, F, every position form and the @ index, none of them the subject."""
    steps = [b.cmd_step("SR", [w], subject=False) for w in sorted(b.v.status_words)]
    steps.append(b.cmd_step("F", [], subject=False))
    steps += _read_position(b)
    steps.append(b.cmd_step("@", [], subject=False))
    return steps


def from_state_checks(b: Any, valid: dict[str, tuple[list[Step], int | None]]) -> None:
    """``<command>/from-state`` for every command of the variant; ``valid`` gives each
    command's own setup and steps (as its valid form has them) and the answer it intends."""
    setup = state_setup(b)
    for cid, (steps, intent) in valid.items():
        b.add(cid, "from-state",
              f"{cid} from a state other than reset (status words, counters): every status "
              "word, F, the positions and @ read back after it",
              [Step(reset=True), *setup, *steps, *read_back(b)], intent=intent)


# commands whose effect on a held queue (INTA=1, INTCOM=1, a vector waiting for G) a host relies
# on in its recovery (GVE64 §13.5.9)
HELD_COMMANDS = ("K", "R", "D", "G", "H", "N", "N<axis>", "SW")


def from_held_checks(b: Any) -> None:
    """``<command>/from-held``: the same state, then HALT with nothing running and a
    zero-pulse vector behind it (INTA and INTCOM set, RUN=1, no axis moves), then the command
    and everything read back; and the recovery commands' own edges from there: R with nothing
    kept, K twice."""
    setup = [*state_setup(b), *b.held()]
    for cid in HELD_COMMANDS:
        if cid in b.v.commands:
            b.add(cid, "from-held",
                  f"{cid} with INTA and INTCOM set and a vector held for G: every status word, "
                  "F, the positions and @ read back after it",
                  [Step(reset=True), *setup, b.cmd_step(cid, b.valid_args(cid)), *read_back(b)])
    b.add("R", "nothing-kept", "R with nothing kept is without effect: nothing it would "
          "restore changes", [Step(reset=True), *state_setup(b), b.cmd_step("R", []), *read_back(b)])
    b.add("K", "twice", "K a second time without R is refused (7); the first K's parking "
          "stands, and R then restores what the first K kept",
          [Step(reset=True), *setup, b.raw("!0K"), b.cmd_step("K", []), *read_back(b),
           b.raw("!0R"), *read_back(b)])
