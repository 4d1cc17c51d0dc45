"""The GVE conformance checks: generated checks, expectations, state machine, state keeper,
mutants, characterisation, scripts, safety and profiles."""
