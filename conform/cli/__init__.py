"""The ``conform`` command line: one small module per subcommand group."""

from conform.stops import keep_early_stops

keep_early_stops()   # before the subcommands load: a stop sent meanwhile is not lost
