"""The GVE scenarios and rules check-sender grades a sender on."""
