"""A simulated Intel RealSense D435: procedural indoor rooms, ray-cast rendering, D435 depth noise.

Entry points:
- `simulate_recording(path, seed=...)`: a whole recording with ground truth (what the CLI runs).
- `build_scene(seed)`: the furnished room of a seed (parts with labels and instance ids).
- `Renderer(scene)`: `render_color` (colour, labels, instances, exact depth in that camera),
  `render_depth` (the depth camera's exact view for the noise model) and `depth_image` (exact
  z-depth of any pinhole camera, without noise: known answers for registration and odometry).
- `FrameSimulator(seed)`: one frame as the recording holds it (noisy colour, D435 depth).
- `d435_rig(width, height)`: the colour and depth intrinsics and the depth-to-colour extrinsics.
"""

from __future__ import annotations

from capture.sim.gt_cloud import LabelledPoints, ply_bytes, read_ply, sample_scene
from capture.sim.noise import D435DepthModel
from capture.sim.render import CameraRig, ColorView, DepthView, Renderer, d435_rig
from capture.sim.scene import Scene, build_scene
from capture.sim.simulate import FrameSimulator, SimFrame, SimSummary, simulate_recording
from capture.sim.trajectory import Trajectory, handheld_loop

__all__ = [
    "CameraRig",
    "ColorView",
    "D435DepthModel",
    "DepthView",
    "FrameSimulator",
    "LabelledPoints",
    "Renderer",
    "Scene",
    "SimFrame",
    "SimSummary",
    "Trajectory",
    "build_scene",
    "d435_rig",
    "handheld_loop",
    "ply_bytes",
    "read_ply",
    "sample_scene",
    "simulate_recording",
]
