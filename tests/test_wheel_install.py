"""A plain (non-editable) install works: the wheel carries every family's tables, and in a fresh
venv with only the declared dependencies `conform spec list` names every variant and a quick
run against each family's embedded emulator passes."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _run(args: list[str], **kw) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "CONFORM_SPECS")}
    return subprocess.run(args, capture_output=True, text=True, env=env, timeout=1200, **kw)


@pytest.mark.slow
@pytest.mark.long(130)
def test_wheel_install_finds_its_tables(tmp_path):
    wheels = tmp_path / "whl"
    built = _run([sys.executable, "-m", "pip", "wheel", "--no-deps",
                  "-w", str(wheels), str(REPO)])
    assert built.returncode == 0, built.stderr[-2000:]
    (wheel,) = wheels.glob("conform-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    tables = sorted(n for n in names if n.endswith(".toml"))
    # the top-level specs/<family>/ land in the family's package (setup.py), nowhere else
    for family, table in (("gve", "commands"), ("grbl", "codes"), ("marlin", "messages")):
        assert f"conform/families/{family}/spec/tables/{table}.toml" in tables
    assert not [n for n in names if n.startswith("specs/")]

    venv = tmp_path / "venv"
    # the machine's packages stand in for the registry; conform itself only from the wheel
    made = _run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)])
    assert made.returncode == 0, made.stderr
    py = venv / "bin" / "python"
    inst = _run([str(py), "-m", "pip", "install", "--no-deps", "--force-reinstall", str(wheel)])
    assert inst.returncode == 0, inst.stderr[-2000:]
    where = _run([str(py), "-c", "import conform; print(conform.__file__)"], cwd=tmp_path)
    assert str(venv) in where.stdout, where.stdout + where.stderr

    conform = venv / "bin" / "conform"
    listed = _run([str(conform), "spec", "list", "--json"], cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    for variant in ("gve64-v10", "gve64-v19", "gve64-phantom", "gve124", "grbl-1.1f", "marlin-2.1",
                    "marlin-2.1-adv"):
        assert variant in listed.stdout
    for target in ("emu:gve64-v19", "emu:grbl-1.1f"):
        ran = _run([str(conform), "run", "--target", target, "--report", str(tmp_path / target[4:])],
                   cwd=tmp_path)
        assert ran.returncode == 0, (target, ran.stdout[-2000:], ran.stderr[-2000:])

    # the README's tour from the wheel: `conform samples` writes what it reads, as in a clone
    samples = tmp_path / "samples"
    made = _run([str(conform), "samples", str(samples)], cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    shipped = {p.name for p in (REPO / "captures").glob("*.mcap")}
    assert {p.name for p in (samples / "captures").glob("*.mcap")} == shipped
    for rel in ("captures/jobs/part.nc", "captures/jobs/grbl-arc.nc", "tests/senders/careful.py",
                "tests/data/marlin/facts-2.1.2.4.transcript", "docs/check-sender.md"):
        assert (samples / rel).is_file(), rel
    for line in (["analyze", "captures/careless-noisy.mcap"],
                 ["analyze", "captures/grbl-counting.mcap"],
                 ["check-sender", "--scenario", "clean", "--report", str(tmp_path / "sender"),
                  "--", str(py), "tests/senders/careful.py", "{port}", "{job}"]):
        ran = _run([str(conform), *line], cwd=samples)
        assert ran.returncode == 0, (line, ran.stdout[-2000:], ran.stderr[-2000:])
