"""Marlin's part of the diagnosis (conform.diagnosis): the session as neutral facts (facts.py)."""
