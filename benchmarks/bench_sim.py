"""The simulated D435: rendering speed, the whole simulate command, and the depth-noise model.

- render: colour, labels, instances, exact depth in the colour camera, the depth camera's view and
  its D435 noise, for 60 frames of a 640x480 handheld walk (seed 1), pipelined as the simulator
  runs it; beside the issue's goal (20 frames/s), the camera's 30 frames/s, and the bare Open3D
  ray casts a frame needs (two cameras, measured in the same run).
- simulate: `simulate_recording` end to end (scene, GT cloud, rendering, MCAP writing).
- noise: the depth spread the simulator records on a wall at 1 m and 3 m, beside Intel's RMS
  formula it implements.
Wall-clock figures depend on what else runs on the machine; the CPU-time row says how many frames
per second two idle cores would give (CPU seconds per frame / 2).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import open3d as o3d

from benchmarks.common import Row
from capture.sim import FrameSimulator, d435_rig, handheld_loop, simulate_recording
from capture.sim.noise import D435DepthModel
from capture.sim.placement import LoopPath, PlacedPart
from capture.sim.render import DepthView, Renderer
from capture.sim.scene import Scene
from capture.sim.shapes import plane_grid
from capture.sim.textures import Material

FRAMES = 60
SIM_FRAMES = 60
GOAL_FPS = 20.0
CAMERA_FPS = 30.0


def _render_fps() -> tuple[float, float, float]:
    """Return (wall frames/s, frames/s two cores give by CPU time, ms of bare ray casts)."""
    with FrameSimulator(1) as sim:
        poses = handheld_loop(sim.scene, frames=FRAMES, fps=30.0, seed=1).world_from_camera
        next(sim.frames(poses[:1]))  # warm up: BVH build, caches
        wall, cpu = time.perf_counter(), time.process_time()
        count = sum(1 for _ in sim.frames(poses))
        wall_fps = count / (time.perf_counter() - wall)
        cpu_fps = 2.0 * count / (time.process_time() - cpu)
        cast_ms = _bare_casts_ms(sim, poses[::6])
    return wall_fps, cpu_fps, cast_ms


def _bare_casts_ms(sim: FrameSimulator, poses: np.ndarray) -> float:
    """Return the best time of Open3D's cast_rays alone for one frame's two cameras."""
    scene = o3d.t.geometry.RaycastingScene()
    for part in sim.scene.parts:
        scene.add_triangles(
            o3d.core.Tensor.from_numpy(part.mesh.vertices.astype(np.float32)),
            o3d.core.Tensor.from_numpy(part.mesh.triangles.astype(np.uint32)),
        )
    best = float("inf")
    for pose in poses:
        rays = []
        for k, world_from_camera in (
            (sim.rig.color, pose),
            (sim.rig.depth, pose @ sim.rig.depth_to_color.color_from_depth),
        ):
            rays.append(
                o3d.t.geometry.RaycastingScene.create_rays_pinhole(
                    o3d.core.Tensor.from_numpy(k.matrix),
                    o3d.core.Tensor.from_numpy(np.linalg.inv(world_from_camera)),
                    k.width,
                    k.height,
                )
            )
        t0 = time.perf_counter()
        for r in rays:
            scene.cast_rays(r)
        best = min(best, time.perf_counter() - t0)
    return best * 1000.0


def _simulate_fps() -> float:
    with tempfile.TemporaryDirectory() as tmp:
        summary = simulate_recording(Path(tmp) / "bench.mcap", seed=1, frames=SIM_FRAMES)
    return summary.frames / summary.seconds


def _noise_spread_mm(depth_m: float) -> tuple[float, float]:
    """Return (recorded spread, Intel's formula) in mm for a textured wall at depth_m."""
    wall = plane_grid((-20.0, -20.0, depth_m), (0.0, 40.0, 0.0), (40.0, 0.0, 0.0), cell_m=5.0)
    part = PlacedPart(wall, Material("noise", (0.6, 0.6, 0.6)), 3, 1)
    lights = np.array([[0.0, 0.0, 0.0]])
    scene = Scene(0, (40.0, 40.0, 40.0), (part,), {1: "wall"}, lights, LoopPath((0, 0), (1, 1)))
    rig = d435_rig()
    view: DepthView = Renderer(scene).render_depth(np.eye(4), intrinsics=rig.depth)
    model = D435DepthModel()
    depth_mm = model.apply(view, focal_px=rig.depth.fx, rng=np.random.default_rng(0))
    valid = depth_mm[depth_mm > 0].astype(np.float64)
    formula = float(model.rms_error_m(depth_m, focal_px=rig.depth.fx)) * 1000.0
    return float(np.std(valid)), formula


def _fps_row(metric: str, fps: float, reference: float, source: str) -> Row:
    goal = ">= 20" if reference == GOAL_FPS else ""
    return Row("sim", metric, "frames/s", fps, reference, source, higher_is_better=True, goal=goal)


def run() -> list[Row]:
    """Measure the simulator's speed and its noise model."""
    wall_fps, cpu_fps, cast_ms = _render_fps()
    rows = [
        _fps_row("render 640x480 (colour+GT+depth+noise)", wall_fps, GOAL_FPS, "issue 3 goal"),
        _fps_row("render 640x480, wall clock", wall_fps, CAMERA_FPS, "D435 frame rate"),
        _fps_row("render 640x480, 2 idle cores (CPU time)", cpu_fps, GOAL_FPS, "issue 3 goal"),
        Row("sim", "render time per frame", "ms", 1000.0 / wall_fps, cast_ms,
            "Open3D cast_rays alone, both cameras (same run)"),
        _fps_row("simulate command (render+GT+MCAP)", _simulate_fps(), GOAL_FPS, "issue 3 goal"),
    ]  # fmt: skip
    for depth_m in (1.0, 3.0):
        spread, formula = _noise_spread_mm(depth_m)
        metric = f"depth spread on a wall at {depth_m:.0f} m"
        rows.append(Row("sim", metric, "mm", spread, formula, "Intel RMS formula z^2*0.08/(f*B)"))
    return rows
