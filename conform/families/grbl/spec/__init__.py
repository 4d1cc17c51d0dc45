"""The tables of the grbl family, shipped as package data (``tables/*.toml``)."""
