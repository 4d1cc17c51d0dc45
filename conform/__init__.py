"""conform: protocol conformance and traffic analysis for serial motion controllers (protocol
families as plugins: conform.families)."""

__version__ = "0.1.0"
