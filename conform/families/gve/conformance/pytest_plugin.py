"""GVE's pytest plugin: ``pytest --conform-target=URL --conform-variant=V`` runs the GVE
conformance checks as test items (usual pass/fail/skip, ``--junitxml`` output). Without
``--conform-target`` it adds nothing. Loaded by the engine's plugin,
``conform.conformance.pytest_plugin`` (the ``pytest11`` entry point ``conform``), from the
family registry (``Family.pytest_plugin``).

A unit's FAIL fails the item; a harness ERROR is raised during setup, so pytest (and JUnit)
report it as an error; SKIPPED and NOT-APPLICABLE checks are skipped; a DEVIATION passes and is
recorded in the item's properties.

Items sit in one node per variant and manual section: ``gve64-v19/13.5.3::V/valid``, so JUnit's
classname is ``gve64-v19.13.5.3`` and ``-k 13.5.3`` (or ``-k "13.5.3 and V"``, ``-k INFO``)
selects by clause. A bad target or variant is one ``ERROR:`` line and exit status 4.
"""

from __future__ import annotations

from typing import Any

import pytest

_STATE = pytest.StashKey[dict]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("conform", "GVE conformance checks")
    group.addoption("--conform-target", default=None, metavar="T",
                    help="emu:VARIANT, a device path, pty or pyserial URL: run the checks on it")
    group.addoption("--conform-variant", default=None, metavar="V",
                    help="the model expected (default: the emulator's, else ask '?')")
    group.addoption("--conform-profile", default="quick", choices=("quick", "full"))
    group.addoption("--conform-check", action="append", default=[], metavar="GLOB",
                    help="only checks whose id matches (repeatable)")
    group.addoption("--conform-baud", type=int, default=115200)
    group.addoption("--conform-seed", type=int, default=0)
    group.addoption("--conform-allow-motion", action="store_true")
    group.addoption("--conform-max-steps", type=int, default=None)


class ConformFailure(Exception):
    """The unit broke what the manual states (a FAIL)."""


class ConformSection(pytest.Collector):
    """The checks of one variant and manual section (``gve64-v19/13.5.3``)."""

    def collect(self) -> list[pytest.Item]:
        return []  # items are added by pytest_collection_modifyitems

    def reportinfo(self) -> tuple[str, int, str]:
        return ("conform", 0, self.name)


class ConformItem(pytest.Item):
    def __init__(self, *, check: Any, **kw: Any) -> None:
        super().__init__(**kw)
        self.check = check
        self.result: Any = None
        self.user_properties.append(("id", check.id))
        self.user_properties.append(("clause", check.clause))
        self.user_properties.append(("level", check.level))
        self.extra_keyword_matches.update({check.level, check.kind})

    def setup(self) -> None:
        from conform.conformance.results import Grade

        runner = _runner(self.config)
        self.result = runner.run_check(self.check)
        self.user_properties.append(("grade", self.result.grade.value))
        if self.result.grade is Grade.ERROR:
            raise RuntimeError(f"harness error: {self.result.detail}")
        if self.result.grade in (Grade.SKIPPED, Grade.NOT_APPLICABLE):
            pytest.skip(f"{self.result.grade.value}: {self.result.detail}")

    def runtest(self) -> None:
        from conform.conformance.results import Grade

        r = self.result
        if r.grade is Grade.DEVIATION:
            self.user_properties.append(("deviation", r.detail))
        if r.grade is Grade.FAIL:
            raise ConformFailure(r)

    def repr_failure(self, excinfo: Any, style: Any = None) -> str:
        if isinstance(excinfo.value, ConformFailure):
            r = excinfo.value.args[0]
            lines = [f"{r.id} [{r.clause}]", f"  expected: {r.expected}", f"  actual:   {r.actual}",
                     f"  {r.detail}", f"  replay: conform run --target {r.target} "
                     f"--variant {r.variant} --replay '{r.replay}'", "  sequence:"]
            lines += [f"    {s}" for s in r.sequence]
            return "\n".join(lines)
        return super().repr_failure(excinfo)

    def reportinfo(self) -> tuple[str, int, str]:
        return ("conform", 0, f"{self.check.id} ({self.check.clause})")


def _runner(config: pytest.Config) -> Any:
    state = config.stash[_STATE]
    if "runner" not in state:
        from conform.conformance.runner import RunOptions
        from conform.families.gve.conformance.runner import Runner

        state["runner"] = Runner(state["spec"], state["target"], state["variant"],
                                 options=RunOptions(profile=config.getoption("conform_profile"),
                                                    seed=config.getoption("conform_seed")))
    return state["runner"]


def _section_name(check: Any) -> str:
    """``gve64-v19/13.5.3/V/valid`` → ``gve64-v19/13.5.3``."""
    parts = check.id.split("/")
    return "/".join(parts[:2]) if len(parts) > 2 else check.variant


def _usage(what: Any) -> pytest.UsageError:
    return pytest.UsageError(f"conform: {what}")


def pytest_configure(config: pytest.Config) -> None:
    """Check the options before anything is collected: a mistake is one usage line."""
    target_text = config.getoption("conform_target", None)
    if not target_text:
        return
    from conform.conformance.target import parse_target
    from conform.errors import UserError
    from conform.families.gve.spec import load_spec

    try:
        spec = load_spec()
        kind, what, mutant = parse_target(target_text)
        if kind == "emu" and what is not None:
            spec.variant(what)
        if mutant is not None:
            from conform.families.gve.conformance.mutants import MUTANTS

            if mutant not in MUTANTS:
                raise UserError(f"--conform-target {target_text}: no mutant {mutant!r}")
        variant = config.getoption("conform_variant")
        if variant is not None:
            spec.variant(variant)
    except UserError as exc:
        raise _usage(exc) from None
    for name, flag in (("conform_baud", "--conform-baud"),
                       ("conform_max_steps", "--conform-max-steps")):
        value = config.getoption(name)
        if value is not None and value <= 0:
            raise _usage(f"{flag} {value}: must be a positive number")
    if config.getoption("conform_allow_motion") and config.getoption("conform_max_steps") is None:
        raise _usage("--conform-allow-motion needs --conform-max-steps")


@pytest.hookimpl(tryfirst=True)  # before -k/-m deselect, so that they apply to the checks
def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config,
                                  items: list[pytest.Item]) -> None:
    target_text = config.getoption("conform_target")
    if not target_text:
        return
    from conform.conformance.target import parse_target
    from conform.errors import UserError
    from conform.families.gve.conformance.safety import Guard
    from conform.families.gve.conformance.suite import suite
    from conform.families.gve.conformance.target import identify, open_target
    from conform.families.gve.spec import load_spec

    spec = load_spec()
    kind, _, _ = parse_target(target_text)
    motion = config.getoption("conform_allow_motion")
    max_steps = config.getoption("conform_max_steps")
    guard = Guard.emulated() if kind == "emu" else Guard(motion, max_steps, False)
    try:
        target, implied = open_target(target_text, spec, baud=config.getoption("conform_baud"),
                                      guard=guard)
    except UserError as exc:
        raise _usage(exc) from None
    config.stash[_STATE] = {"spec": spec, "target": target}
    variant = config.getoption("conform_variant") or implied
    if variant is None:
        variant, _ = identify(target, spec)
    config.stash[_STATE]["variant"] = variant
    sections: dict[str, ConformSection] = {}
    for check in suite(spec, variant, patterns=config.getoption("conform_check"), guard=guard,
                       profile=config.getoption("conform_profile")):
        name = _section_name(check)
        parent = sections.get(name)
        if parent is None:
            parent = sections[name] = ConformSection.from_parent(session, name=name,
                                                                  nodeid=name)
        items.append(ConformItem.from_parent(parent, name=check.key, check=check))


def pytest_unconfigure(config: pytest.Config) -> None:
    state = config.stash.get(_STATE, None)
    if state and "target" in state:
        target = state["target"]
        if not target.emulated and target.guard.allow_motion:
            target.safe_stop()  # H, D, O0,FF (GVE64 §13.5.9)
        target.close()
