"""ROS 2 message definitions (full concatenated .msg text) and topic names of RECORDING.md."""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

DEFAULT_NAMESPACE: Final = "/camera/camera"
COLOR_FRAME_ID: Final = "camera_color_optical_frame"
DEPTH_FRAME_ID: Final = "camera_depth_optical_frame"
LINK_FRAME_ID: Final = "camera_link"
WORLD_FRAME_ID: Final = "world"
# camera_link (x forward, y left, z up) from an optical frame (x right, y down, z forward).
LINK_FROM_OPTICAL: Final = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

# Topic suffixes under the namespace; readers discover namespaces by these.
COLOR_IMAGE: Final = "/color/image_raw"
COLOR_COMPRESSED: Final = "/color/image_raw/compressed"
COLOR_INFO: Final = "/color/camera_info"
DEPTH_IMAGE: Final = "/depth/image_rect_raw"
DEPTH_INFO: Final = "/depth/camera_info"
ALIGNED_DEPTH_IMAGE: Final = "/aligned_depth_to_color/image_raw"
ALIGNED_DEPTH_INFO: Final = "/aligned_depth_to_color/camera_info"
EXTRINSICS: Final = "/extrinsics/depth_to_color"
COLOR_METADATA: Final = "/color/metadata"
DEPTH_METADATA: Final = "/depth/metadata"
TF_STATIC: Final = "/tf_static"
GT_POSE: Final = "/ground_truth/pose"
GT_LABELS: Final = "/ground_truth/labels"
GT_INSTANCES: Final = "/ground_truth/instances"
GT_CLOUD_ATTACHMENT: Final = "ground_truth_cloud.ply"

IMAGE: Final = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE: Final = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO: Final = "sensor_msgs/msg/CameraInfo"
POSE_STAMPED: Final = "geometry_msgs/msg/PoseStamped"
TF_MESSAGE: Final = "tf2_msgs/msg/TFMessage"
RS_EXTRINSICS: Final = "realsense2_camera_msgs/msg/Extrinsics"
RS_METADATA: Final = "realsense2_camera_msgs/msg/Metadata"

_SEP = "=" * 80

_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_POINT = "float64 x\nfloat64 y\nfloat64 z\n"
_QUATERNION = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
_VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"
_ROI = "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"


def _concat(main: str, *deps: tuple[str, str]) -> str:
    parts = [main]
    for name, text in deps:
        parts.append(f"{_SEP}\nMSG: {name}\n{text}")
    return "\n".join(parts)


MSG_DEFS: Final[dict[str, str]] = {
    IMAGE: _concat(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
        "uint8 is_bigendian\nuint32 step\nuint8[] data\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
    COMPRESSED_IMAGE: _concat(
        "std_msgs/Header header\nstring format\nuint8[] data\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
    CAMERA_INFO: _concat(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n"
        "float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n"
        "uint32 binning_y\nRegionOfInterest roi\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        ("sensor_msgs/RegionOfInterest", _ROI),
    ),
    POSE_STAMPED: _concat(
        "std_msgs/Header header\nPose pose\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        ("geometry_msgs/Pose", "Point position\nQuaternion orientation\n"),
        ("geometry_msgs/Point", _POINT),
        ("geometry_msgs/Quaternion", _QUATERNION),
    ),
    TF_MESSAGE: _concat(
        "geometry_msgs/TransformStamped[] transforms\n",
        (
            "geometry_msgs/TransformStamped",
            "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
        ),
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        ("geometry_msgs/Transform", "Vector3 translation\nQuaternion rotation\n"),
        ("geometry_msgs/Vector3", _VECTOR3),
        ("geometry_msgs/Quaternion", _QUATERNION),
    ),
    RS_EXTRINSICS: "float64[9] rotation\nfloat64[3] translation\n",
    RS_METADATA: _concat(
        "std_msgs/Header header\nstring json_data\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
}


def stamp(stamp_ns: int) -> dict[str, int]:
    """Return a builtin_interfaces/Time dict for a stamp in nanoseconds."""
    return {"sec": stamp_ns // 1_000_000_000, "nanosec": stamp_ns % 1_000_000_000}


def stamp_ns_of(msg_stamp: object) -> int:
    """Return the nanoseconds of a decoded builtin_interfaces/Time."""
    return int(getattr(msg_stamp, "sec")) * 1_000_000_000 + int(getattr(msg_stamp, "nanosec"))  # noqa: B009


def header(stamp_ns: int, frame_id: str) -> dict[str, object]:
    """Return a std_msgs/Header dict."""
    return {"stamp": stamp(stamp_ns), "frame_id": frame_id}


def image(
    stamp_ns: int, frame_id: str, *, width: int, height: int, encoding: str, step: int, data: bytes
) -> dict[str, object]:
    """Return a little-endian sensor_msgs/Image dict."""
    return {
        "header": header(stamp_ns, frame_id),
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": step,
        "data": data,
    }


def camera_info(
    stamp_ns: int,
    frame_id: str,
    *,
    width: int,
    height: int,
    k: tuple[float, float, float, float],
    distortion_model: str,
    coeffs: tuple[float, ...],
) -> dict[str, object]:
    """Return a sensor_msgs/CameraInfo dict for a pinhole camera with k = (fx, fy, cx, cy)."""
    fx, fy, cx, cy = k
    return {
        "header": header(stamp_ns, frame_id),
        "height": height,
        "width": width,
        "distortion_model": distortion_model,
        "d": list(coeffs),
        "k": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "p": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        "binning_x": 0,
        "binning_y": 0,
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


def pose(matrix: npt.ArrayLike) -> tuple[dict[str, float], dict[str, float]]:
    """Return the (position or translation, orientation quaternion) dicts of a 4x4 transform."""
    mat = np.asarray(matrix, dtype=np.float64)
    x, y, z, w = Rotation.from_matrix(mat[:3, :3]).as_quat()
    t = mat[:3, 3]
    return (
        {"x": float(t[0]), "y": float(t[1]), "z": float(t[2])},
        {"x": float(x), "y": float(y), "z": float(z), "w": float(w)},
    )


def pose_stamped(stamp_ns: int, frame_id: str, matrix: npt.ArrayLike) -> dict[str, object]:
    """Return a geometry_msgs/PoseStamped dict of a 4x4 transform."""
    position, orientation = pose(matrix)
    return {
        "header": header(stamp_ns, frame_id),
        "pose": {"position": position, "orientation": orientation},
    }


def tf_static(color_from_depth: npt.NDArray[np.float64], stamp_ns: int) -> dict[str, object]:
    """Return the tf2_msgs/TFMessage of camera_link -> both optical frames.

    camera_link sits at the depth optical origin, as in realsense-ros.
    """
    link_from_depth = np.eye(4)
    link_from_depth[:3, :3] = LINK_FROM_OPTICAL
    link_from_color = link_from_depth @ np.linalg.inv(color_from_depth)
    transforms = []
    for child, matrix in ((DEPTH_FRAME_ID, link_from_depth), (COLOR_FRAME_ID, link_from_color)):
        translation, rotation = pose(matrix)
        transforms.append(
            {
                "header": header(stamp_ns, LINK_FRAME_ID),
                "child_frame_id": child,
                "transform": {"translation": translation, "rotation": rotation},
            }
        )
    return {"transforms": transforms}
