"""The grbl wire protocol, sans-I/O: the byte stream split into lines and realtime bytes, what grbl
sends classified (codec), and the g-code parser with its modal state (gcode)."""
