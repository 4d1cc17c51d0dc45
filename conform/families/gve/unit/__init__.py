"""The reference unit model: the GVE protocol state machine on an injected clock."""

from conform.families.gve.unit.given import drive_given
from conform.families.gve.unit.model import DEFER, HANDLER_NAMES, Unit, run_until_idle

__all__ = ["DEFER", "HANDLER_NAMES", "Unit", "drive_given", "run_until_idle"]
