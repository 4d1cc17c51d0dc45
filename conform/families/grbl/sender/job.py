"""A job file as grbl's reference sender streams it: each line stripped of spaces and
comments, upper-cased, the way grbl's own doc/script/stream.py prepares a block (grbl does the
same before a line enters its line buffer, protocol.c), blank results left out.

Everything grbl would refuse or act on in a way the job cannot mean is refused here, before a
byte is sent: a line longer than the variant's line buffer (grbl answers error:11 and drops
it), and realtime bytes (``?``, ``!``, ``~``, anything above 0x7F), which grbl acts on the
moment they arrive instead of reading them as part of a line.
"""

from __future__ import annotations

from dataclasses import dataclass

from conform.errors import UserError, read_user_text


@dataclass(frozen=True)
class JobLine:
    number: int   # 1-based line of the job file
    text: str     # the file's line, as written (for messages)
    block: bytes  # what is sent, without the newline

    @property
    def size(self) -> int:
        """Bytes the line takes in grbl's receive buffer, newline included."""
        return len(self.block) + 1

    def where(self, path: str) -> str:
        return f"{path}:{self.number} {self.text.strip()!r}"


def strip_block(line: str) -> str | None:
    """A job line as grbl reads it (protocol.c): spaces and ``(comments)`` left out, a ``;``
    outside a comment ends the line, upper case; None for a comment left open."""
    out: list[str] = []
    in_comment = False
    for c in line:
        if in_comment:
            in_comment = c != ")"
        elif c == "(":
            in_comment = True
        elif c == ";":
            break
        elif not c.isspace():
            out.append(c)
    return None if in_comment else "".join(out).upper()


def load_job(path: str, *, line_max: int, realtime: set[int]) -> list[JobLine]:
    """The lines of ``path`` to stream; one ``UserError`` line for what grbl cannot take."""
    lines: list[JobLine] = []
    for n, text in enumerate(read_user_text(path).splitlines(), 1):
        block = strip_block(text)
        if block is None:
            raise UserError(f"{path}:{n}: a comment '(' that is not closed on its line")
        if not block:
            continue
        bad = next((c for c in block if ord(c) > 0x7F or ord(c) in realtime or ord(c) < 0x20),
                   None)
        if bad is not None:
            raise UserError(f"{path}:{n}: {bad!r} is not job text (grbl acts on realtime and "
                            "control bytes at once, outside the line); nothing was sent")
        if len(block) > line_max:
            raise UserError(f"{path}:{n}: {len(block)} characters without spaces and comments; "
                            f"grbl's line buffer takes {line_max} (it would answer error:11 and "
                            "drop the line); nothing was sent")
        lines.append(JobLine(n, text, block.encode("ascii")))
    if not lines:
        raise UserError(f"{path}: no line to send (only blank lines and comments)")
    return lines
