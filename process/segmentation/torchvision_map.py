"""Key mapping of torchvision's published MobileNetV3 / DeepLabV3 checkpoints into our modules.

torchvision `deeplabv3_mobilenet_v3_large` (COCO subset with the 20 VOC classes, 21 outputs,
file deeplabv3_mobilenet_v3_large-fc3c493d.pth) is DeepLabV3 without a decoder:

| torchvision key | ours (head "deeplabv3") | ours (head "deeplabv3plus") |
| --- | --- | --- |
| `backbone.{i}.*` (features 0-16, dilated) | `backbone.features.{i}.*` | same |
| `classifier.0.convs.*`, `.project.*` (ASPP 12/24/36) | `aspp.*` | same if ASPP not separable |
| `classifier.1`, `.2` (3x3 conv + BN) | `decoder.head.0`, `.1` | dropped: decoder untrained |
| `classifier.4` (1x1 to 21 classes) | `classifier` | dropped |
| `aux_classifier.*` (FCN head on stride 8, training only) | dropped | dropped |

The 21 VOC outputs become our labels through `VOC_TO_LABEL` (RECORDING.md) at inference time.
torchvision `mobilenet_v3_large` ImageNet checkpoints (-8738ca79 V1, -5c1a4163 V2) give
`features.{i}.*` -> `backbone.features.{i}.*`; their `classifier.*` (1000 ImageNet classes) is
dropped, so ASPP, decoder and classifier start untrained: use them as a training init.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

import torch

# Published checkpoints: name -> (file name, url). The hash in the name is a SHA-256 prefix.
TORCHVISION_FILES: Final = {
    "deeplabv3_mobilenet_v3_large": "deeplabv3_mobilenet_v3_large-fc3c493d.pth",
    "mobilenet_v3_large": "mobilenet_v3_large-8738ca79.pth",
    "mobilenet_v3_large_v2": "mobilenet_v3_large-5c1a4163.pth",
}
TORCHVISION_URL: Final = "https://download.pytorch.org/models/"

_DEEPLAB_RULES: Final = (
    (r"^backbone\.(\d+)\.", r"backbone.features.\1."),
    (r"^classifier\.0\.", "aspp."),
    (r"^classifier\.1\.", "decoder.head.0."),
    (r"^classifier\.2\.", "decoder.head.1."),
    (r"^classifier\.4\.", "classifier."),
    (r"^aux_classifier\.", None),
)
_IMAGENET_RULES: Final = (
    (r"^features\.", "backbone.features."),
    (r"^classifier\.", None),
)


@dataclass(frozen=True)
class Mapped:
    """A torchvision state dict renamed into our modules, with what was dropped."""

    kind: str  # "deeplabv3" or "imagenet_backbone"
    state_dict: dict[str, torch.Tensor]
    dropped: tuple[str, ...]


def torchvision_kind(state_dict: dict[str, torch.Tensor]) -> str | None:
    """Return "deeplabv3", "imagenet_backbone" or None for a non-torchvision state dict."""
    if "backbone.0.0.weight" in state_dict and "classifier.0.project.0.weight" in state_dict:
        return "deeplabv3"
    if "features.0.0.weight" in state_dict and "classifier.3.weight" in state_dict:
        return "imagenet_backbone"
    return None


def map_torchvision(state_dict: dict[str, torch.Tensor], *, head: str) -> Mapped:
    """Rename a torchvision checkpoint's keys into ours for a network with the given head."""
    kind = torchvision_kind(state_dict)
    if kind is None:
        raise ValueError(
            "not a torchvision deeplabv3_mobilenet_v3_large/mobilenet_v3_large state dict"
        )
    rules = _DEEPLAB_RULES if kind == "deeplabv3" else _IMAGENET_RULES
    out: dict[str, torch.Tensor] = {}
    dropped: list[str] = []
    for key, tensor in state_dict.items():
        new = _rename(key, rules)
        decoder_only = new is not None and (new.startswith(("decoder.", "classifier.")))
        if new is None or (head != "deeplabv3" and decoder_only):
            dropped.append(key)
        else:
            out[new] = tensor
    return Mapped(kind, out, tuple(dropped))


def _rename(key: str, rules: tuple[tuple[str, str | None], ...]) -> str | None:
    for pattern, repl in rules:
        if re.match(pattern, key):
            return None if repl is None else re.sub(pattern, repl, key)
    return key
