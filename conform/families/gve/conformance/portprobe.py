"""``conform ports --probe`` for GVE units: ask ``?`` (it only reads the firmware string,
GVE64 §13.5.1), plain and, if the unit wants them, with a checksum, and map the firmware
string to a variant."""

from __future__ import annotations

import re

from conform.conformance.target import HarnessError
from conform.errors import UserError
from conform.families import ProbeAnswer


def probe(device: str, *, baud: int, timeout: float) -> ProbeAnswer:
    from conform.families.gve.conformance.safety import Guard
    from conform.families.gve.conformance.target import open_target, variant_for_firmware
    from conform.families.gve.spec import load_spec

    spec = load_spec()
    try:
        target, _ = open_target(device, spec, baud=baud, guard=Guard(False, None, False))
    except UserError as exc:
        return ProbeAnswer(None, None, str(exc))
    answer, how = None, "no answer"
    try:
        # another family's question may have left bytes in the unit's line: end that line
        # first (an empty line gets no answer, GVE64 §13.5) and drop what it answers
        target.send(b"\r")
        target.wait(0.05)
        target.drain()
        for checksum in (False, True):
            try:
                reply = target.exchange(target.frame("!0?", checksum=checksum), timeout=timeout)
            except HarnessError as exc:
                how = f"no answer to ? ({exc})"
                continue
            text = reply.lines[0].decode("latin-1").strip() if reply.lines else ""
            if not text.startswith("0,"):
                answer = text or None
                how = f"answered {text!r}, not a firmware string" if text else "no answer"
                continue
            firmware = text.split(",", 1)[1]
            if checksum:
                firmware = re.sub(r",[0-9A-Fa-f]{2}$", "", firmware)
            variant, how = variant_for_firmware(spec, firmware)
            return ProbeAnswer(variant, text, how)
    finally:
        target.close()
    return ProbeAnswer(None, answer, how)
