"""Errors of the processor: one base class, caught once by the CLI and printed as one line."""

from __future__ import annotations


class ReplayError(Exception):
    """Base of every error that `semreplay-process` reports as one line."""


class ConfigError(ReplayError):
    """A configuration file or value is invalid."""


class ModelError(ReplayError):
    """Segmentation weights are missing, corrupt, or of another architecture."""


class CloudError(ReplayError):
    """A point cloud file is missing, malformed, or lacks the fields a stage needs."""


class StageError(ReplayError):
    """A pipeline stage cannot run on the input it was given."""


class OutputError(ReplayError):
    """An output file cannot be written (no space, no permission, not a folder)."""


class RunInterruptedError(ReplayError):
    """Ctrl-C (or SIGTERM) stopped a run; the message says which complete files it left."""
