"""`semreplay-capture simulate`: a simulated D435 walking through a procedural room."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from capture.errors import CaptureError
from capture.recording import GT_CLOUD_ATTACHMENT, RecordingWriter
from capture.recording.writer import capture_record
from capture.sim.gt_cloud import ply_bytes, sample_scene
from capture.sim.noise import ColorSensorNoise, D435DepthModel
from capture.sim.render import CameraRig, ColorView, DepthView, Renderer, d435_rig
from capture.sim.scene import build_scene
from capture.sim.trajectory import handheld_loop

logger = logging.getLogger(__name__)

DEVICE_NAME: Final = "Simulated Intel RealSense D435"
GT_CLOUD_SPACING_M: Final = 0.02


@dataclass(frozen=True, slots=True)
class SimSummary:
    """What a simulation wrote."""

    path: Path
    seed: int
    frames: int
    fps: float
    duration_s: float  # recording time covered by the frames
    seconds: float  # wall time the simulation took
    gt_points: int  # points in the ground-truth cloud attachment


@dataclass(frozen=True, slots=True)
class SimFrame:
    """One simulated frame: the colour view with ground truth and the D435 depth image."""

    color: ColorView  # colour with sensor noise; labels, instances, exact depth in colour camera
    depth_mm: npt.NDArray[np.uint16]  # (H, W) D435 depth in the depth camera, 0 = none
    depth_view: DepthView  # the exact depth-camera view the noise was applied to


class FrameSimulator:
    """Render frames of one scene: colour and ground truth, and D435 depth with its noise."""

    def __init__(self, seed: int, *, width: int = 640, height: int = 480) -> None:
        self.scene = build_scene(seed)
        self.renderer = Renderer(self.scene)
        self.rig: CameraRig = d435_rig(width, height)
        self.depth_model = D435DepthModel()
        self._color_from_depth = self.rig.depth_to_color.color_from_depth
        self._rng = np.random.default_rng([seed, 11])
        self._color_noise = ColorSensorNoise(
            np.random.default_rng([seed, 12]), size=width * height * 3
        )
        self._pool = ThreadPoolExecutor(max_workers=2)

    def render(self, world_from_color: npt.NDArray[np.float64]) -> SimFrame:
        """Render one frame; the depth camera pose follows from the rig's extrinsics."""
        return next(self.frames(world_from_color[None]))

    def frames(self, world_from_color: npt.NDArray[np.float64]) -> Iterator[SimFrame]:
        """Yield the frames of poses (N, 4, 4) in order, rendering the next while one is used.

        Two workers ray-cast and shade the colour and the depth camera of the next frame while
        the caller handles this one (Embree and most of numpy release the GIL), so the two cores
        stay busy. The noise is drawn here, in order, so results do not depend on the timing.
        """
        pending = self._submit(world_from_color[0]) if len(world_from_color) else None
        for index in range(len(world_from_color)):
            assert pending is not None
            color_job, depth_job = pending
            more = index + 1 < len(world_from_color)
            pending = self._submit(world_from_color[index + 1]) if more else None
            yield self._finish(color_job.result(), depth_job.result())

    def _submit(
        self, world_from_color: npt.NDArray[np.float64]
    ) -> tuple[Future[ColorView], Future[DepthView]]:
        world_from_depth = world_from_color @ self._color_from_depth
        return (
            self._pool.submit(
                self.renderer.render_color, world_from_color, intrinsics=self.rig.color
            ),
            self._pool.submit(
                self.renderer.render_depth, world_from_depth, intrinsics=self.rig.depth
            ),
        )

    def _finish(self, view: ColorView, depth_view: DepthView) -> SimFrame:
        color = self._color_noise.apply(view.color)
        depth_mm = self.depth_model.apply(depth_view, focal_px=self.rig.depth.fx, rng=self._rng)
        noisy = ColorView(color, view.labels, view.instances, view.depth_m)
        return SimFrame(noisy, depth_mm, depth_view)

    def close(self) -> None:
        """Stop the worker threads."""
        self._pool.shutdown()

    def __enter__(self) -> FrameSimulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def simulate_recording(
    path: Path,
    *,
    seed: int = 0,
    frames: int = 300,
    fps: float = 30.0,
    width: int = 640,
    height: int = 480,
    compression: str = "zstd",
) -> SimSummary:
    """Write a simulated D435 recording with ground truth, exactly as a real capture is written."""
    if frames < 1 or fps <= 0 or width < 16 or height < 16:
        raise CaptureError(
            f"expected frames >= 1, fps > 0 and an image of at least 16x16; got frames={frames}, "
            f"fps={fps}, {width}x{height}: {path}"
        )
    started = time.perf_counter()
    with FrameSimulator(seed, width=width, height=height) as sim:
        cloud = _write(path, sim, seed=seed, frames=frames, fps=fps, compression=compression)
    seconds = time.perf_counter() - started
    logger.info("simulated %d frames of seed %d in %.1f s: %s", frames, seed, seconds, path)
    return SimSummary(Path(path), seed, frames, fps, frames / fps, seconds, cloud)


def _write(
    path: Path, sim: FrameSimulator, *, seed: int, frames: int, fps: float, compression: str
) -> int:
    """Write the recording; return the number of ground-truth cloud points."""
    trajectory = handheld_loop(sim.scene, frames=frames, fps=fps, seed=seed)
    stamps = [int(s) for s in trajectory.stamps_ns]
    cloud = sample_scene(sim.scene, renderer=sim.renderer, spacing_m=GT_CLOUD_SPACING_M, seed=seed)
    config = {
        "seed": seed,
        "frames": frames,
        "fps": fps,
        "width": sim.rig.color.width,
        "height": sim.rig.color.height,
        "compression": compression,
        "gt_cloud_spacing_m": GT_CLOUD_SPACING_M,
    }
    with RecordingWriter(path, compression=compression) as writer:
        writer.write_metadata("device", _device(seed))
        writer.write_calibration(sim.rig.depth_to_color, stamp_ns=stamps[0])
        writer.write_attachment(
            GT_CLOUD_ATTACHMENT, ply_bytes(cloud), media_type="application/x-ply", log_ns=stamps[0]
        )
        poses = trajectory.world_from_camera
        for index, frame in enumerate(sim.frames(poses)):
            _write_frame(writer, sim, frame, index=index, stamp_ns=stamps[index], pose=poses[index])
        writer.finish(_capture_summary(config, frames, stamps[0]))
    return len(cloud.labels)


def _write_frame(
    writer: RecordingWriter,
    sim: FrameSimulator,
    frame: SimFrame,
    *,
    index: int,
    stamp_ns: int,
    pose: npt.NDArray[np.float64],
) -> None:
    metadata = {
        "frame_number": index,
        "frame_timestamp": stamp_ns / 1e6,
        "clock_domain": "simulated",
    }
    writer.write_color(
        frame.color.color, stamp_ns=stamp_ns, intrinsics=sim.rig.color, metadata=metadata
    )
    writer.write_depth(
        frame.depth_mm, stamp_ns=stamp_ns, intrinsics=sim.rig.depth, metadata=metadata
    )
    writer.write_ground_truth(
        stamp_ns=stamp_ns,
        world_from_camera=pose,
        labels=frame.color.labels,
        instances=frame.color.instances,
    )


def _device(seed: int) -> dict[str, str]:
    return {
        "name": DEVICE_NAME,
        "serial_number": f"SIM-{seed}",
        "firmware_version": "simulated",
        "usb_type": "simulated",
        "product_line": "D400",
        "depth_scale_m": "0.001",
        "simulated": "true",
    }


def _capture_summary(config: dict[str, object], frames: int, start_ns: int) -> dict[str, object]:
    return capture_record(
        "semreplay-capture simulate",
        source="simulator",
        config=config,
        host="simulator",
        start_time=datetime.fromtimestamp(start_ns / 1e9, tz=UTC).isoformat(),
        frames_written={"color": frames, "depth": frames, "ground_truth": frames},
        frames_dropped={"color": 0, "depth": 0},
    )
