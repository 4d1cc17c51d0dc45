"""conform: protocol conformance and traffic analysis for Gravos GVE interpolators."""

__version__ = "0.1.0"
