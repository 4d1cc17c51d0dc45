"""The protocol as data: load and query the ``specs/`` tables."""

from conform.families.gve.spec.load import default_root, load_spec
from conform.families.gve.spec.model import (
    AnswerField,
    CommandSpec,
    Dialect,
    EepromMap,
    ErrorCode,
    Example,
    ParamSpec,
    Question,
    Spec,
    Variant,
)
from conform.families.gve.spec.schema import SpecError

__all__ = [
    "AnswerField", "CommandSpec", "Dialect", "EepromMap", "ErrorCode", "Example", "ParamSpec",
    "Question", "Spec", "SpecError", "Variant", "default_root", "load_spec",
]
