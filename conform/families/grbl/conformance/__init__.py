"""The grbl conformance checks generated from the tables, and characterisation of a unit."""
