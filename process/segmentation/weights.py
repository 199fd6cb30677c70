"""Checkpoints: our safetensors/.pt format, torchvision's published files, the torch hub cache.

Our checkpoint is a state dict plus metadata (architecture, output class -> label map, input
normalisation, the short side it was trained at, provenance). It is read with safetensors or
`torch.load(weights_only=True)`: no arbitrary object is ever unpickled.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import torch
from torch import nn

from capture.recording import NUM_LABELS, VOC_TO_LABEL
from process.errors import ModelError
from process.outputs import atomic_path
from process.segmentation.deeplab import PRESETS, ArchConfig, DeepLab
from process.segmentation.torchvision_map import (
    TORCHVISION_FILES,
    TORCHVISION_URL,
    map_torchvision,
    torchvision_kind,
)

logger = logging.getLogger(__name__)

FORMAT: Final = "semreplay-segmentation"
VERSION: Final = "1"
SAMPLES_CHECKPOINT: Final = (
    Path(__file__).resolve().parents[2] / "samples" / "segmentation.safetensors"
)
IMAGENET_MEAN: Final = (0.485, 0.456, 0.406)
IMAGENET_STD: Final = (0.229, 0.224, 0.225)
TORCHVISION_PREFIX: Final = "torchvision:"
MAX_CHANNELS: Final = 2048  # the largest head of any preset is 256 channels
MAX_ATROUS_RATE: Final = 256


@dataclass(frozen=True)
class Checkpoint:
    """A network's weights and what is needed to use them."""

    arch: ArchConfig
    state_dict: dict[str, torch.Tensor]
    class_to_label: tuple[int, ...]  # network output index -> RECORDING.md label
    mean: tuple[float, float, float] = IMAGENET_MEAN  # on RGB in [0, 1]
    std: tuple[float, float, float] = IMAGENET_STD
    short_side_px: int = 240  # the image short side the network expects
    info: dict[str, Any] = field(default_factory=dict)  # provenance: command, seed, mIoU
    path: Path | None = None


def save_checkpoint(ckpt: Checkpoint, path: Path, *, half: bool = False) -> Path:
    """Write a checkpoint as .safetensors (or .pt), atomically; half stores float16 tensors."""
    tensors = {k: _storable(v, half=half) for k, v in ckpt.state_dict.items()}
    meta = {
        "format": FORMAT,
        "version": VERSION,
        "architecture": ckpt.arch.to_json(),
        "class_to_label": json.dumps(list(ckpt.class_to_label)),
        "mean": json.dumps(list(ckpt.mean)),
        "std": json.dumps(list(ckpt.std)),
        "short_side_px": str(ckpt.short_side_px),
        "info": json.dumps(ckpt.info, sort_keys=True),
    }
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        if path.suffix == ".safetensors":
            from safetensors.torch import save_file

            save_file(tensors, str(tmp), metadata=meta)
        else:
            torch.save({**meta, "state_dict": tensors}, tmp)
    return path


def checkpoint_from_model(model: DeepLab, **kwargs: Any) -> Checkpoint:
    """Return a Checkpoint of a model's current weights (kwargs: Checkpoint's other fields)."""
    state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
    kwargs.setdefault("class_to_label", tuple(range(model.arch.num_classes)))
    return Checkpoint(arch=model.arch, state_dict=state, **kwargs)


def resolve_weights(spec: str | Path) -> Path:
    """Return the file a weights spec names: "" = shipped sample, "torchvision:NAME", or a path."""
    text = str(spec)
    if text == "":
        if not SAMPLES_CHECKPOINT.is_file():
            raise ModelError(
                "the shipped segmentation checkpoint is missing; restore it from git or pass "
                f"--weights: {SAMPLES_CHECKPOINT}"
            )
        return SAMPLES_CHECKPOINT
    if text.startswith(TORCHVISION_PREFIX):
        return torchvision_file(text.removeprefix(TORCHVISION_PREFIX))
    path = Path(text).expanduser()
    if not path.is_file():
        raise ModelError(
            "segmentation weights not found; expected a .safetensors/.pt/.pth checkpoint "
            f"(or '' for the shipped one, or 'torchvision:NAME'): {path}"
        )
    return path


def torchvision_file(name: str, *, download: bool = True) -> Path:
    """Return a torchvision checkpoint in the torch hub cache, downloading it when missing."""
    if name not in TORCHVISION_FILES:
        raise ModelError(
            f"unknown torchvision checkpoint {name!r}; choose one of {sorted(TORCHVISION_FILES)}"
        )
    filename = TORCHVISION_FILES[name]
    dst = Path(torch.hub.get_dir()) / "checkpoints" / filename
    if dst.is_file():
        return dst
    url = TORCHVISION_URL + filename
    if not download:
        raise ModelError(f"{filename} is not in the torch hub cache; download {url} to: {dst}")
    dst.parent.mkdir(parents=True, exist_ok=True)
    hash_prefix = filename.rsplit("-", 1)[1].split(".")[0]
    try:
        torch.hub.download_url_to_file(url, str(dst), hash_prefix=hash_prefix, progress=False)
    except (OSError, RuntimeError) as err:  # URLError is an OSError; a bad hash a RuntimeError
        reason = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise ModelError(
            f"cannot download {url} ({reason}); offline? fetch it elsewhere and put it at: {dst}"
        ) from err
    return dst


def load_checkpoint(path: Path) -> Checkpoint:
    """Read our checkpoint or a torchvision one; raise ModelError if unreadable or foreign."""
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"segmentation weights not found; expected a checkpoint file: {path}")
    tensors, meta = _read(path)
    if meta.get("format") == FORMAT:
        return _ours(tensors, meta, path)
    if torchvision_kind(tensors) is not None:
        return _from_torchvision(tensors, path)
    raise ModelError(
        f"not a segmentation checkpoint (no {FORMAT!r} metadata and not a torchvision "
        f"DeepLabV3/MobileNetV3 state dict; found keys like {sorted(tensors)[:3]}); "
        f"pass a checkpoint written by `semreplay-process train`: {path}"
    )


def build_from_checkpoint(ckpt: Checkpoint) -> DeepLab:
    """Build the network of a checkpoint and load its weights strictly."""
    model = DeepLab(ckpt.arch)
    expected = model.state_dict()
    # BatchNorm counters are bookkeeping, absent from older checkpoints: keep the defaults.
    missing = sorted(
        k for k in set(expected) - set(ckpt.state_dict) if not k.endswith("num_batches_tracked")
    )
    unexpected = sorted(set(ckpt.state_dict) - set(expected))
    wrong = sorted(
        k
        for k in set(expected) & set(ckpt.state_dict)
        if expected[k].shape != ckpt.state_dict[k].shape
    )
    if missing or unexpected or wrong:
        raise ModelError(
            f"checkpoint does not fit architecture {ckpt.arch.backbone}/{ckpt.arch.head}: "
            f"{len(missing)} missing keys {missing[:2]}, "
            f"{len(unexpected)} unexpected {unexpected[:2]}, "
            f"{len(wrong)} shape mismatches {wrong[:2]}; pass weights trained for it: {ckpt.path}"
        )
    state = {k: v.to(expected[k].dtype) for k, v in ckpt.state_dict.items()}
    model.load_state_dict({**expected, **state}, strict=True)
    return model.eval()


def _read(path: Path) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    try:
        if path.suffix == ".safetensors":
            from safetensors import safe_open

            with safe_open(str(path), framework="pt") as f:
                meta = dict(f.metadata() or {})
                return {k: f.get_tensor(k) for k in f.keys()}, meta  # noqa: SIM118
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # safetensors, zipfile and unpickler errors have no common base
        reason = str(err).splitlines()[0][:120] if str(err) else type(err).__name__
        raise ModelError(
            f"cannot read segmentation weights (corrupt, truncated or not a checkpoint: {reason}); "
            f"re-download or retrain them: {path}"
        ) from err
    if not isinstance(data, dict):
        raise ModelError(f"expected a dict checkpoint, found {type(data).__name__}: {path}")
    if "state_dict" in data and isinstance(data["state_dict"], dict):
        meta = {k: v for k, v in data.items() if k != "state_dict"}
        return dict(data["state_dict"]), meta
    if "model" in data and isinstance(data["model"], dict):  # torchvision reference-script format
        return dict(data["model"]), {}
    return {k: v for k, v in data.items() if isinstance(v, torch.Tensor)}, {}


def check_arch_bounds(arch: ArchConfig, path: Path | None) -> ArchConfig:
    """Refuse architectures whose layers would be absurdly large, before anything is allocated.

    A checkpoint's metadata is data: a corrupt or hostile one asking for 2**20 ASPP channels
    would allocate gigabytes in DeepLab's constructor before the weights are found not to fit.
    """
    sizes = {
        "aspp_channels": arch.aspp_channels,
        "decoder_channels": arch.decoder_channels,
        "low_level_channels": arch.low_level_channels,
    }
    too_big = {k: v for k, v in sizes.items() if v > MAX_CHANNELS}
    rates = [r for r in arch.atrous_rates if r > MAX_ATROUS_RATE]
    if too_big or rates:
        raise ModelError(
            f"checkpoint metadata asks for {too_big or ''} {rates or ''}; expected channels <= "
            f"{MAX_CHANNELS} and atrous rates <= {MAX_ATROUS_RATE} (corrupt metadata?): {path}"
        )
    return arch


def _ours(tensors: dict[str, torch.Tensor], meta: dict[str, Any], path: Path) -> Checkpoint:
    try:
        return Checkpoint(
            arch=check_arch_bounds(ArchConfig.from_json(meta["architecture"]), path),
            state_dict=tensors,
            class_to_label=tuple(int(v) for v in json.loads(meta["class_to_label"])),
            mean=_triple(json.loads(meta["mean"])),
            std=_triple(json.loads(meta["std"])),
            short_side_px=int(meta["short_side_px"]),
            info=dict(json.loads(meta.get("info", "{}"))),
            path=path,
        )
    except (KeyError, ValueError, TypeError, ModelError) as err:
        raise ModelError(
            f"checkpoint metadata is incomplete or invalid ({err}); retrain it: {path}"
        ) from err


def _from_torchvision(tensors: dict[str, torch.Tensor], path: Path) -> Checkpoint:
    mapped = map_torchvision(tensors, head="deeplabv3")
    if mapped.kind != "deeplabv3":
        raise ModelError(
            "this is torchvision's ImageNet mobilenet_v3_large (a backbone without a segmentation "
            f"head); use it as `train(..., init=...)`, not for inference: {path}"
        )
    logger.info(
        "torchvision DeepLabV3 checkpoint; dropped %d aux_classifier tensors", len(mapped.dropped)
    )
    return Checkpoint(
        arch=PRESETS["deeplabv3_mobilenet_v3_large"],
        state_dict=mapped.state_dict,
        class_to_label=VOC_TO_LABEL,
        short_side_px=520,  # torchvision's SemanticSegmentation(resize_size=520)
        info={"source": "torchvision deeplabv3_mobilenet_v3_large COCO_WITH_VOC_LABELS_V1"},
        path=path,
    )


def init_from(model: DeepLab, path: Path) -> list[str]:
    """Copy the fitting tensors of a checkpoint (ours or torchvision) into model; return others."""
    tensors, meta = _read(Path(path))
    if meta.get("format") != FORMAT and torchvision_kind(tensors) is not None:
        tensors = map_torchvision(tensors, head=model.arch.head).state_dict
    own = model.state_dict()
    usable = {k: v for k, v in tensors.items() if k in own and own[k].shape == v.shape}
    if not usable:
        raise ModelError(
            f"no tensor of this checkpoint fits the network {model.arch.backbone}: {path}"
        )
    model.load_state_dict({k: v.to(own[k].dtype) for k, v in usable.items()}, strict=False)
    return sorted(set(own) - set(usable))


def label_matrix(class_to_label: tuple[int, ...]) -> torch.Tensor:
    """Return the (labels, classes) 0/1 matrix that sums class probabilities into labels."""
    if any(not 0 <= v < NUM_LABELS for v in class_to_label):
        raise ModelError(f"class_to_label {class_to_label} has ids outside 0..{NUM_LABELS - 1}")
    m = torch.zeros(NUM_LABELS, len(class_to_label))
    m[list(class_to_label), list(range(len(class_to_label)))] = 1.0
    return m


def _storable(t: torch.Tensor, *, half: bool) -> torch.Tensor:
    t = t.detach().cpu().contiguous()
    return t.half() if half and t.is_floating_point() else t


def _triple(values: list[float]) -> tuple[float, float, float]:
    a, b, c = (float(v) for v in values)
    return a, b, c


def parameter_count(model: nn.Module) -> int:
    """Return the number of trainable parameters (torchvision's `num_params`)."""
    return sum(p.numel() for p in model.parameters())
