"""The GVE rules a sender is graded on, each citing the GVE64 manual clause it comes from.

Each rule is a small function of a :class:`conform.sendercheck.session.Session` (the
analysed capture, the emulator's ground truth, the job, the program's exit) returning
(grade, detail, evidence). MUST rules decide the exit code; a SHOULD rule that fails is a
DEVIATION (the engine's grade). The analyser's findings are the evidence on the wire; double
moves and lost vectors are graded from the ground truth alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from conform.families.gve.analysis.frames import CS_BAD, CS_MISSING
from conform.sendercheck.family import FAIL, MUST, PASS, SHOULD, Rule

Result = tuple[str, str, list[str]]
MOTION = ("C", "L")
RESOLVING = ("G", "D", "K")  # after an interrupt: resume, delete, keep (GVE64 §13.5.9)
HAMMER_TRIES = 5  # tries per queue-full run, sent at once, that count as hammering
GAVE_UP = 0.05  # s: a command this long after the previous one waited for its answer


def _msgs(findings: list[Any], limit: int = 5) -> list[str]:
    return [f"{f.kind} @ {f.t:.3f}s: {f.message}" for f in findings[:limit]]


def _no_analysis(s: Any) -> Result | None:
    if s.analysis is None:
        return FAIL, f"the session could not be analysed: {s.analysis_error or 'no capture'}", []
    return None


def terminates(s: Any) -> Result:
    if s.hung:
        return FAIL, (f"still running after the {s.timeout:g} s timeout: stopped "
                      "(SIGTERM, then SIGKILL)"), []
    return PASS, f"ended by itself after {s.duration:.2f} s with exit status {s.exit_code}", []


def simplex(s: Any) -> Result:
    if (r := _no_analysis(s)) is not None:
        return r
    ex = s.analysis.exchanges
    found = s.of_kind("simplex-violation")
    # a command sent after waiting GAVE_UP s for an answer is recovery after a timeout (the
    # answer came late), not a second command in flight
    start, end = ex["t_cmd_first"].to_numpy(), ex["t_cmd_last"].to_numpy()
    late = [f for f in found if f.row is not None and f.row + 1 < len(ex)
            and start[f.row + 1] - end[f.row] >= GAVE_UP]
    n = s.count("simplex-violation") - len(late)
    if n > 0:
        return FAIL, f"{n} command(s) sent before the previous answer had arrived", _msgs(
            [f for f in found if f not in late])
    note = (f"; {len(late)} sent after waiting {GAVE_UP * 1000:.0f} ms or more for an answer "
            "that then came late (a timeout, not counted)") if late else ""
    return PASS, f"{len(ex)} commands, each after the previous answer{note}", []


def checksums(s: Any) -> Result:
    if (r := _no_analysis(s)) is not None:
        return r
    cs = s.analysis.exchanges["cmd_checksum"].to_numpy()
    on = int((cs > 0).sum())
    bad = int(np.isin(cs, (CS_BAD, CS_MISSING)).sum())
    if not on:
        return PASS, "checksums never on (nothing to get wrong)", []
    if bad:
        found = [f for f in s.of_kind("checksum-error") if f.extra.get("direction") == "host"]
        return FAIL, f"{bad} of {on} commands sent while checksums were on had a wrong or " \
                     "missing checksum", _msgs(found)
    return PASS, f"{on} commands with a right checksum", []


def checksums_on_noise(s: Any) -> Result:
    if (r := _no_analysis(s)) is not None:
        return r
    cs = s.analysis.exchanges["cmd_checksum"].to_numpy()
    altered = s.comparison.altered if s.comparison else []
    if not (cs > 0).any():
        more = (f"; {len(altered)} damaged vector(s) were executed as received" if altered
                else "")
        return FAIL, "checksums never turned on on a noisy line: a damaged digit moves the " \
                     f"machine elsewhere{more}", [f"altered: {a}" for a in altered[:5]]
    return PASS, "checksums on", []


def _uncertain_motion(s: Any) -> int:
    ex = s.analysis.exchanges
    return int((ex["uncertain"].to_numpy() & np.isin(ex["name"].to_numpy(), MOTION)).sum()
               + (ex["uncertain"].to_numpy() & (ex["name"].to_numpy() == "*E")).sum())


def _paired_fifo(s: Any) -> str:
    return (" (the sender broke the simplex rule, so answers were paired first in, first out)"
            if s.count("simplex-violation") else "")


def recovery_asks(s: Any) -> Result:
    if (r := _no_analysis(s)) is not None:
        return r
    unc = _uncertain_motion(s)
    if not unc:
        return PASS, "no answer to a vector was garbled or lost in this run", []
    moved = [f for f in s.of_kind("lost-vector") if f.extra.get("confirmed") is False]
    blind = s.of_kind("blind-resend")
    if moved or blind:
        return FAIL, (f"{unc} vector(s) got a garbled answer or none; {len(blind)} resent and "
                      f"{len(moved)} passed over without asking `>` or `@`{_paired_fifo(s)}"), \
            _msgs(blind + moved)
    misused = _index_before_repeat(s)
    if misused:
        return FAIL, ("`@` asked before `>` after an uncertain vector: `>` then repeats the "
                      "`@`, not the vector"), misused[:5]
    used = s.count("repeat-used") + s.count("index-checked")
    return PASS, f"{unc} uncertain vector answer(s), each followed by `>` or `@` ({used} " \
                 "recoveries seen)", []


def _index_before_repeat(s: Any) -> list[str]:
    """Uncertain vectors after which the sender asked `@` and only then `>`."""
    ex = s.analysis.exchanges
    name = ex["name"].to_numpy()
    motion = np.flatnonzero(np.isin(name, MOTION + ("*E",)))
    unc = motion[ex["uncertain"].to_numpy()[motion]]
    out = []
    for r in unc.tolist():
        k = int(np.searchsorted(motion, r)) + 1
        hi = int(motion[k]) if k < len(motion) else len(name)
        seg = [n for n in name[r + 1:hi] if n in ("@", ">")]
        if "@" in seg and ">" in seg and seg.index("@") < seg.index(">"):
            out.append(f"host:{r} `{name[r]}` uncertain, then " + " ".join(seg[:4]))
    return out


def no_blind_resend(s: Any) -> Result:
    if (r := _no_analysis(s)) is not None:
        return r
    n = s.count("blind-resend")
    if n:
        return FAIL, f"{n} vector(s) sent again after a garbled answer or none, without " \
                     f"asking `>`/`@` whether the first copy arrived{_paired_fifo(s)}", \
            _msgs(s.of_kind("blind-resend"))
    return PASS, "no vector sent again blindly", []


def vectors_exact(s: Any) -> Result:
    c = s.comparison
    if c is None:
        return FAIL, "no ground truth", []
    bad = c.doubles + c.extras + c.lost
    if not bad and not (c.altered and not _checksums_used(s)):
        if c.altered:
            return FAIL, f"{len(c.altered)} vector(s) accepted other than sent although " \
                         "checksums were on", [str(a) for a in c.altered[:5]]
        return PASS, c.summary() + ("; the rest deleted after the interrupt" if c.accepted
                                    < c.job else ""), []
    ev = [f"double: {d}" for d in c.doubles[:5]] + [f"extra: {d}" for d in c.extras[:3]] + \
         [f"lost: {d}" for d in c.lost[:5]]
    if not bad:  # only vectors altered on the wire, checksums off: graded by the noise rule
        return PASS, c.summary() + " (altered vectors: see the checksum rule)", ev
    return FAIL, c.summary() + " (ground truth: the unit's own record)", ev


def _checksums_used(s: Any) -> bool:
    if s.analysis is None:
        return False
    return bool((s.analysis.exchanges["cmd_checksum"].to_numpy() > 0).any())


def queue_full_paced(s: Any) -> Result:
    if (r := _no_analysis(s)) is not None:
        return r
    polls = s.of_kind("queue-full-polling")
    if not polls:
        return PASS, "the unit never answered 1 (queue full)", []
    f = polls[0]
    gap = f.extra.get("median_retry_gap_s", float("nan"))
    share = f.extra.get("share_of_host_bytes", 0.0)
    detail = (f"{f.extra.get('polls')} tries answered 1 in {f.extra.get('runs')} run(s); "
              f"median {gap * 1000:.1f} ms between the answer and the next try; retries are "
              f"{share:.0%} of the bytes sent")
    tries = f.extra.get("polls", 0) / max(f.extra.get("runs", 1), 1)
    if (f.extra.get("pattern") == "immediate" and tries >= HAMMER_TRIES) or share > 0.5:
        return FAIL, "hammering: " + detail, _msgs(polls)
    return PASS, detail, []


def queue_fed(s: Any) -> Result:
    acc = s.truth.get("accepted", [])
    if not acc:
        return FAIL, "no vector accepted", []
    starved = [a for a in acc if a.get("starved")]
    share = len(starved) / len(acc)
    detail = (f"{len(starved)} of {len(acc)} vectors started from rest because the queue had "
              "run dry (the unit's motion model)")
    if s.analysis is not None and s.analysis.queue is not None:
        detail += f"; the analyser's replay counts {s.count('starvation')} starvation(s)"
    if share > 0.05:
        return FAIL, detail, [f"vector {a['index']} at {a['t']:.3f}s" for a in starved[:5]]
    return PASS, detail, []


def _interrupt_rows(s: Any) -> tuple[Any, int | None]:
    ex = s.analysis.exchanges
    hit = np.flatnonzero(ex["inta"].to_numpy() & (ex["status"].to_numpy() == "answered"))
    return ex, (int(hit[0]) if len(hit) else None)


def interrupt_stops(s: Any) -> Result:
    if (r := _no_analysis(s)) is not None:
        return r
    ex, first = _interrupt_rows(s)
    if first is None:
        return FAIL, "the stop input was pressed but no answer the program got showed INTA " \
                     "(did the job end first?)", [str(e) for e in s.events]
    names = ex["name"].to_numpy()
    after = names[first + 1:]
    stop_at = next((k for k, n in enumerate(after) if n in RESOLVING), len(after))
    sent = [first + 1 + k for k in range(stop_at) if after[k] in MOTION]
    if sent:
        return FAIL, (f"INTA first answered to host:{first}; {len(sent)} more vector(s) sent "
                      f"before G, D or K"), [f"host:{r} {names[r]}" for r in sent[:5]]
    how = names[first + 1 + stop_at] if stop_at < len(after) else "nothing"
    return PASS, f"INTA first answered to host:{first}; no vector sent until `{how}`", []


def interrupt_resolved(s: Any) -> Result:
    fin = s.truth.get("final", {})
    ev = [e for e in s.truth.get("events", []) if e["command"] in ("G", "D", "K", "R", "H")]
    used = ", ".join(f"{e['command']}→{e['code']}" for e in ev[:8]) or "none"
    if fin.get("inta") and fin.get("queue"):
        return FAIL, (f"the program ended with the unit interrupted and {fin['queue']} "
                      f"vector(s) still queued (neither G nor D); commands: {used}"), []
    return PASS, f"interrupt resolved; G/D/K/R/H answers: {used}", []


def interrupt_krd_idle(s: Any) -> Result:
    ev = s.truth.get("events", [])
    refused: list[str] = []
    if s.analysis is not None:  # refused while running: the handler never ran, the wire shows it
        ex = s.analysis.exchanges
        rows = np.flatnonzero(np.isin(ex["name"].to_numpy(), ("K", "R", "D"))
                              & (ex["code"].to_numpy() == 7))
        refused = [f"host:{r} {ex['name'].iat[r]} answered 7" for r in rows.tolist()]
    keeps = 0
    twice = False
    for e in ev:
        if e["code"] != 0:
            continue
        if e["command"] == "K":
            keeps += 1
            twice |= keeps > 1
        elif e["command"] == "R":
            keeps = 0
    if twice:
        return FAIL, "K sent twice without R in between (KEEP without RESTORE only once)", []
    if refused:
        return FAIL, f"{len(refused)} K/R/D sent while the unit was still running (answered " \
                     "7); read F or SR6 until RUN is clear first", refused[:5]
    return PASS, "K/R/D only when the unit was at rest", []


def link_resumes(s: Any) -> Result:
    c = s.comparison
    if c is None:
        return FAIL, "no ground truth", []
    if c.accepted >= c.job and not c.lost:
        return PASS, "after the line came back the program finished the job", []
    return FAIL, f"after the line came back the job was not finished: {c.summary()}", []


def honest_exit(s: Any) -> Result:
    c = s.comparison
    if s.hung or c is None:
        return PASS, "graded by the timeout rule", []
    complete = c.exact and c.accepted == c.job
    if s.exit_code == 0 and not complete:
        return FAIL, f"exit status 0 although the job was not delivered exactly ({c.summary()})", []
    if s.exit_code != 0 and complete:
        return FAIL, f"exit status {s.exit_code} although every vector was delivered", []
    return PASS, f"exit status {s.exit_code}; {c.summary()}", []


def _tag(tag: str) -> Any:
    return lambda scn: tag in scn.tags


RULES: tuple[Rule, ...] = (
    Rule("terminates", "the program ends by itself within the timeout",
         "none (harness rule: a run must end)", MUST, terminates),
    Rule("simplex", "strictly simplex: one command, then wait for its answer",
         "GVE64 §13.3.1", MUST, simplex),
    Rule("checksums", "checksums right while they are on", "GVE64 §13.3.2", MUST, checksums),
    Rule("checksums-on-noise", "checksums used on a noisy line", "GVE64 §13.3.2", SHOULD,
         checksums_on_noise, _tag("noise")),
    Rule("recovery-asks", "after a garbled or lost answer to a vector, `>` or `@` before "
         "resending or going on", "GVE64 §13.5.13", MUST, recovery_asks),
    Rule("no-blind-resend", "no vector sent again without knowing the first did not arrive",
         "GVE64 §13.5.13 (`@`: positions must not be repeated blindly)", MUST, no_blind_resend),
    Rule("vectors-exact", "no double move and no lost vector (ground truth)",
         "GVE64 §13.5.2 (vectors are relative), §13.7 code 1", MUST, vectors_exact),
    Rule("queue-full-paced", "queue full (1) answered by waiting and sending again, "
         "without hammering", "GVE64 §13.7 code 1, §13.5.2", SHOULD, queue_full_paced),
    Rule("queue-fed", "the vector queue kept fed (no starvation between C vectors)",
         "GVE64 §13.5.2 (CONT. vectors join only when queued), §13.3.3 (packets on USB)",
         SHOULD, queue_fed, _tag("fed")),
    Rule("interrupt-stops", "after an answer with INTA, no more vectors until G, D or K",
         "GVE64 §13.5.12, §13.7 (INTA bit)", MUST, interrupt_stops, _tag("stop")),
    Rule("interrupt-resolved", "the interrupted queue is resumed (G) or deleted (D)",
         "GVE64 §13.5.9", MUST, interrupt_resolved, _tag("stop")),
    Rule("interrupt-krd-idle", "K, R and D only at rest; K at most once without R",
         "GVE64 §13.5.9", SHOULD, interrupt_krd_idle, _tag("stop")),
    Rule("link-resumes", "after a lost link the program recovers and finishes the job",
         "GVE64 §13.5.13", SHOULD, link_resumes, _tag("link")),
    Rule("honest-exit", "exit status 0 exactly when every vector was delivered once",
         "GVE64 §13.5.2", SHOULD, honest_exit, lambda scn: "stop" not in scn.tags),
)
