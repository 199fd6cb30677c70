"""Small dataset folders with known stamps, poses and depth, and independent file readers."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from capture.recording import RecordingReader
from capture.recording.frames import RgbdFrame

W, H = 640, 480

# TUM folder: rgb and depth stamps chosen so that associate.py's greedy rule decides.
TUM_RGB_S = ("1.000000", "1.033000", "1.066000", "1.105000", "1.133000", "1.200000", "1.300000")
TUM_DEPTH_S = ("1.005000", "1.030000", "1.052000", "1.120000", "1.220000", "1.280000")
# (1.033, 1.030) 3 ms, (1.000, 1.005) 5 ms, (1.133, 1.120) 13 ms, (1.066, 1.052) 14 ms; then
# (1.105, 1.120) at 15 ms and (1.033, 1.052) find a stamp taken (in file order 1.105 would have
# won 1.120); (1.200, 1.220) and (1.300, 1.280) are exactly 0.02 s apart, not < 0.02 s.
TUM_PAIRS = ((0, 0), (1, 1), (2, 2), (4, 3))  # (rgb index, depth index)
TUM_GT_S = tuple(f"{0.99 + 0.01 * i:.2f}" for i in range(8))  # 0.99 .. 1.06 at 100 Hz
# Raw TUM depth units (5000 per metre) in the top-left corner of every depth image, and their mm.
TUM_CORNER_RAW = (0, 5000, 5002, 5003, 65535)
TUM_CORNER_MM = (0, 1000, 1000, 1001, 13107)


def tum_pose(t_s: float) -> npt.NDArray[np.float64]:
    """Return the known ground truth at t: a straight line and a turn about z, both linear in t."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec([0.0, 0.0, 2.0 * (t_s - 1.0)]).as_matrix()
    out[:3, 3] = [t_s - 1.0, 2.0 * (t_s - 1.0), 0.5]
    return out


def tum_depth_raw(j: int) -> npt.NDArray[np.uint16]:
    """Return depth image j: 1 m + 100 mm per index (in 1/5000 m), the corner values at row 0."""
    raw = np.full((H, W), 5000 + 500 * j, np.uint16)
    raw[0, : len(TUM_CORNER_RAW)] = TUM_CORNER_RAW
    return raw


def color_image(j: int) -> npt.NDArray[np.uint8]:
    """Return RGB image j: a flat colour that names its index, so pairing is visible."""
    return np.full((H, W, 3), (10 * j + 5, 100, 200), np.uint8)


def write_tum_folder(root: Path, name: str, *, groundtruth: bool = True) -> Path:
    """Write a TUM RGB-D folder with the stamps above and return it."""
    src = root / name
    (src / "rgb").mkdir(parents=True)
    (src / "depth").mkdir()
    rgb_lines = ["# color images", "# file: 'test'", "# timestamp filename"]
    for j, stamp in enumerate(TUM_RGB_S):
        write_color(src / "rgb" / f"{stamp}.png", color_image(j))
        rgb_lines.append(f"{stamp} rgb/{stamp}.png")
    depth_lines = ["# depth maps", "# timestamp filename"]
    for j, stamp in enumerate(TUM_DEPTH_S):
        assert cv2.imwrite(str(src / "depth" / f"{stamp}.png"), tum_depth_raw(j))
        depth_lines.append(f"{stamp}\tdepth/{stamp}.png")
    (src / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (src / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    if groundtruth:
        gt_lines = ["# ground truth trajectory", "# timestamp tx ty tz qx qy qz qw"]
        for stamp in TUM_GT_S:
            pose = tum_pose(float(stamp))
            q = Rotation.from_matrix(pose[:3, :3]).as_quat()
            gt_lines.append(" ".join([stamp, *(f"{v:.9f}" for v in (*pose[:3, 3], *q))]))
        (src / "groundtruth.txt").write_text("\n".join(gt_lines) + "\n")
    return src


def write_color(path: Path, rgb: npt.NDArray[np.uint8]) -> None:
    """Write an RGB image to PNG (lossless) through OpenCV's BGR order."""
    assert cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))


@dataclass(frozen=True)
class SevenScenesFrame:
    """What one written 7-Scenes frame holds."""

    number: int
    depth_mm: npt.NDArray[np.uint16]  # as written, 65535 = invalid
    world_from_camera: npt.NDArray[np.float64]


def write_seven_scenes(
    seq: Path, numbers: tuple[int, ...] = (0, 1, 2), *, color_suffix: str = ".png"
) -> list[SevenScenesFrame]:
    """Write a 7-Scenes sequence (colour PNG, depth mm with 65535 holes, 4x4 poses)."""
    seq.mkdir(parents=True)
    frames = []
    for number in numbers:
        stem = seq / f"frame-{number:06d}"
        write_color(stem.with_name(stem.name + ".color" + color_suffix), color_image(number))
        depth = np.full((H, W), 1500 + number, np.uint16)
        depth[10:20, 30:40] = 65535
        assert cv2.imwrite(str(stem.with_name(stem.name + ".depth.png")), depth)
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("xyz", [0.1, -0.2, 0.05 * number]).as_matrix()
        pose[:3, 3] = [0.1 * number, -0.05, 1.2]
        np.savetxt(stem.with_name(stem.name + ".pose.txt"), pose, fmt="%.12e", delimiter="\t")
        frames.append(SevenScenesFrame(number, depth, pose))
    return frames


def read_frames(path: Path) -> list[RgbdFrame]:
    """Return every frame of a recording, read back through RecordingReader."""
    with RecordingReader(path) as rec:
        return list(rec.frames())


def read_pgm16(path: Path) -> npt.NDArray[np.uint16]:
    """Return a binary 16-bit PGM (P5, big-endian samples), parsed without OpenCV."""
    data = path.read_bytes()
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:  # magic, width, height, maxval; '#' comments run to the line end
        while data[pos : pos + 1].isspace():
            pos += 1
        if data[pos : pos + 1] == b"#":
            pos = data.index(b"\n", pos)
            continue
        end = pos
        while not data[end : end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    assert fields[0] == b"P5" and int(fields[3]) > 255, fields
    w, h = int(fields[1]), int(fields[2])
    return np.frombuffer(data, ">u2", count=w * h, offset=pos + 1).reshape(h, w).astype(np.uint16)


def read_redwood_log(path: Path) -> list[npt.NDArray[np.float64]]:
    """Return the 4x4 matrices of a Redwood .log in file order."""
    lines = [line.split() for line in path.read_text().splitlines() if line.strip()]
    return [np.array(lines[b + 1 : b + 5], dtype=np.float64) for b in range(0, len(lines), 5)]


def write_redwood(src: Path, *, frames: int = 3, posed: tuple[int, ...] = (0, 2)) -> Path:
    """Write a 64x48 Redwood folder with an Open3D camera json and poses for `posed` frames."""
    (src / "color").mkdir(parents=True)
    (src / "depth").mkdir()
    for i in range(frames):
        write_color(src / "color" / f"{i:05d}.jpg", color_image(i)[:48, :64])
        assert cv2.imwrite(
            str(src / "depth" / f"{i:05d}.png"), np.full((48, 64), 800 + i, np.uint16)
        )
    # Column-major K of fx 50, fy 60, cx 31.5, cy 23.5: the transpose would swap cx into K[2, 0].
    k = [50.0, 0.0, 0.0, 0.0, 60.0, 0.0, 31.5, 23.5, 1.0]
    (src / "camera.json").write_text(f'{{"width": 64, "height": 48, "intrinsic_matrix": {k}}}')
    blocks = []
    for i in posed:
        pose = np.eye(4)
        pose[:3, 3] = [0.1 * i, 0.0, 0.0]
        blocks.append(f"{i} {i} {frames}\n" + "\n".join(" ".join(map(str, r)) for r in pose))
    (src / "trajectory.log").write_text("\n".join(blocks) + "\n")
    return src


def has_pose(frame: RgbdFrame) -> bool:
    """Return whether a frame read back carries a ground-truth pose."""
    return frame.ground_truth is not None and frame.ground_truth.world_from_camera is not None


def pose_of(frame: RgbdFrame) -> npt.NDArray[np.float64]:
    """Return a frame's ground-truth pose, failing the test when it has none."""
    assert frame.ground_truth is not None and frame.ground_truth.world_from_camera is not None
    return frame.ground_truth.world_from_camera


def imread(path: Path, flags: int = cv2.IMREAD_UNCHANGED) -> npt.NDArray[np.generic]:
    """Return an image read by OpenCV, failing the test when it cannot be read."""
    image = cv2.imread(str(path), flags)
    assert image is not None, path
    return np.asarray(image)
