"""The job against what the unit accepted: double moves, lost and altered vectors, as facts.

Vectors are relative (GVE64 §13.5.2): the machine ends where the job says only if the unit
accepted every job vector exactly once, in order. The accepted list comes from the
emulator's ground truth, so nothing here is inferred from the wire. The two sequences are
aligned (difflib, no junk heuristics); what the unit took beyond the job is an extra vector
(a double move when it repeats a job vector next to it), what it never took is a lost
vector, and a job vector replaced by a different one was altered on the way (a damaged line
the unit could not recognise as damaged: no checksums).
"""

from __future__ import annotations

from dataclasses import dataclass, field

Vec = tuple[str, tuple[int, ...]]
LOOKAHEAD = 3


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


def _resyncs(job: list[Vec], i: int, acc: list[Vec], j: int, k: int = LOOKAHEAD) -> bool:
    a, b = job[i:i + k], acc[j:j + k]
    n = min(len(a), len(b))
    return a[:n] == b[:n] and (n == k or len(job) - i == len(acc) - j)


def compare(job: list[Vec], accepted: list[Vec], *, tail_may_be_missing: bool = False
            ) -> Comparison:
    """Walk ``job`` and ``accepted`` side by side; at a difference, the explanation that
    brings the two back in step for the next few vectors wins: an extra accepted vector
    (a double move when it repeats its neighbour), a job vector never accepted (lost), or
    one replaced by another (altered). ``tail_may_be_missing``: the run was ended on purpose
    (an interrupt answered with D), so job vectors after the last accepted one are not lost.
    """
    c = Comparison(len(job), len(accepted))
    i = j = 0
    while i < len(job) or j < len(accepted):
        if i < len(job) and j < len(accepted) and job[i] == accepted[j]:
            i += 1
            j += 1
            continue
        if i >= len(job):
            extra = True
        elif j >= len(accepted):
            extra = False
        else:
            repeat = accepted[j] == accepted[j - 1] if j else False
            extra_ok = _resyncs(job, i, accepted, j + 1)
            lost_ok = _resyncs(job, i + 1, accepted, j)
            if extra_ok and (repeat or not lost_ok):
                extra = True
            elif lost_ok:
                extra = False
            else:
                c.altered.append({"job_index": i, "job": _fmt(job[i]), "accepted_index": j,
                                  "accepted": _fmt(accepted[j])})
                i += 1
                j += 1
                continue
        if extra:
            near = accepted[j] in job[max(0, i - 1):i + 1] or (j and accepted[j] == accepted[j - 1])
            (c.doubles if near else c.extras).append(
                {"accepted_index": j, "vector": _fmt(accepted[j]), "after_job_index": i - 1})
            j += 1
        else:
            c.lost.append({"job_index": i, "vector": _fmt(job[i])})
            i += 1
    c.prefix = accepted == job[: len(accepted)]
    if tail_may_be_missing and c.lost:
        last = max((x["after_job_index"] for x in c.doubles + c.extras), default=-1)
        matched_upto = _last_matched(job, accepted)
        c.lost = [x for x in c.lost if x["job_index"] < max(last, matched_upto)]
    return c


def _last_matched(job: list[Vec], accepted: list[Vec]) -> int:
    """How far into the job the accepted vectors reach (for an aborted run)."""
    reach = 0
    i = 0
    for v in accepted:
        while i < len(job) and job[i] != v:
            i += 1
        if i < len(job):
            i += 1
            reach = i
    return reach
