"""Marlin's senders: ``sim`` (a scripted host on a virtual clock, for tests and benchmarks) and
the reference streamer of ``conform send`` (``stream``, ``command``)."""
