"""What pyproject.toml cannot say: each family's tables live in the top-level ``specs/<family>/``
and ship inside the wheel as the data package ``conform.families.<family>.spec.tables``, where
``conform.families.table_folder`` finds them through importlib.resources. A plain
``pip install .`` and ``pip install -e .`` both read this; nothing is copied in the tree."""

from pathlib import Path

from setuptools import find_packages, setup

SPECS = Path(__file__).resolve().parent / "specs"
TABLES = {f"conform.families.{d.name}.spec.tables": f"specs/{d.name}"
          for d in sorted(SPECS.iterdir()) if d.is_dir()}

setup(
    packages=[*find_packages(include=["conform*"], exclude=["conform.samples.*"]), *TABLES],
    package_dir=TABLES,
)
