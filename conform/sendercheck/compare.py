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
from difflib import SequenceMatcher

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


def compare(job: list[Vec], accepted: list[Vec], *, tail_may_be_missing: bool = False
            ) -> Comparison:
    """Align ``accepted`` with ``job``; ``tail_may_be_missing``: the run was ended on purpose
    (an interrupt answered with D), so job vectors never sent after the last accepted one
    are not lost."""
    c = Comparison(len(job), len(accepted))
    sm = SequenceMatcher(None, job, accepted, autojunk=False)
    for op, i1, i2, j1, j2 in sm.get_opcodes():
        if op == "equal":
            continue
        if op == "replace" and i2 - i1 == j2 - j1:
            for k in range(i2 - i1):
                c.altered.append({"job_index": i1 + k, "job": _fmt(job[i1 + k]),
                                  "accepted_index": j1 + k, "accepted": _fmt(accepted[j1 + k])})
            continue
        for j in range(j1, j2):  # inserted (or the longer side of a replace)
            near = {job[i] for i in (i1 - 1, i1, i2 - 1, i2) if 0 <= i < len(job)}
            item = {"accepted_index": j, "vector": _fmt(accepted[j]), "after_job_index": i1 - 1}
            (c.doubles if accepted[j] in near or accepted[j] in accepted[max(0, j - 1):j]
             else c.extras).append(item)
        for i in range(i1, i2):
            c.lost.append({"job_index": i, "vector": _fmt(job[i])})
    c.prefix = accepted == job[: len(accepted)]
    if tail_may_be_missing and c.lost:
        last = max((m[0] + m[2] for m in sm.get_matching_blocks() if m[2]), default=0)
        c.lost = [x for x in c.lost if x["job_index"] < last]
    return c
