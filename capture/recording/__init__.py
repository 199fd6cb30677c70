"""The recording contract of RECORDING.md in code: topics, message types, frames, writer, reader.

Everything another package needs of the recording format is importable from here.
"""

from __future__ import annotations

from capture.errors import RecordingError
from capture.recording.frames import (
    LABEL_COLORS,
    LABEL_NAMES,
    NUM_LABELS,
    OBJECT_LABELS,
    STRUCTURAL_LABELS,
    VOC_TO_LABEL,
    Extrinsics,
    GroundTruth,
    Intrinsics,
    Label,
    RgbdFrame,
)
from capture.recording.messages import DEFAULT_NAMESPACE, GT_CLOUD_ATTACHMENT
from capture.recording.reader import RecordingReader, TopicInfo
from capture.recording.writer import RecordingWriter

__all__ = [
    "DEFAULT_NAMESPACE",
    "GT_CLOUD_ATTACHMENT",
    "LABEL_COLORS",
    "LABEL_NAMES",
    "NUM_LABELS",
    "OBJECT_LABELS",
    "STRUCTURAL_LABELS",
    "VOC_TO_LABEL",
    "Extrinsics",
    "GroundTruth",
    "Intrinsics",
    "Label",
    "RecordingError",
    "RecordingReader",
    "RecordingWriter",
    "RgbdFrame",
    "TopicInfo",
]
