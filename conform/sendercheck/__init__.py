"""Judge a user's sender program: run it against the reference unit under scenarios, record
each session through the proxy, and grade it per rule and manual clause.

    families/gve/sendercheck/scenarios.py   what each GVE scenario does to the link and the unit
    families/gve/sendercheck/rules.py       the GVE rules, each citing its clause
    family.py      a protocol family: its scenarios, rules and job format, in one object
    faults.py      fault injection scripted by the scenario (lost answers, a dead line)
    compare.py     the job against what the unit accepted: double moves and lost vectors
    session.py     one run of the program: emulator, proxy, recording, ground truth
    grade.py       sessions -> verdicts -> results (exit code)
    report.py      index.html, summary.md, junit.xml, results.json
"""
