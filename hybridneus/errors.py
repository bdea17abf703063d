"""Exceptions that carry a one-line, user-facing message.

The CLI prints any :class:`HybridNeusError` as ``error: <message>`` on one line and exits
with code 2, without a traceback. Messages name the offending file (or config key) first.
"""

from __future__ import annotations


class HybridNeusError(Exception):
    """Base class for errors caused by bad input rather than by a bug."""


class DatasetError(HybridNeusError, ValueError):
    """A dataset on disk does not follow the EventNeRF layout (see docs/data.md)."""


class ConfigError(HybridNeusError, ValueError):
    """A configuration key, value or preset is unknown or has the wrong type."""


class MeshError(HybridNeusError, ValueError):
    """A mesh file cannot be read, or holds no usable geometry."""


class RunError(HybridNeusError, ValueError):
    """A run directory or checkpoint is missing or unreadable."""


class RecordingError(HybridNeusError, ValueError):
    """A recording, pose track or calibration file cannot be read or does not fit together."""


class OutputError(HybridNeusError, OSError):
    """An output path cannot be written (a folder where a file is wanted, a file in its
    path, no permission)."""
