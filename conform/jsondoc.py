"""A name for JSON objects whose values are read back: parsed from a file, a capture or a
bundle (their values are whatever the file held) or documents built with mixed values and
read again (a capture's metadata, an analysis's metrics, a JSON Schema). A function that only
builds a document for ``json.dumps`` returns ``dict[str, object]`` instead."""

from typing import Any

JsonObject = dict[str, Any]
