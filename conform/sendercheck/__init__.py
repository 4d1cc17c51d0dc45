"""Judge a user's sender program, for every family: run it against the family's reference
unit under scenarios, record each session, and grade it per rule and clause.

    family.py      the shapes a family hands check-sender (``Family.check_sender``): its
                   scenarios (``params`` for its own knobs), rules, job, unit, ground truth
    session.py     the supervisor: one run of the program against the emulator on a pty,
                   templating, timeouts, the scenario's timed actions, the recording
    faults.py      fault injection scripted by the scenario (lost answers, a dead line)
    grade.py       sessions -> verdicts (the engine's Grade) -> results (exit code); Ctrl-C
    report.py      index.html, summary.md, junit.xml, results.json
    options.py     the command's option checks

A family's own scenarios and rules live in its package (``families/<name>/sendercheck/``).
"""
