"""The grbl reference unit, sans-I/O on an injected clock: the model (model), the planner in
virtual time (planner), the `$` commands (system), the text it sends (replies), its input pins
(inputs), faults and the control requests (faults, control)."""
