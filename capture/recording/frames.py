"""Frame value types, label table and the small geometry of camera models."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Final

import numpy as np
import numpy.typing as npt


class Label(IntEnum):
    """The label ids of RECORDING.md (the paper's Table 6, plus 0)."""

    UNLABELLED = 0
    CEILING = 1
    FLOOR = 2
    WALL = 3
    TABLE = 4
    CHAIR = 5
    PERSON = 6
    PLANT = 7
    SOFA = 8
    TV_MONITOR = 9
    CLUTTER = 10


# Label names, in id order, as metrics and the viewer show them.
LABEL_NAMES: Final[tuple[str, ...]] = (
    "unlabelled",
    "ceiling",
    "floor",
    "wall",
    "table",
    "chair",
    "person",
    "plant",
    "sofa",
    "tv monitor",
    "clutter",
)
# Fixed colours, one per label id (RGB).
LABEL_COLORS: Final[tuple[tuple[int, int, int], ...]] = (
    (0, 0, 0),
    (220, 220, 255),
    (140, 110, 80),
    (170, 170, 170),
    (250, 160, 30),
    (230, 40, 40),
    (255, 100, 200),
    (40, 190, 60),
    (120, 60, 200),
    (30, 140, 250),
    (250, 240, 60),
)
NUM_LABELS: Final = len(LABEL_NAMES)
STRUCTURAL_LABELS: Final = (Label.CEILING, Label.FLOOR, Label.WALL)  # planes, not the network
OBJECT_LABELS: Final = tuple(Label(i) for i in range(Label.TABLE, Label.CLUTTER + 1))

# PASCAL VOC class index -> our label (RECORDING.md). VOC order:
# 0 background, 1 aeroplane, 2 bicycle, 3 bird, 4 boat, 5 bottle, 6 bus, 7 car, 8 cat, 9 chair,
# 10 cow, 11 diningtable, 12 dog, 13 horse, 14 motorbike, 15 person, 16 pottedplant, 17 sheep,
# 18 sofa, 19 train, 20 tvmonitor.
VOC_TO_LABEL: Final[tuple[int, ...]] = (
    0, 10, 10, 10, 10, 10, 10, 10, 10, 5, 10, 4, 10, 10, 10, 6, 7, 10, 8, 10, 9,
)  # fmt: skip


@dataclass(frozen=True, slots=True)
class Intrinsics:
    """A pinhole camera with its distortion model, as in a ROS CameraInfo."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion_model: str = "plumb_bob"
    coeffs: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def matrix(self) -> npt.NDArray[np.float64]:
        """Return the 3x3 camera matrix K."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )

    @property
    def is_distorted(self) -> bool:
        """Return whether any distortion coefficient is non-zero."""
        return any(c != 0.0 for c in self.coeffs)


@dataclass(frozen=True, slots=True)
class Extrinsics:
    """The rigid transform that takes depth-camera points into the colour camera."""

    color_from_depth: npt.NDArray[np.float64]  # (4, 4), metres

    @staticmethod
    def from_librealsense(rotation: npt.ArrayLike, translation: npt.ArrayLike) -> Extrinsics:
        """Build from librealsense's column-major rotation[9] and translation[3] in metres."""
        m = np.eye(4)
        m[:3, :3] = np.asarray(rotation, dtype=np.float64).reshape(3, 3).T
        m[:3, 3] = np.asarray(translation, dtype=np.float64)
        return Extrinsics(m)

    def to_librealsense(self) -> tuple[list[float], list[float]]:
        """Return (column-major rotation[9], translation[3]) as librealsense stores them."""
        rot = self.color_from_depth[:3, :3].T.reshape(-1)
        return [float(v) for v in rot], [float(v) for v in self.color_from_depth[:3, 3]]


@dataclass(frozen=True, slots=True)
class GroundTruth:
    """What a simulator or a dataset knows about a frame; any part may be absent."""

    world_from_camera: npt.NDArray[np.float64] | None = None  # (4, 4), colour optical frame
    labels: npt.NDArray[np.uint8] | None = None  # (H, W), RECORDING.md label ids
    instances: npt.NDArray[np.uint16] | None = None  # (H, W), 0 = none


@dataclass(frozen=True, slots=True)
class RgbdFrame:
    """One synchronised colour + depth frame of a recording."""

    index: int
    stamp_ns: int
    color: npt.NDArray[np.uint8]  # (H, W, 3) RGB
    depth_m: npt.NDArray[np.float32]  # (h, w) metres, 0 = no depth; colour camera when aligned
    color_intrinsics: Intrinsics
    depth_intrinsics: Intrinsics  # equals color_intrinsics when aligned
    aligned: bool
    depth_to_color: Extrinsics | None = None  # None when aligned
    ground_truth: GroundTruth | None = None
    metadata: dict[str, str] = field(default_factory=dict)  # colour metadata json, if any
