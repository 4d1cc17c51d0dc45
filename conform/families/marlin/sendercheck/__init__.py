"""The Marlin scenarios and rules check-sender grades a sender on: the scenarios and the job
(scenarios), the family's hooks (family), what the rules read of a session (session), the
rules (rules)."""
