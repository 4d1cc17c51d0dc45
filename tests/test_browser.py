"""The reports in a real browser: headless Chromium (Debian's ``chromium`` and
``chromium-driver``) loads the conformance and the analysis report without a console error, and
the first screen shows the summary and the first failure.

Off CI the test skips only when Chromium is not installed; in CI (``CI=true``) a missing
Chromium fails it (``.ci/run`` installs it). ``CONFORM_SCREENSHOTS=DIR`` keeps the screenshots.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest

from conform.cli.main import main

REPO = Path(__file__).resolve().parent.parent
WIDTH, HEIGHT = 1280, 900  # a laptop's browser window: "the first screen"

pytestmark = pytest.mark.slow


def _find(*names: str) -> str | None:
    for name in names:
        found = shutil.which(name) or (name if os.path.exists(name) else None)
        if found:
            return found
    return None


def _chromium() -> tuple[str, str]:
    """Chromium and its driver; skip when they are not installed, fail when in CI."""
    chromium = _find("chromium", "chromium-browser", "/usr/lib/chromium/chromium")
    driver_path = _find("chromedriver", "/usr/lib/chromium/chromedriver")
    if chromium is None or driver_path is None:
        if os.environ.get("CI") == "true":
            pytest.fail("chromium/chromedriver missing in CI: .ci/run installs Debian's "
                        "chromium and chromium-driver")
        pytest.skip("chromium and chromium-driver are not installed")
    return chromium, driver_path


def test_missing_chromium_skips_here_and_fails_in_ci(monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setattr(os.path, "exists", lambda path: False)
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception):
        _chromium()
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="missing in CI"):
        _chromium()


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    chromium, driver_path = _chromium()
    from selenium import webdriver  # a dependency (pyproject.toml): never a reason to skip
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for arg in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--no-first-run",
                "--disable-dev-shm-usage", f"--window-size={WIDTH},{HEIGHT}",
                f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    drv = webdriver.Chrome(service=Service(executable_path=driver_path), options=options)
    drv.set_page_load_timeout(60)
    try:
        yield drv
    finally:
        drv.quit()


def _load(browser, page: Path, name: str) -> list[dict]:
    """Open ``page``; the console entries of level SEVERE (errors); keep a screenshot."""
    browser.get_log("browser")  # drop what an earlier page left
    browser.get(page.resolve().as_uri())
    browser.execute_script("return document.readyState")
    keep = os.environ.get("CONFORM_SCREENSHOTS")
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        browser.save_screenshot(str(Path(keep) / f"{name}.png"))
    return [e for e in browser.get_log("browser") if e.get("level") == "SEVERE"]


_ON_SCREEN = """
const el = document.querySelector(arguments[0]);
if (!el) return null;
const r = el.getBoundingClientRect();
return [r.top, r.bottom, window.innerHeight, el.innerText.slice(0, 1000)];
"""


def _on_first_screen(browser, selector: str) -> str:
    found = browser.execute_script(_ON_SCREEN, selector)
    assert found is not None, f"no {selector} on the page"
    top, bottom, height, text = found
    assert 0 <= top and top < height, f"{selector} starts at {top}px, below the first screen"
    return text


def test_conformance_report_first_screen(browser, tmp_path, capsys):
    out = tmp_path / "conformance"
    with pytest.raises(SystemExit) as info:  # v10 firmware judged as v19: FAILs that cite §14.1
        main(["run", "-q", "--target", "emu:gve64-v10", "--variant", "gve64-v19",
              "--report", str(out)])
    assert info.value.code == 1
    capsys.readouterr()
    errors = _load(browser, out / "index.html", "conformance")
    assert errors == []
    assert browser.title.startswith("conform — conformance report: FAIL")
    summary = _on_first_screen(browser, "#summary")
    assert "FAIL" in summary and "checks on 1 target" in summary
    assert "Nothing skipped" in _on_first_screen(browser, "#not-verified")
    assert "MUST" in _on_first_screen(browser, "#legend")
    first = _on_first_screen(browser, ".detail.FAIL")
    assert "expected" in first and "actual" in first and "conform run --target" in first
    # what a reader needs first: the unit is another variant, and most FAILs are one cause
    assert "try --variant gve64-v10" in _on_first_screen(browser, "#hint")
    causes = _on_first_screen(browser, "#causes")
    assert "VL, VK, VN, XM" in causes and "one cause" in causes
    marked = browser.execute_script(
        "return document.querySelector('.detail.FAIL mark.d').innerText")
    assert marked   # the differing bytes of expected vs actual are highlighted


def _crowded_first_screen():
    """The most a first screen must hold: four targets, a stopped run, notes, four reasons
    for skipped checks."""
    from conform.conformance.results import CheckResult, Grade, LogEntry, RunResults, TargetRun

    runs = []
    for i, (target, variant) in enumerate((("/dev/ttyUSB0", "gve64-v19"),
                                           ("emu:gve64-v10", "gve64-v10"),
                                           ("emu:gve64-phantom", "gve64-phantom"),
                                           ("socket://10.0.0.5:4000", "gve124"))):
        real = not target.startswith("emu")
        run = TargetRun(target, variant, not real, "quick", "t0",
                        aborted="interrupted (Ctrl-C) after 120 checks; sent H, D, O0,FF"
                        if i == 0 else None,
                        notes=["variant: firmware 'IP64MPG v19 10.9.2010' is gve64-v19",
                               "motion-bearing checks SKIPPED (no --allow-motion)"] if real else [])
        common = dict(variant=variant, target=target)
        run.checks = [
            CheckResult(f"{variant}/13.5.2/C/valid", Grade.SKIPPED, "GVE64 §13.5.2",
                        detail="needs motion (not allowed in this run: --allow-motion)", **common),
            CheckResult(f"{variant}/13.5.12/EW/valid", Grade.SKIPPED, "GVE64 §13.5.12",
                        detail="needs eeprom (not allowed in this run: --allow-motion)", **common),
            CheckResult(f"{variant}/13.5.11/I1/inputs", Grade.SKIPPED, "GVE64 §13.5.11",
                        detail="needs inputs driven, which only the emulator allows", **common),
            CheckResult(f"{variant}/13.5.2/L/valid", Grade.SKIPPED, "GVE64 §13.5.2",
                        detail="refused to send b'!0L2000,0,0': a move of 2000 steps exceeds "
                               "--max-steps 1000", **common),
            CheckResult(f"{variant}/13.5.3/V/valid", Grade.FAIL, "GVE64 §13.5.3",
                        expected="!0V1000 → 0", actual="!0V1000 → 5", detail="answer differs",
                        log=[LogEntry(0.0, "tx", b"!0V1000\r"), LogEntry(0.002, "rx", b"5\r")],
                        **common)]
        runs.append(run)
    return RunResults(runs, "conform run --target /dev/ttyUSB0 --target ... --matrix")


_FULLY_ON_SCREEN = """
const rows = document.querySelector(arguments[0]).querySelectorAll("tr");
return [...rows].map(r => r.getBoundingClientRect().bottom <= window.innerHeight);
"""


def test_conformance_report_of_a_stopped_run_says_why_first(browser, tmp_path):
    from conform.report.render import write_reports

    out = write_reports(_crowded_first_screen(), tmp_path / "r")
    assert _load(browser, out / "index.html", "conformance-incomplete") == []
    assert browser.title.endswith("INCOMPLETE")
    assert "Ctrl-C" in _on_first_screen(browser, ".abort")
    skipped = _on_first_screen(browser, "#not-verified")
    for how in ("--allow-motion --max-steps N", "--allow-eeprom", "a larger --max-steps",
                "--target emu:VARIANT"):
        assert how in skipped
    assert "!0V1000 → 5" in _on_first_screen(browser, ".detail.FAIL")
    # the first failure whole: expected, actual, detail, replay and its tx/rx
    assert browser.execute_script(_FULLY_ON_SCREEN, ".detail.FAIL") \
        == [True] * 5


def test_analysis_report_first_screen(browser, tmp_path, capsys):
    out = tmp_path / "analysis"
    with pytest.raises(SystemExit) as info:
        main(["analyze", str(REPO / "captures" / "careless-noisy.mcap"), "--no-progress",
              "--report", str(out)])
    assert info.value.code == 0
    capsys.readouterr()
    errors = _load(browser, out / "index.html", "analysis")
    assert errors == []
    # the diagnosis opens the report: its one sentence, then the session's figures
    diagnosis = _on_first_screen(browser, ".diagnosis")
    assert diagnosis.startswith("Diagnosis: Completed"), diagnosis[:200]   # the outcome first
    summary = _on_first_screen(browser, "table.session")
    assert "variant" in summary and "exchanges" in summary
    first = _on_first_screen(browser, ".sev-hazard, .sev-error")
    assert "hazard" in first or "error" in first
    images = browser.execute_script(
        "return [...document.images].filter(i => !(i.complete && i.naturalWidth > 0)).length")
    assert images == 0, "a plot did not load"


def test_marlin_analysis_report_first_screen(browser, tmp_path, capsys):
    out = tmp_path / "marlin"
    with pytest.raises(SystemExit) as info:
        main(["analyze", str(REPO / "captures" / "marlin-noisy.mcap"), "--no-progress",
              "--report", str(out)])
    assert info.value.code == 0
    capsys.readouterr()
    assert _load(browser, out / "index.html", "marlin-analysis") == []
    # the verdict first, in a sentence, in its colour; then the figures in words
    verdict = _on_first_screen(browser, ".verdict")
    assert verdict.startswith("ERROR: The unit rejected 10 line(s)"), verdict
    background = browser.execute_script(
        "return getComputedStyle(document.querySelector('.verdict')).backgroundColor")
    assert background == "rgb(253, 226, 200)"   # the error colour of the shared stylesheet
    figures = _on_first_screen(browser, "table.session")
    assert "time from a line to its ok" in figures and "ok_p50_ms" not in figures
    plots = browser.execute_script(
        "return [...document.images].map(i => [i.alt, i.complete && i.naturalWidth > 0])")
    assert [alt.split(" ")[0] for alt, _ in plots] == ["time", "the", "when", "lines"]
    assert all(ok for _alt, ok in plots), plots


@pytest.mark.long(57)
def test_fleet_report_loads_and_names_its_counts(browser, tmp_path, capsys):
    out = tmp_path / "fleet"
    with pytest.raises(SystemExit):
        main(["analyze", str(REPO / "captures"), "--report", str(out), "--jobs", "1"])
    capsys.readouterr()
    assert _load(browser, out / "index.html", "fleet") == []
    heading = _on_first_screen(browser, "h1")
    assert heading.startswith("Fleet analysis: ") and " 1 machines" not in heading
    # styled as a session's report: the verdict and the counts first, then the plots
    verdict = _on_first_screen(browser, ".verdict")
    assert verdict.startswith("HAZARD: 5 hazards on "), verdict   # careless-noisy's five
    assert "hazard: 5" in _on_first_screen(browser, ".badge.sev-hazard")
    assert "exchanges" in _on_first_screen(browser, "table.fleet")
    background = browser.execute_script(
        "return getComputedStyle(document.querySelector('.verdict')).backgroundColor")
    assert background == "rgb(248, 208, 208)"   # the hazard colour of the shared stylesheet
    plots = browser.execute_script(
        "return [...document.images].map(i => [i.alt, i.complete && i.naturalWidth > 0])")
    assert len(plots) == 2 and all(ok for _alt, ok in plots), plots
    assert plots[0][0].startswith("sessions over time")
    # every table on the page: none runs off it (the sessions table's columns wrap)
    widths = browser.execute_script(
        "return [document.documentElement.scrollWidth, window.innerWidth, ...[...document"
        ".querySelectorAll('table')].map(t => [t.className, t.getBoundingClientRect().right,"
        " t.parentElement.getBoundingClientRect().right])]")
    page, window, *tables = widths
    assert page <= window, widths
    assert all(right <= room + 1 for _name, right, room in tables), tables
    # a session's name opens that session's own report
    link = browser.find_element("link text", "good-rs232")   # a GVE session's
    session = link.text
    link.click()
    assert re.search(rf"/sessions/[^/]+/{session}/index\.html$", browser.current_url)
    assert [e for e in browser.get_log("browser") if e.get("level") == "SEVERE"] == []
    own = _on_first_screen(browser, "h1")
    assert own.startswith("Session analysis: ") and own.endswith(f"{session}.mcap"), own
    _on_first_screen(browser, "table.session")
