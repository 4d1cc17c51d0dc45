"""The host's bytes as a GVE unit would have read them, and its `>` echoes compared.

Line assembly follows the unit's reception (unit/reception.py): lines end at the A1
terminator (GVE64 §13.3: Enter), a begun ``!`` line that does not complete within the A13
watchdog is answered 2 and dropped (§13.7 code 2), with checksums on (``%+``, §13.3.2) a line
whose sum does not hold is refused, and a line holding a second ``!`` is two commands run
together (the unit reads it as one, and refuses it). Where the host asked ``>`` (§13.5.13:
repeat the last command and its answer), the unit's echo is what it really received: an echo
that differs from the line sent means the line changed on the way, and when the echo is still
a valid command the unit executed it as received.
"""

from __future__ import annotations

from typing import Any

from conform.diagnosis.facts import ParsedLine
from conform.families.gve.protocol.lines import LineSplitter
from conform.families.gve.unit.reception import WATCHDOG_S, parser_for

ECHO_WAIT_S = 1.0       # an echo arrives within this after its `>`
RECENT = 8              # an echo equal to one of these earlier lines repeats that one


def _lines(d: Any, mode: str, t0: float) -> list[tuple[float, float, bytes]]:
    """(first byte's time, last byte's time, line) of one direction, read by read."""
    data = d.data.tobytes()
    sp = LineSplitter(mode, None)
    out = []
    begun: float | None = None
    for s, n, tf, tr in zip(d.start.tolist(), d.length.tolist(), d.t_first.tolist(),
                            d.t_read.tolist(), strict=True):
        first = (tf if tf == tf else tr) - t0
        if begun is None or not sp.pending:
            begun = first
        for line in sp.feed(data[s:s + n]):
            out.append((begun, tr - t0, bytes(line)))
            begun = first
        if not sp.pending:
            begun = None
    return out


def reception(raw: Any, *, variant: str | None = None) -> list[ParsedLine]:
    from conform.families.gve.spec import load_spec

    spec = load_spec()
    session = raw.metadata.get("conform.session", {})
    vid = variant or str(session.get("variant", "") or "") or "gve64-v19"
    try:
        var = spec.variant(vid)
    except Exception:  # noqa: BLE001 - an unknown variant is read as the default one
        var = spec.variant("gve64-v19")
    dia = spec.dialect(str(session.get("dialect", "") or "")) if session.get("dialect") \
        else spec.dialect()
    parser = parser_for(var, dia, spec)
    watchdog = WATCHDOG_S.get(str(dia.choices.get("A13", "100ms")))
    mode = {"cr": "cr", "cr-or-lf": "cr-or-lf", "crlf": "crlf"}.get(
        str(dia.choices.get("A1", "cr")), "cr")
    t0 = min([float(x.t_read[0]) for x in (raw.host, raw.unit) if len(x.t_read)], default=0.0)
    host = _lines(raw.host, mode, t0)
    unit = _lines(raw.unit, mode, t0)
    out: list[ParsedLine] = []
    checksums = False
    last_cmd: tuple[int, bytes] | None = None
    recent: list[bytes] = []      # the last command lines sent, the newest last
    u = 0
    for n, (t_begin, t_end, line) in enumerate(host):
        text = line.decode("latin-1")
        bang = line.rfind(b"!")
        if bang > 0 and b"!" in line[:bang]:
            out.append(ParsedLine("merged", [n], text, line[bang:].decode("latin-1"), t_end,
                                  "two commands without a terminator between them: the "
                                  "unit refuses the run-together line"))
            continue
        if watchdog is not None and line.startswith(b"!") and t_end - t_begin > watchdog:
            out.append(ParsedLine("truncated", [n], text, "", t_begin + watchdog,
                                  f"took {1000 * (t_end - t_begin):.0f} ms to arrive, more "
                                  f"than the {1000 * watchdog:.0f} ms watchdog (A13): "
                                  "answered 2 and dropped"))
            continue
        r = parser.parse(line, checksums)
        name = getattr(r, "name", None)
        if getattr(r, "kind", None) == "checksum":
            out.append(ParsedLine("damaged", [n], text, text, t_end,
                                  "checksums are on and its sum does not hold: refused "
                                  "(GVE64 §13.3.2)"))
            continue
        if name == "%" and not hasattr(r, "kind"):
            checksums = b"+" in line.split(b"%", 1)[1][:1]
        if name == ">" and last_cmd is not None:
            while u < len(unit) and unit[u][1] < t_end:
                u += 1
            k = u
            while k < len(unit) and unit[k][1] <= t_end + ECHO_WAIT_S and \
                    not unit[k][2].startswith(b"!"):
                k += 1
            if k < len(unit) and unit[k][1] <= t_end + ECHO_WAIT_S:
                echo = unit[k][2]
                m, sent = last_cmd
                if echo != sent and echo in recent[:-1]:
                    out.append(ParsedLine(
                        "dropped", [m], sent.decode("latin-1"), "", unit[k][1],
                        "the unit's `>` echo repeats an earlier line: this one never arrived "
                        "valid (A29), so it was not executed", echo.decode("latin-1")))
                elif echo != sent:
                    valid = not hasattr(parser.parse(echo, checksums), "kind")
                    out.append(ParsedLine(
                        "damaged-valid" if valid else "damaged", [m],
                        sent.decode("latin-1"), echo.decode("latin-1"), unit[k][1],
                        "the unit's `>` echo differs from the line sent: it changed on the "
                        "way" + ("; still a valid command, executed as received" if valid
                                 else ""), echo.decode("latin-1")))
        elif name not in (">", "@", None) and not hasattr(r, "kind"):
            last_cmd = (n, line)
            recent = [*recent[-(RECENT - 1):], line]
    return out
