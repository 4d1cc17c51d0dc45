"""One Marlin check (``MarlinCheck``) and what its run returns (``Outcome``): the shape the
runner (checks.py) grades and every module of checks builds (checks.py, depth.py)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from conform.conformance.results import MUST
from conform.families.marlin.conformance.session import Session

Outcome = tuple[bool | None, str, str]      # passed (None: not applicable), expected, actual


@dataclass
class MarlinCheck:
    id: str
    clause: str
    title: str
    run: Callable[[Session], Outcome]
    level: str = MUST
    motion: bool = False      # moves axes, or leaves the unit dead (M112)
    heat: bool = False
    emulator_only: bool = False
    kills: bool = False       # leaves the unit halted until a reset (M112): on a real unit
                              # only the last of these runs, once
    eeprom: bool = False      # writes the EEPROM (M500)

    @property
    def subject(self) -> str:
        """What is checked: ``line``, ``checksum``, ``report``, ``halt`` …"""
        parts = self.id.split("/")
        return parts[2] if len(parts) > 2 else self.id


def ok_kind(s: Session, line: str) -> bool:
    """The line is an ``ok`` (plain, with temperatures, or ADVANCED_OK's)."""
    return s.spec.classify(line)[0].startswith("ok")
