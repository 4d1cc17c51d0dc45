"""Where a stopped GVE job can go on.

Vectors are relative (GVE64 §13.5.2), so resuming needs the machine where the last executed
vector ended and the modal values the job set (V, A, B, $, T, VL, XM, checksum mode; §13.4
says a reset brings the defaults back). The last vector known executed comes from the queue
replay (the unit's motion model run on the accepted vectors: completed before the capture
ended) and is overruled by a position read-back (P, PF, P4, §13.5.6) that matches the sum of
the vectors up to another one. Vectors accepted after it are uncertain: queued, not known run.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from conform.diagnosis.facts import Facts, ResumePoint
from conform.families.gve.protocol.checksum import append_checksum, split_checksum

MODAL = ("V", "A", "B", "$", "T", "VL", "XM")
POSITION = ("P", "PF", "P4")
AXES = ("dx", "dy", "dz", "da")


def resume_state(a: Any, f: Facts) -> ResumePoint | None:
    ex = a.exchanges
    if ex is None or a.queue is None:
        return None
    name = ex["name"].to_numpy()
    ok = ((ex["status"].to_numpy() == "answered") & (ex["answer_kind"].to_numpy() == "answer")
          & (ex["code"].to_numpy() == 0))
    vec = np.flatnonzero(ok & np.isin(name, ("C", "L")))
    if not len(vec):
        return None
    frame = ex["frame"].to_numpy()
    d = np.stack([ex[c].to_numpy() for c in AXES], axis=1)[vec].astype(np.int64)
    cum = np.cumsum(d, axis=0)
    end = a.t0 + f.duration
    q = a.queue
    is_done = np.isin(vec, q.done_rows[q.ends <= end + 1e-9])
    k_exec = int(np.flatnonzero(is_done)[-1]) if is_done.any() else -1
    n_done = int(is_done.sum())
    evidence = [f"the queue replay completes {n_done} of {len(vec)} accepted vectors by "
                f"the end of the capture ({f.duration:.3f} s)"]
    # a position read-back overrules the model where it matches a vector's end
    t_cmd = ex["t_cmd_last"].to_numpy()
    for r in np.flatnonzero(ok & np.isin(name, POSITION))[::-1].tolist():
        fields = a.unit_text(int(ex["answer_frame"].iat[r])).split(",")[1:]
        try:
            pos = [int(x) for x in fields]
        except ValueError:
            continue
        before = int(np.searchsorted(t_cmd[vec], t_cmd[r], side="left"))   # sent before it
        width = min(len(pos), cum.shape[1])
        hits = np.flatnonzero((cum[:before, :width] == np.array(pos[:width])).all(axis=1)) \
            if len(pos) <= cum.shape[1] else np.zeros(0, np.int64)
        match = hits.tolist()
        if match:
            k_exec = match[-1]
            evidence.append(f"position read-back `{a.host_text(int(frame[r]))}` -> "
                            f"{','.join(map(str, pos))} at {t_cmd[r] - a.t0:.3f} s matches "
                            f"the end of vector line {int(frame[vec[match[-1]]]) + 1}")
        break
    modal: dict[str, str] = {}
    checksums = False
    for r in np.flatnonzero(ok & np.isin(name, (*MODAL, "%", "J"))).tolist():
        text = a.host_text(int(frame[r])).removesuffix("\\r").rstrip("\r")
        if name[r] in MODAL:
            modal[str(name[r])] = split_checksum(text.encode("latin-1"))[0].decode("latin-1")
        elif name[r] == "%":
            checksums = "%+" in text
        elif name[r] == "J":
            modal.clear()
            checksums = False
    last_ack = int(frame[vec[-1]])
    executed = int(frame[vec[k_exec]]) if k_exec >= 0 else None
    uncertain = [int(frame[v]) for v in vec[k_exec + 1:].tolist()]
    expect = cum[k_exec].tolist() if k_exec >= 0 else [0, 0, 0, 0]
    preamble = [modal[m] for m in MODAL if m in modal] + ["!0P4"]
    if checksums:       # the answer to %+ already carries one (GVE64 §13.3.2)
        preamble = ["!0%+"] + [append_checksum(x.encode()).decode() for x in preamble]
    resume_from = uncertain[0] if uncertain else last_ack + 1
    pos_text = ",".join(str(x) for x in expect[:len(a.variant.axes)])
    cmd = (f"send the preamble; if `!0P4` does not answer 0,{pos_text}, move by the "
           f"difference with one `!0L` vector; then the job from line {resume_from + 1}")
    state = {"modal": modal, "checksums": checksums, "position_counters": expect}
    return ResumePoint(executed, last_ack, uncertain, preamble, resume_from, cmd, evidence,
                       state)
