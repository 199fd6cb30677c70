"""Helpers of the segmentation tests: torchvision manifests, fake checkpoints, labelled scenes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import numpy.typing as npt
import torch

from capture.recording import Intrinsics, RecordingWriter
from process.segmentation.deeplab import build_model
from process.segmentation.weights import Checkpoint, checkpoint_from_model, save_checkpoint

FIXTURES = Path(__file__).resolve().parent / "fixtures"

# A colour per label for the synthetic scenes (distinct, so a tiny network separates them fast).
SCENE_COLORS = {
    0: (20, 20, 20),
    2: (150, 100, 60),
    3: (200, 200, 190),
    4: (240, 150, 20),
    9: (30, 60, 220),
}


def manifest(name: str) -> dict[str, object]:
    """Return a committed manifest of a torchvision checkpoint's keys and shapes."""
    data: dict[str, object] = json.loads(
        (FIXTURES / f"torchvision_manifest_{name}.json").read_text()
    )
    return data


def fake_torchvision_state(name: str, *, seed: int = 0) -> dict[str, torch.Tensor]:
    """Return random tensors with exactly the keys and shapes of a torchvision checkpoint."""
    gen = torch.Generator().manual_seed(seed)
    out: dict[str, torch.Tensor] = {}
    keys = manifest(name)["keys"]
    assert isinstance(keys, list)
    for key, shape in keys:
        if key.endswith("num_batches_tracked"):
            out[key] = torch.tensor(1000, dtype=torch.int64)
        elif key.endswith("running_var"):
            out[key] = torch.rand(shape, generator=gen) + 0.5
        else:
            out[key] = torch.randn(shape, generator=gen) * 0.1
    return out


def random_checkpoint(arch: str, *, seed: int = 0, logit_gain: float = 3.0) -> Checkpoint:
    """Return an untrained checkpoint with calibrated BatchNorm statistics and a decisive argmax.

    Freshly initialised BatchNorm statistics make activations vanish layer by layer; a few
    forward passes in training mode over smooth random images set them to the data's.
    """
    torch.manual_seed(seed)
    model = build_model(arch)
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.momentum = None  # cumulative average over the calibration passes
    with torch.no_grad():
        model.train()
        for _ in range(3):
            model(torch.nn.functional.avg_pool2d(torch.randn(2, 3, 96, 128), 5, 1, 2) * 3)
        model.classifier.weight.mul_(logit_gain)
    model.eval()
    return checkpoint_from_model(model, short_side_px=96)


def write_random_checkpoint(
    path: Path, arch: str = "deeplabv3plus_lite_mobilenet_v3_small", *, seed: int = 0
) -> Path:
    """Write `random_checkpoint` to path and return it."""
    return save_checkpoint(random_checkpoint(arch, seed=seed), path)


def synthetic_scene(
    rng: np.random.Generator, *, height: int = 96, width: int = 128
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint8]]:
    """Return (colour, labels) of a wall over a floor with a table and a monitor, colour-coded."""
    labels = np.full((height, width), 3, np.uint8)
    labels[int(height * rng.uniform(0.55, 0.7)) :] = 2
    for label in (4, 9):
        h, w = (
            int(rng.integers(height // 6, height // 3)),
            int(rng.integers(width // 6, width // 3)),
        )
        y, x = int(rng.integers(0, height - h)), int(rng.integers(0, width - w))
        labels[y : y + h, x : x + w] = label
    palette = np.zeros((256, 3), np.uint8)
    for label, rgb in SCENE_COLORS.items():
        palette[label] = rgb
    noise = rng.normal(0.0, 12.0, (height, width, 3))
    color = np.clip(palette[labels].astype(np.float64) + noise, 0, 255).astype(np.uint8)
    return color, labels


def write_labelled_recording(path: Path, *, frames: int = 6, seed: int = 0) -> Path:
    """Write a recording of synthetic scenes with /ground_truth/labels (aligned depth)."""
    rng = np.random.default_rng(seed)
    k = Intrinsics(128, 96, 100.0, 100.0, 64.0, 48.0)
    with RecordingWriter(path) as writer:
        for i in range(frames):
            stamp_ns = 1_000_000_000 + i * 33_333_333
            color, labels = synthetic_scene(rng)
            writer.write_color(color, stamp_ns=stamp_ns, intrinsics=k)
            writer.write_depth(
                np.full((96, 128), 1500, np.uint16), stamp_ns=stamp_ns, intrinsics=k, aligned=True
            )
            writer.write_ground_truth(stamp_ns=stamp_ns, world_from_camera=np.eye(4), labels=labels)
    return path
