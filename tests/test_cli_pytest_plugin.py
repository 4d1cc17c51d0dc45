"""The pytest plugin as a user runs it: usage errors, JUnit classnames, -k by clause."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest


def _pytest(tmp_path, *args):
    cmd = [sys.executable, "-m", "pytest", "-p", "conform", "-q", "--rootdir", str(tmp_path),
           str(tmp_path), "-p", "no:cacheprovider", *args]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=120)


@pytest.mark.parametrize("args, named", [
    (["--conform-target=emu:gve64-v91"], "'gve64-v91'"),
    (["--conform-target=emu:gve64-v19", "--conform-variant=nonsense"], "'nonsense'"),
    (["--conform-target=emu:gve64-v19:no-such-mutant"], "'no-such-mutant'"),
    (["--conform-target=/dev/conform-no-such-port"], "/dev/conform-no-such-port"),
    (["--conform-target=/dev/conform-no-such-port", "--conform-allow-motion"],
     "--conform-max-steps"),
])
def test_a_bad_option_is_one_usage_line(tmp_path, args, named):
    run = _pytest(tmp_path, *args)
    assert run.returncode == 4, run.stdout + run.stderr
    out = run.stdout + run.stderr
    assert "INTERNALERROR" not in out and "Traceback" not in out
    errors = [line for line in out.splitlines() if line.startswith("ERROR:")]
    assert len(errors) == 1 and named in errors[0], out


@pytest.mark.slow
def test_junit_classname_and_k_by_clause(tmp_path):
    junit = tmp_path / "j.xml"
    run = _pytest(tmp_path, "--conform-target=emu:gve64-v10", "--conform-variant=gve64-v19",
                  "-k", "13.5.3 and valid", f"--junitxml={junit}")
    assert run.returncode == 1, run.stdout[-2000:]  # VL is absent in v10: §14.1
    cases = list(ET.parse(junit).getroot().iter("testcase"))
    assert cases and {c.get("classname") for c in cases} == {"gve64-v19.13.5.3"}
    names = {c.get("name"): c for c in cases}
    assert names["VL/valid"].find("failure") is not None
    assert names["V/valid"].find("failure") is None
    assert all(n.endswith("valid") for n in names)
    assert "deselected" in run.stdout


@pytest.mark.slow
def test_k_selects_by_level(tmp_path):
    run = _pytest(tmp_path, "--conform-target=emu:gve64-v19", "-k", "13.5.9 and INFO",
                  "--conform-check=*/G/*", "-rA")
    assert run.returncode == 0, run.stdout[-2000:]
    passed = [line for line in run.stdout.splitlines() if line.startswith("PASSED ")]
    assert passed and all("gve64-v19/13.5.9::" in line for line in passed)
