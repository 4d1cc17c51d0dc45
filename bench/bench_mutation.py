"""Mutation score of each family's reference unit: mutants of ``conform/families/<f>/unit/``
made by cosmic-ray's operators, each run against the conformance checks (in-process, full
profile, every opt-in, no state machine), against the target of 90 % killed.

    pip install -e '.[mutation]'
    python bench/bench_mutation.py [--family gve|grbl|marlin ...] [--sample N] [--seed S]
                                   [--jobs J] [--out DIR] [--all-files] [--every-variant]
                                   [--every-alternative]
                                   [--mutant ID ...]

A mutant is KILLED when the run reports a FAIL or an ERROR, stops, crashes or runs out of
time (10x the unmutated run's CPU time); it SURVIVED when the run passes as the unmutated
one does. ``--sample N`` mutants per family are drawn with ``--seed`` from all mutation points
of the unit modules the unmutated run imports and whose functions the emulator's unit runs (a
module only the suite's side runs, such as grbl's adopt.py, is left out and named;
``--all-files``: every file in unit/, the control socket's and fault injection's too;
``--every-variant``: each mutant is tested by every variant's checks in turn, each on its own
emulator, so that code only a build with some option runs is reached too;
``--every-alternative``: each mutant is also tested under the family's open-question
alternatives (GVE's A1..A29: a few dialects that together hold every alternative, each run
with reference and emulator in that dialect), so that code only another dialect runs is
reached too). Equivalent mutants
are listed, each with why, in
``<out>/<family>-equivalent.toml`` and left out of the denominator:
score = killed / (sampled - equivalent). Written per family: ``<family>-survivors.txt`` (each
survivor's id and changed line) and ``<family>-results.json`` (every mutant). ``--mutant ID``
runs just those mutants (ids as in the survivors file) and prints each one's outcome.
Ids and the triage file's format: bench/mutation_lib.py and docs/conformance.md.
"""

from __future__ import annotations

import argparse
import json
import random
import resource
import subprocess
import sys
import time
import warnings
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from mutation_lib import (  # noqa: E402
    FAMILIES,
    ROOT,
    Point,
    TriageError,
    enumerate_points,
    family_dir,
    line_diff,
    load_equivalent,
    match_key,
    module_name,
    mutated_source,
)

TARGET = 0.90
TIMEOUT_FACTOR = 10
CHILD = [sys.executable, str(Path(__file__).resolve().parent / "mutation_lib.py"), "--child"]


def fail(text: str) -> None:
    print(f"bench_mutation: {text}", file=sys.stderr)
    sys.exit(2)


def run_child(job: dict, wall_limit: float) -> dict:
    try:
        r = subprocess.run(CHILD, input=json.dumps(job), capture_output=True, text=True,
                           timeout=wall_limit, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return {"outcome": "timeout", "why": f"no result within {wall_limit:.0f} s"}
    if r.returncode == -24:   # SIGXCPU: the CPU limit
        return {"outcome": "timeout", "why": f"CPU limit {job.get('cpu_limit')} s"}
    lines = r.stdout.strip().splitlines()
    if r.returncode != 0 or not lines:
        tail = (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]
        return {"outcome": "crashed", "why": tail[:200]}
    out = json.loads(lines[-1])
    if out.get("loaded") is False:
        out |= {"outcome": "unreached", "why": "the run never imported the module"}
    elif out["failed"]:
        out |= {"outcome": "killed", "why": out["failed"]}
    else:
        out |= {"outcome": "survived", "why": ""}
    return out


def baseline(family: str, reach: dict[str, bool]) -> tuple[dict, float]:
    """The unmutated runs: the plain one (which unit modules it imports), then the one whose
    emulator runs the copy of those modules, which must pass as well (its CPU time sets the
    timeout)."""
    plain = run_child({"family": family, "stop": False} | reach,
                      wall_limit=900)
    if plain.get("outcome") != "survived":
        fail(f"{family}: the unmutated run does not pass ({plain.get('why')}); mutants cannot be "
             "judged against it")
    t0 = time.perf_counter()
    out = run_child({"family": family, "stop": False, "shadow": True,
                     "modules": plain["unit_modules"]} | reach,
                    wall_limit=900)
    wall = time.perf_counter() - t0
    if out.get("outcome") != "survived" or out.get("not_pass") != plain.get("not_pass"):
        fail(f"{family}: the run against the unit's unmutated copy does not pass as the plain run "
             f"does ({out.get('why') or out.get('not_pass')}); the copy is not faithful")
    if out.get("not_pass"):
        print(f"  {family}: unmutated run grades other than PASS: {out['not_pass']}")
    traced = run_child({"family": family, "stop": False, "shadow": True, "trace": True,
                        "modules": plain["unit_modules"]} | reach,
                       wall_limit=900)
    if traced.get("outcome") != "survived":
        fail(f"{family}: the traced run of the unit's copy does not pass ({traced.get('why')})")
    return out | {"unit_modules": plain["unit_modules"], "unit_ran": traced["unit_ran"]}, wall


def unit_files(family: str, base: dict, all_files: bool
               ) -> tuple[list[Path], list[str], list[str]]:
    """The files mutated; those the run never imports; those it imports for the suite's own
    side only (none of their functions runs in the emulator's unit: a mutant there could never
    be seen by any check, as the unit under test does not run it)."""
    files = sorted((family_dir(family) / "unit").glob("*.py"))
    if all_files:
        return files, [], []
    loaded, ran = set(base["unit_modules"]), set(base["unit_ran"])
    unloaded = [p.name for p in files if module_name(p) not in loaded]
    unrun = [p.name for p in files if module_name(p) in loaded and module_name(p) not in ran
             and p.name != "__init__.py"]
    kept = [p for p in files if p.name not in unloaded and p.name not in unrun]
    return kept, unloaded, unrun


def judge(family: str, points: list[Point], cpu_limit: int, jobs: int, modules: list[str],
          reach: dict[str, bool]) -> list[dict]:
    """Run each point's mutant in its own interpreter; one record per point."""
    records: list[dict] = []

    def one(point: Point) -> dict:
        code = mutated_source(point)
        original = point.path.read_text()
        rec = {"id": point.id, "diff": line_diff(original, code) if code else []}
        if code is None or code == original:
            return rec | {"outcome": "invalid", "why": "the operator changed nothing"}
        try:
            compile(code, str(point.path), "exec", dont_inherit=True)
        except SyntaxError as exc:
            return rec | {"outcome": "invalid", "why": f"not Python: {exc.msg}"}
        job = {"family": family, "shadow": True, "modules": modules,
               "module": module_name(point.path), "code": code, "cpu_limit": cpu_limit} | reach
        out = run_child(job, wall_limit=cpu_limit * 10 + 60)   # the CPU limit judges; this catches a stuck child
        return rec | {k: out.get(k) for k in ("outcome", "why", "not_pass", "cpu_s")}

    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        for n, rec in enumerate(pool.map(one, points), 1):
            records.append(rec)
            if n % 10 == 0 or n == len(points):
                print(f"  {family}: {n}/{len(points)} mutants in {time.perf_counter() - t0:.0f} s",
                      file=sys.stderr, flush=True)
    return records


def write_outputs(out_dir: Path, family: str, records: list[dict], equivalent: dict[str, str],
                  meta: dict) -> None:
    survivors = [r for r in records if r["outcome"] in ("survived", "unreached")
                 and match_key(r["id"]) not in equivalent]
    lines = [f"# {family}: {len(survivors)} surviving mutants not listed as equivalent "
             f"(sample {meta['sampled']}, seed {meta['seed']}); triage: list an equivalent one in "
             f"{family}-equivalent.toml with why, or give the suite a check that kills it.", ""]
    for r in sorted(survivors, key=lambda r: (r["id"].split(":")[0], int(r["id"].split(":")[1]))):
        lines.append(r["id"] + ("  (module never imported)" if r["outcome"] == "unreached" else ""))
        lines += [f"    {d}" for d in r["diff"]]
        if r.get("not_pass"):
            lines.append(f"    grades other than PASS: {r['not_pass']}")
        lines.append("")
    (out_dir / f"{family}-survivors.txt").write_text("\n".join(lines))
    doc = meta | {"mutants": sorted(records, key=lambda r: r["id"])}
    (out_dir / f"{family}-results.json").write_text(json.dumps(doc, indent=1) + "\n")


def bench_family(family: str, args: argparse.Namespace, out_dir: Path) -> dict:
    triage = out_dir / f"{family}-equivalent.toml"
    try:
        equivalent = load_equivalent(triage)
    except TriageError as exc:
        fail(str(exc))
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    reach = {"every_variant": args.every_variant, "every_alternative": args.every_alternative}
    base, base_wall = baseline(family, reach)
    cpu_limit = max(10, int(TIMEOUT_FACTOR * base["cpu_s"] + 0.999) + 2)
    files, skipped, suite_side = unit_files(family, base, args.all_files)
    left_out: Counter[str] = Counter()
    points = enumerate_points(files, family, left_out)
    by_key = {p.key: p for p in points}
    stale = sorted(k for k in equivalent if k not in by_key)
    for k in stale:
        print(f"  {family}: triage entry {k} matches no mutation point (its line changed?)")
    if args.mutant:
        chosen = [by_key[match_key(m)] for m in args.mutant if match_key(m) in by_key]
        args.matched.update(p.key for p in chosen)
    else:
        chosen = random.Random(args.seed).sample(points, min(args.sample, len(points)))
    print(f"{family}: {len(points)} mutation points in {len(files)} files (left out, as they "
          f"cannot change what the unit does: {dict(left_out) or 'none'})"
          + (f"; files left out, not imported by the run: {', '.join(skipped)}" if skipped else "")
          + (f"; files left out, imported by the suite but none of their code runs in the "
             f"emulator's unit: {', '.join(suite_side)}" if suite_side else "")
          + f"; unmutated run {base['checks']} checks, {base['cpu_s']:.2f} s CPU; "
          f"timeout {cpu_limit} s CPU")
    records = judge(family, chosen, cpu_limit, args.jobs, base["unit_modules"], reach)
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime)
    count = {k: sum(1 for r in records if r["outcome"] == k)
             for k in ("killed", "crashed", "timeout", "survived", "unreached", "invalid")}
    equiv = [r for r in records if r["outcome"] == "survived" and match_key(r["id"]) in equivalent]
    for r in records:
        if r["outcome"] in ("killed", "crashed", "timeout") and match_key(r["id"]) in equivalent:
            print(f"  {family}: {r['id']} is listed as equivalent but was killed ({r['why']})")
    killed = count["killed"] + count["crashed"] + count["timeout"]
    by_fail = sum(1 for r in records if r["outcome"] == "killed" and r["why"].startswith("FAIL"))
    judged = len(records) - count["invalid"] - len(equiv)
    score = killed / judged if judged else 0.0
    res = {"sampled": len(records), "killed": killed, "killed_by_fail": by_fail,
           "killed_by_error": count["killed"] - by_fail, "crashed": count["crashed"],
           "timed_out": count["timeout"], "survived": count["survived"] + count["unreached"],
           "unreached": count["unreached"], "invalid": count["invalid"],
           "equivalent": len(equiv), "score": round(score, 4),
           "score_ratio": round(score / TARGET, 4), "points": len(points),
           "cpu_s": round(cpu, 1), "wall_s": round(time.perf_counter() - t0, 1),
           "cpu_per_mutant_s": round(cpu / max(1, len(records)), 2),
           "points_left_out": dict(left_out), "files_not_imported": skipped,
           "files_suite_side": suite_side,
           "baseline_cpu_s": base["cpu_s"], "baseline_wall_s": round(base_wall, 2)} | reach
    if not args.mutant:
        write_outputs(out_dir, family, records, equivalent,
                      {"family": family, "seed": args.seed, "sampled": len(records)} | res)
    print(f"{family}: sampled {res['sampled']}, killed {killed} (by a FAIL {by_fail}, an ERROR "
          f"{res['killed_by_error']}, crashed {count['crashed']}, timed out {count['timeout']}), "
          f"survived {res['survived']}, "
          f"equivalent {len(equiv)}, invalid {count['invalid']}: score {score:.1%} "
          f"({res['score_ratio']:.2f} of the {TARGET:.0%} target); {cpu:.0f} s CPU "
          f"({res['cpu_per_mutant_s']} s per mutant), {res['wall_s']:.0f} s wall")
    if args.mutant:
        for r in records:
            print(f"  {r['outcome'].upper()} {r['id']}  {r['why'] or ''}")
            for d in r["diff"]:
                print(f"      {d}")
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", action="append", choices=FAMILIES,
                    help="family to mutate (repeatable; default: all three)")
    ap.add_argument("--sample", type=int, default=300, help="mutants per family (default 300)")
    ap.add_argument("--seed", type=int, default=1, help="seed of the sample (default 1)")
    ap.add_argument("--jobs", type=int, default=2, help="mutants run side by side (default 2)")
    ap.add_argument("--out", default=str(ROOT / "bench" / "mutation"),
                    help="folder of the survivors, results and triage files (default bench/mutation)")
    ap.add_argument("--all-files", action="store_true",
                    help="also mutate unit/ files the unmutated run never imports")
    ap.add_argument("--every-variant", action="store_true",
                    help="test each mutant with every variant's checks, each on its own "
                         "emulator (code that only a build with some option runs is reached)")
    ap.add_argument("--every-alternative", action="store_true",
                    help="also test each mutant under the open questions' other alternatives "
                         "(a few dialects that together hold each one; families without open "
                         "questions: no effect), reference and emulator alike")
    ap.add_argument("--mutant", action="append", default=[], metavar="ID",
                    help="run only this mutant (an id from a survivors file; repeatable)")
    args = ap.parse_args(argv)
    warnings.filterwarnings("ignore", category=SyntaxWarning)   # a mutant's `x is 0` compiles
    if args.sample <= 0 or args.jobs <= 0:
        fail("--sample and --jobs must be positive")
    try:
        import cosmic_ray  # noqa: F401
    except ImportError:
        fail("cosmic-ray is not installed: pip install -e '.[mutation]'")
    for m in args.mutant:
        try:
            match_key(m)
        except ValueError as exc:
            fail(f"--mutant: {exc}")
    families = args.family or list(FAMILIES)   # --mutant: each id runs in the family it matches
    args.matched = set()
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = {f: bench_family(f, args, out_dir) for f in families}
    summary = {"families": results, "sample": args.sample, "seed": args.seed, "jobs": args.jobs,
               "target": TARGET, "profile": "full", "all_files": args.all_files,
               "every_variant": args.every_variant, "every_alternative": args.every_alternative,
               "met": all(r["score"] >= TARGET for r in results.values())}
    print(json.dumps(summary))
    unmatched = [m for m in args.mutant if match_key(m) not in args.matched]
    if unmatched:
        fail(f"--mutant {unmatched[0]}: no mutation point of {', '.join(families)} has this id "
             "(its line changed, or another family's?)")
    return 0 if summary["met"] else 1


if __name__ == "__main__":
    sys.exit(main())
