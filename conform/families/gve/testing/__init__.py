"""What GVE's tests and the fuzz bench use and the shipped commands never do: the fuzz campaign
against the reference unit and the hypothesis strategies drawn from the tables."""
