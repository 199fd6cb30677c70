"""Errors of the capture package: one base class, caught once by the CLI."""

from __future__ import annotations


class CaptureError(Exception):
    """Base of every error that the capture tools report as one line."""


class RecordingError(CaptureError):
    """A recording file is missing, malformed, or does not follow RECORDING.md."""


class CameraError(CaptureError):
    """The camera (or a RealSense recording played back through it) failed."""


class ImportFormatError(CaptureError):
    """A dataset folder is not of the format it was imported as."""
