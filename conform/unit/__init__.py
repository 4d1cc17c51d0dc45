"""The reference unit model: the GVE protocol state machine on an injected clock."""

from conform.unit.model import DEFER, HANDLER_NAMES, Unit, run_until_idle

__all__ = ["DEFER", "HANDLER_NAMES", "Unit", "run_until_idle"]
