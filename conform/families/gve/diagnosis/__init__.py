"""GVE's side of ``conform diagnose``: facts from the GVE analysis (facts.py), the host's bytes
through the unit's line reception (reception.py) and the resume point (resume.py)."""
