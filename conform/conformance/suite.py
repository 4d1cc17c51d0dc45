"""What every family's conformance run shares: profile names, replay tokens, the results of a
``conform run`` (``results_of``) and its timestamps. A family's suite of checks is its own
(GVE: conform.families.gve.conformance.suite)."""

from __future__ import annotations

from datetime import UTC, datetime

from conform.conformance.results import RunResults, TargetRun
from conform.errors import UserError

PROFILE_NAMES = ("quick", "full")


def parse_replay(token: str) -> tuple[str, int | None]:
    """``gve64-v19/13.5/sequences@1234`` → (check id, seed)."""
    check_id, _, seed = token.partition("@")
    if seed and not seed.isdigit():
        raise UserError(f"--replay {token!r}: the seed after '@' must be a number")
    return check_id, int(seed) if seed else None


def now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def results_of(runs: list[TargetRun], command: str, mutants: list[dict[str, object]] | None = None
               ) -> RunResults:
    return RunResults(runs, command, now_iso(), mutants or [])
