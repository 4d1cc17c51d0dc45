"""The pytest plugin of the ``pytest11`` entry point ``conform``: ``pytest --conform-target=URL``
runs conformance checks as test items. Each family brings its own plugin module
(``Family.pytest_plugin``, GVE's: conform.families.gve.conformance.pytest_plugin); this module
only loads them, through the family registry, so that the entry point's name and module stay
where installed environments expect them. Load it with ``-p conform`` or
``-p conform.conformance.pytest_plugin``.
"""

from __future__ import annotations

from conform.families import families

pytest_plugins = [f.pytest_plugin for f in families() if getattr(f, "pytest_plugin", None)]
