import pytest
from rewrite_cache import leave_plugins_alone, rewrite_for_workers

leave_plugins_alone()     # before anything of conform's is imported here (rewrite_cache.py)


@pytest.fixture(scope="session")
def spec():
    from conform.families.gve.spec import load_spec

    return load_spec()


@pytest.fixture(scope="session")
def marlin_mutant_report():
    """Every Marlin deviant unit through the checks (what `conform run --mutants` runs), on the
    variant with the most checks: swept once for the tests that read it (they run in one
    worker: pytest_collection_modifyitems)."""
    from conform.families.marlin import FAMILY

    return FAMILY.run_mutants(["marlin-2.1-adv"])


# fixtures of session scope that build something costly: their tests run in one worker
SHARED = ("marlin_mutant_report",)


@pytest.fixture
def emulate():
    """Start ``conform emulate ARGS...``; returns (process, device path). Stopped with SIGTERM at
    the end of the test (killed if it does not stop); its exit code and stderr are then in
    ``process.returncode`` and ``process.stderr_text``."""
    import signal
    import subprocess
    import sys

    procs = []

    def start(*args: str):
        proc = subprocess.Popen([sys.executable, "-m", "conform", "emulate", *args],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(proc)
        path = proc.stdout.readline().strip()
        assert path, proc.stderr.read()
        return proc, path

    yield start
    for proc in procs:
        stop_emulator(proc, signal.SIGTERM)


def stop_emulator(proc, sig) -> None:
    import subprocess

    if proc.returncode is None:
        proc.send_signal(sig)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    if not hasattr(proc, "stderr_text"):
        proc.stderr_text = proc.stderr.read()


# what a test that needs a real sender program says when it skips (README.md, "Tests with real
# senders"): on a developer's machine such a test skips; in CI, where .ci/run installs them,
# the skip is a failure, so a missing install step cannot pass unseen
REAL_SENDERS = ("CONFORM_OCTOPRINT_PYTHON", "printrun not installed", "CONFORM_BCNC_PYTHON")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    import os

    outcome = yield
    report = outcome.get_result()
    if report.skipped and os.environ.get("CI") == "true" and any(
            word in str(report.longrepr) for word in REAL_SENDERS):
        report.outcome = "failed"


# -- running side by side (pytest-xdist, pyproject.toml's addopts) -----------------------------

def pytest_configure(config):
    """Started as `python -m pytest &` from a script, the suite (and each worker) inherits
    SIGINT ignored, and Python then leaves Ctrl-C without its KeyboardInterrupt: the tests
    that interrupt a run in-process need it back. The controller rewrites the test modules'
    asserts once for all the workers (rewrite_cache.py)."""
    import signal
    from pathlib import Path

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if not hasattr(config, "workerinput") and config.getoption("numprocesses", None):
        rewrite_for_workers(config, Path(__file__).parent)   # once, before the workers start


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Tests of a module that builds something once for the module (a fixture of module
    scope: a mutant report, a browser, a recorded storm) run in one worker, so that it is
    built once, and so do the tests of a costly session fixture (SHARED); and the slow tests
    (ptys, subprocesses, real clocks) start first, the longest of all (``long``) first of
    them, so that the run does not end waiting on one of them."""
    for item in items:
        info = getattr(item, "_fixtureinfo", None)
        defs = info.name2fixturedefs.values() if info is not None else ()
        shared = [name for name in SHARED if name in getattr(item, "fixturenames", ())]
        if shared:
            item.add_marker(pytest.mark.xdist_group(shared[0]))
        elif any(d[-1].scope == "module" for d in defs if d):
            item.add_marker(pytest.mark.xdist_group(item.module.__name__))
    items.sort(key=lambda item: (-_seconds(item), item.get_closest_marker("slow") is None))


def _seconds(item) -> float:
    """What a ``long`` test's mark says it takes on a quiet machine: the longest start first,
    one to a worker, while the short ones fill the gaps (pyproject.toml keeps xdist from
    reordering the groups by their size)."""
    mark = item.get_closest_marker("long")
    return float(mark.args[0]) if mark is not None else 0.0
