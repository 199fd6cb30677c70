"""Which segmentation model a run uses, and why: the shipped models and `choose_model`.

Shipped in `samples/` (see its README): the simulator checkpoint (`segmentation.safetensors`,
trained on simulated rooms only) and two real-image networks under Apache-2.0, DeepLabV3
MobileNetV2 on PASCAL VOC (int8) and on ADE20K (float). A recording from the simulated D435
gets the simulator checkpoint; any other recording (a real camera, an imported dataset) gets
the real-image networks combined (`combined.py`). `--weights`, then the config's `weights`,
`model` or a non-default `backend`, win over that rule.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from process.segmentation.config import SegmentationConfig
from process.segmentation.weights import SAMPLES_CHECKPOINT

SAMPLES: Final = SAMPLES_CHECKPOINT.parent
VOC_TFLITE: Final = SAMPLES / "deeplabv3_mnv2_pascal_quant.tflite"
ADE20K_TFLITE: Final = SAMPLES / "deeplabv3_mnv2_ade20k.tflite"
REAL_DEFAULT: Final = "combined"
SIMULATED_DEVICE: Final = (
    "simulated"  # capture.sim names its device "Simulated Intel RealSense D435"
)

# model name -> (backend, weights spec, what it is)
SHIPPED: Final[dict[str, tuple[str, str, str]]] = {
    "simulator": ("torch", "", "DeepLabV3+ MobileNetV3 trained on simulated rooms"),
    "voc": ("tflite", str(VOC_TFLITE), "DeepLabV3 MobileNetV2, PASCAL VOC, int8"),
    "ade20k": ("tflite", str(ADE20K_TFLITE), "DeepLabV3 MobileNetV2, ADE20K, float"),
    "combined": ("combined", "", "ADE20K and PASCAL VOC networks combined per pixel"),
}


@dataclass(frozen=True)
class ModelChoice:
    """The model a run uses: its name, its weights, its runtime and why it was chosen."""

    name: str  # a SHIPPED name, or the weights file's name
    path: Path | None  # the weights file; None for the combined pair
    backend: str
    reason: str


def is_simulated(device_name: str | None) -> bool:
    """Return whether a recording's `device` name says it comes from the simulator."""
    return device_name is not None and SIMULATED_DEVICE in device_name.lower()


def choose_model(
    cfg: SegmentationConfig, *, weights: Path | None = None, device_name: str | None = None
) -> ModelChoice:
    """Return the model for a recording whose `device` metadata names `device_name`.

    Order: `weights` (the --weights option), the config's `weights`, its `model`, a backend
    other than torch (the simulator checkpoint on that runtime), then the recording's device.
    """
    explicit = explicit_choice(cfg, weights=weights)
    if explicit is not None:
        return explicit
    device = f"device {device_name!r}" if device_name else "no device record"
    if is_simulated(device_name):
        return shipped("simulator", f"simulated recording ({device})", cfg)
    if importlib.util.find_spec("ai_edge_litert") is None:
        return shipped(
            "simulator",
            f"real recording ({device}) but ai-edge-litert is missing, so the real-image "
            "networks cannot run: pip install '.[tflite]'",
            cfg,
        )
    return shipped(REAL_DEFAULT, f"real recording ({device}): real-image networks", cfg)


def explicit_choice(cfg: SegmentationConfig, *, weights: Path | None = None) -> ModelChoice | None:
    """Return the model that `weights` or the config names explicitly, or None if neither does."""
    if weights is not None:
        return _weights_choice(Path(weights), cfg.backend, "--weights was given")
    if cfg.weights:
        return _weights_choice(Path(cfg.weights), cfg.backend, "segmentation.weights is set")
    if cfg.model != "auto":
        return shipped(cfg.model, f"segmentation.model = {cfg.model!r} in the config", cfg)
    if cfg.backend != "torch":
        name = "combined" if cfg.backend == "combined" else "simulator"
        return shipped(name, f"segmentation.backend = {cfg.backend!r} in the config", cfg)
    return None


def shipped(name: str, reason: str, cfg: SegmentationConfig | None = None) -> ModelChoice:
    """Return the choice of a shipped model by name."""
    backend, spec, _ = SHIPPED[name]
    if name == "simulator" and cfg is not None:
        backend = cfg.backend if cfg.backend != "combined" else "torch"  # tflite: an error
    path = SAMPLES_CHECKPOINT if name == "simulator" else (Path(spec) if spec else None)
    return ModelChoice(name=name, path=path, backend=backend, reason=reason)


def _weights_choice(path: Path, backend: str, reason: str) -> ModelChoice:
    if path.suffix == ".tflite":
        backend = "tflite"
    return ModelChoice(name=path.name, path=path, backend=backend, reason=reason)
