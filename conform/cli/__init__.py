"""The ``conform`` command line: one small module per subcommand group."""
