"""The grbl scenarios and rules check-sender grades a sender on: the scenarios and the command
(scenarios), one run of a program (session), the rules (rules)."""
