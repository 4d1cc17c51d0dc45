"""grbl's part of the diagnosis (conform.diagnosis): the session as neutral facts, the lines as
grbl's receive buffer and parser took them, the resume point (facts.py), and the live view's
counters (live.py)."""
