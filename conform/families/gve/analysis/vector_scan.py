"""The strict form of the motion vectors (C, L), read straight from the byte stream, compiled.

Almost every line of a busy session is a vector; reading them with one compiled pass over
the bytes costs a few nanoseconds a line where a regular expression over Arrow strings and
a cast per axis cost half a microsecond. The form is the one ``frames._vector_form`` takes
from the table rows (C and L, GVE64 §13.5.2; number syntax A22 ``strict``, GVE64 §13.5.2
and §13.7; mnemonics A21 ``upper-mnemonics``, GVE64 §13.5.7):
``!<address><mnemonic>`` then the axes as optional-minus decimal integers separated by
commas, the first three always there with 1 to 10 digits, the further ones optional
(missing ones are 0). Anything else, and any axis too long to be held exactly, is left to
the command parser, which decides what it is.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_MINUS, _COMMA, _ZERO, _NINE = 45, 44, 48, 57
_MAX_DIGITS = 18  # an int64 holds any 18-digit number; longer ones go to the parser


@njit(cache=True, nogil=True)
def scan_vectors(data: np.ndarray, start: np.ndarray, end: np.ndarray, rows: np.ndarray,
                 prefix: np.ndarray, naxes: int) -> tuple:
    """(ok, values) for the lines ``rows`` (bytes ``data[start[r]:end[r]]``): ``ok[i]`` when
    line ``rows[i]`` is ``prefix`` followed by the axes, ``values[i]`` its ``naxes`` axes."""
    m = len(rows)
    ok = np.zeros(m, np.bool_)
    values = np.zeros((m, naxes), np.int64)
    k = len(prefix)
    for i in range(m):
        r = rows[i]
        pos = start[r]
        stop = end[r]
        if stop - pos <= k:
            continue
        good = True
        for j in range(k):
            if data[pos + j] != prefix[j]:
                good = False
                break
        if not good:
            continue
        pos += k
        for a in range(naxes):
            if a > 0:
                if pos == stop and a >= 3:
                    break  # the further axes may be left out
                if pos == stop or data[pos] != _COMMA:
                    good = False
                    break
                pos += 1
            neg = False
            if pos < stop and data[pos] == _MINUS:
                neg = True
                pos += 1
            value = 0
            digits = 0
            while pos < stop and _ZERO <= data[pos] <= _NINE:
                value = value * 10 + (data[pos] - _ZERO)
                digits += 1
                pos += 1
                if digits > _MAX_DIGITS:
                    break
            if digits == 0 or digits > _MAX_DIGITS or (a < 3 and digits > 10):
                good = False
                break
            values[i, a] = -value if neg else value
        if good and pos == stop:
            ok[i] = True
    return ok, values
