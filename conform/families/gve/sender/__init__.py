"""The reference sender: streams a job (vectors or G-code) with a chosen recovery policy."""

from conform.families.gve.sender.core import POLICIES, Sender
from conform.families.gve.sender.job import Item, load_job

__all__ = ["POLICIES", "Item", "Sender", "load_job"]
