"""The job against what the unit accepted: double moves, lost and altered vectors, as facts.

Vectors are relative (GVE64 §13.5.2): the machine ends where the job says only if the unit
accepted every job vector exactly once, in order. The accepted list comes from the
emulator's ground truth, so nothing here is inferred from the wire. The two sequences are
aligned by the cheapest edit script (dynamic programming in a band around the diagonal);
what the unit took beyond the job is an extra vector
(a double move when it repeats a job vector next to it), what it never took is a lost
vector, and a job vector replaced by a different one was altered on the way (a damaged line
the unit could not recognise as damaged: no checksums).
"""

from __future__ import annotations

from dataclasses import dataclass, field

Vec = tuple[str, tuple[int, ...]]


@dataclass
class Comparison:
    job: int
    accepted: int
    doubles: list[dict] = field(default_factory=list)  # extra copies of a job vector
    extras: list[dict] = field(default_factory=list)  # vectors the job never had
    lost: list[dict] = field(default_factory=list)
    altered: list[dict] = field(default_factory=list)
    prefix: bool = False  # the accepted vectors are exactly the job's first ``accepted``

    @property
    def exact(self) -> bool:
        return not (self.doubles or self.extras or self.lost or self.altered)

    def summary(self) -> str:
        parts = [f"{self.accepted} of {self.job} job vectors accepted"]
        for name, items in (("double", self.doubles), ("extra", self.extras),
                            ("lost", self.lost), ("altered", self.altered)):
            if items:
                parts.append(f"{len(items)} {name}")
        return ", ".join(parts)


def _fmt(v: Vec) -> str:
    return v[0] + ",".join(str(x) for x in v[1])


def _align(job: list[Vec], acc: list[Vec], band: int) -> list[tuple[str, int, int]]:
    """The cheapest edit script from ``job`` to ``acc`` (match 0; extra, lost or altered 1),
    computed in a band of ``band`` cells either side of the diagonal: a list of
    ("=" | "+" | "-" | "~", job index, accepted index)."""
    n, m = len(job), len(acc)
    big = n + m + 1
    lo = [max(0, (i * m) // max(n, 1) - band - max(0, m - n)) for i in range(n + 1)]
    hi = [min(m, (i * m) // max(n, 1) + band + max(0, m - n)) for i in range(n + 1)]
    cost: list[list[int]] = []
    step: list[bytearray] = []
    for i in range(n + 1):
        row = [big] * (hi[i] - lo[i] + 1)
        how = bytearray(len(row))
        for j in range(lo[i], hi[i] + 1):
            k = j - lo[i]
            if i == 0 and j == 0:
                row[k] = 0
                continue
            best, b = big, 0
            if i and lo[i - 1] <= j <= hi[i - 1]:
                # a lost vector first: on a tie the accepted ones align with the job's start
                best, b = cost[i - 1][j - lo[i - 1]] + 1, 3
                if j and j - 1 >= lo[i - 1] and job[i - 1] == acc[j - 1]:
                    d = cost[i - 1][j - 1 - lo[i - 1]]
                    if d < best:
                        best, b = d, 1  # match
            if j and j - 1 >= lo[i] and row[k - 1] + 1 < best:
                best, b = row[k - 1] + 1, 2  # extra
            if i and j and lo[i - 1] <= j - 1 <= hi[i - 1] and job[i - 1] != acc[j - 1]:
                d = cost[i - 1][j - 1 - lo[i - 1]] + 1
                if d < best:
                    best, b = d, 4  # altered
            row[k], how[k] = best, b
        cost.append(row)
        step.append(how)
    if not lo[n] <= m <= hi[n] or cost[n][m - lo[n]] >= big:
        raise ValueError("outside the band")
    out = []
    i, j = n, m
    while i or j:
        b = step[i][j - lo[i]]
        if b == 1:
            i, j = i - 1, j - 1
            out.append(("=", i, j))
        elif b == 2:
            j -= 1
            out.append(("+", i, j))
        elif b == 3:
            i -= 1
            out.append(("-", i, j))
        else:
            i, j = i - 1, j - 1
            out.append(("~", i, j))
    out.reverse()
    return out


def compare(job: list[Vec], accepted: list[Vec], *, tail_may_be_missing: bool = False,
            band: int = 64) -> Comparison:
    """Align ``accepted`` with ``job`` (the fewest extra, lost and altered vectors that
    explain the difference); an accepted vector beyond the job is a double move when it
    repeats the job vector next to it. ``tail_may_be_missing``: the run was ended on purpose
    (an interrupt answered with D), so job vectors after the last accepted one are not lost.
    """
    c = Comparison(len(job), len(accepted))
    c.prefix = accepted == job[: len(accepted)]
    if job == accepted:
        return c
    script = None
    while script is None:
        try:
            script = _align(job, accepted, band)
        except ValueError:
            band *= 4
    reach = max((i + 1 for op, i, _j in script if op in ("=", "~")), default=0)
    for op, i, j in script:
        if op == "+":
            near = {job[k] for k in (i - 1, i) if 0 <= k < len(job)}
            item = {"accepted_index": j, "vector": _fmt(accepted[j]), "after_job_index": i - 1}
            (c.doubles if accepted[j] in near else c.extras).append(item)
        elif op == "-":
            if not (tail_may_be_missing and i >= reach):
                c.lost.append({"job_index": i, "vector": _fmt(job[i])})
        elif op == "~":
            c.altered.append({"job_index": i, "job": _fmt(job[i]), "accepted_index": j,
                              "accepted": _fmt(accepted[j])})
    return c
