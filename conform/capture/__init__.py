"""MCAP captures: crash-safe recording, tolerant reading, info and recovery.

See docs/capture-format.md for the file layout and the APIs.
"""

from conform.capture.reader import Capture, CaptureMessage, open_capture
from conform.capture.recorder import Recorder, RecordingError
from conform.capture.recover import capture_info, recover

__all__ = [
    "Capture", "CaptureMessage", "Recorder", "RecordingError", "capture_info", "open_capture",
    "recover",
]
