"""DeepLabV3+ (and torchvision's DeepLabV3 layout) on a MobileNetV3 backbone.

DeepLabV3+ (Chen et al. 2018, the paper's network): ASPP on the stride-16 features (a 1x1
branch, three 3x3 atrous branches, image pooling), then a decoder that upsamples to stride 4,
concatenates projected low-level features and refines with two 3x3 convolutions. The `lite`
presets use depthwise-separable 3x3 convolutions in ASPP and decoder (as in the DeepLabV3+
paper's Xception variant) and narrower channels, for CPU speed. Head "deeplabv3" reproduces
torchvision's `deeplabv3_mobilenet_v3_large` exactly, so its VOC checkpoint loads unchanged.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from typing import Any, Final

import torch
from torch import nn
from torch.nn import functional as F  # noqa: N812 (the torch convention)

from capture.recording import NUM_LABELS
from process.errors import ModelError
from process.segmentation.mobilenetv3 import VARIANTS, ConvBNAct, MobileNetV3Features

HEADS: Final = ("deeplabv3plus", "deeplabv3")


@dataclass(frozen=True)
class ArchConfig:
    """Everything needed to rebuild a network; stored in every checkpoint."""

    backbone: str = "mobilenet_v3_large"
    width_mult: float = 1.0
    dilated: bool = True  # output stride 16 (True) or 32
    head: str = "deeplabv3plus"
    separable: bool = False  # depthwise-separable 3x3 convs in ASPP and decoder
    aspp_channels: int = 256
    atrous_rates: tuple[int, int, int] = (6, 12, 18)
    aspp_dropout: float = 0.5
    low_level_channels: int = 48
    decoder_channels: int = 256
    num_classes: int = NUM_LABELS

    def __post_init__(self) -> None:
        problems = []
        if self.backbone not in VARIANTS:
            problems.append(f"backbone {self.backbone!r} not in {sorted(VARIANTS)}")
        if self.head not in HEADS:
            problems.append(f"head {self.head!r} not in {list(HEADS)}")
        if not 0.1 <= self.width_mult <= 2.0:
            problems.append(f"width_mult {self.width_mult} outside [0.1, 2]")
        if min(self.aspp_channels, self.decoder_channels, self.low_level_channels) < 8:
            problems.append("channel counts below 8")
        if not 2 <= self.num_classes <= 256:
            problems.append(f"num_classes {self.num_classes} outside [2, 256]")
        if len(self.atrous_rates) != 3 or min(self.atrous_rates) < 1:
            problems.append(f"atrous_rates {self.atrous_rates} are not 3 positive ints")
        if problems:
            raise ModelError(f"invalid architecture: {'; '.join(problems)}")

    def to_json(self) -> str:
        """Return the config as a JSON string."""
        return json.dumps(asdict(self), sort_keys=True)

    @staticmethod
    def from_json(text: str) -> ArchConfig:
        """Parse a config written by `to_json`; unknown keys are an error."""
        data: dict[str, Any] = json.loads(text)
        known = set(ArchConfig.__dataclass_fields__)
        if unknown := sorted(set(data) - known):
            raise ModelError(
                f"unknown architecture keys {unknown}; expected a subset of {sorted(known)}"
            )
        if "atrous_rates" in data:
            data["atrous_rates"] = tuple(data["atrous_rates"])
        return ArchConfig(**data)


PRESETS: Final[dict[str, ArchConfig]] = {
    # The paper's network at the DeepLabV3+ paper's sizes.
    "deeplabv3plus_mobilenet_v3_large": ArchConfig(),
    # CPU-oriented: separable convs, 128-wide ASPP/decoder, 32 low-level channels.
    "deeplabv3plus_lite_mobilenet_v3_large": ArchConfig(
        separable=True, aspp_channels=128, decoder_channels=128, low_level_channels=32,
        aspp_dropout=0.1,
    ),
    "deeplabv3plus_lite_mobilenet_v3_small": ArchConfig(
        backbone="mobilenet_v3_small", separable=True, aspp_channels=96, decoder_channels=96,
        low_level_channels=24, aspp_dropout=0.1,
    ),
    # torchvision's deeplabv3_mobilenet_v3_large (COCO with VOC labels): no decoder, rates 12/24/36.
    "deeplabv3_mobilenet_v3_large": ArchConfig(
        head="deeplabv3", atrous_rates=(12, 24, 36), num_classes=21
    ),
}  # fmt: skip


class SeparableConvBNReLU(nn.Sequential):
    """Depthwise 3x3 (+BN+ReLU) then pointwise 1x1 (+BN+ReLU)."""

    def __init__(self, in_ch: int, out_ch: int, *, dilation: int = 1) -> None:
        super().__init__(
            ConvBNAct(in_ch, in_ch, 3, dilation=dilation, groups=in_ch),
            ConvBNAct(in_ch, out_ch, 1),
        )


def conv3x3(in_ch: int, out_ch: int, *, dilation: int = 1, separable: bool) -> nn.Module:
    """Return a 3x3 conv + BN + ReLU block, depthwise-separable when asked."""
    if separable:
        return SeparableConvBNReLU(in_ch, out_ch, dilation=dilation)
    return ConvBNAct(in_ch, out_ch, 3, dilation=dilation)


class ASPPPooling(nn.Sequential):
    """Image-level features: global average, 1x1 conv, broadcast back to the input size."""

    def __init__(self, in_ch: int, out_ch: int) -> None:
        super().__init__(
            nn.AdaptiveAvgPool2d(1),
            nn.Conv2d(in_ch, out_ch, 1, bias=False),
            nn.BatchNorm2d(out_ch),
            nn.ReLU(),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Return pooled features expanded to x's spatial size."""
        y = x
        for module in self:
            y = module(y)
        # A 1x1 map upsampled bilinearly is a broadcast; expand is cheaper and exports cleanly.
        return y.expand(-1, -1, x.shape[2], x.shape[3])


class ASPP(nn.Module):
    """Atrous spatial pyramid pooling: 1x1, three atrous 3x3, image pooling, 1x1 projection."""

    def __init__(self, in_ch: int, arch: ArchConfig) -> None:
        super().__init__()
        c = arch.aspp_channels
        branches: list[nn.Module] = [ConvBNAct(in_ch, c, 1)]
        branches += [
            conv3x3(in_ch, c, dilation=r, separable=arch.separable) for r in arch.atrous_rates
        ]
        branches.append(ASPPPooling(in_ch, c))
        self.convs = nn.ModuleList(branches)
        self.project = nn.Sequential(
            nn.Conv2d(len(branches) * c, c, 1, bias=False),
            nn.BatchNorm2d(c),
            nn.ReLU(),
            nn.Dropout(arch.aspp_dropout),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Return the fused multi-scale features at x's resolution."""
        out: torch.Tensor = self.project(torch.cat([branch(x) for branch in self.convs], dim=1))
        return out


class PlusDecoder(nn.Module):
    """DeepLabV3+ decoder: upsample ASPP x4, concat projected stride-4 features, two 3x3 convs."""

    def __init__(self, low_in: int, arch: ArchConfig) -> None:
        super().__init__()
        self.project = ConvBNAct(low_in, arch.low_level_channels, 1)
        fused_in = arch.aspp_channels + arch.low_level_channels
        self.fuse = nn.Sequential(
            conv3x3(fused_in, arch.decoder_channels, separable=arch.separable),
            conv3x3(arch.decoder_channels, arch.decoder_channels, separable=arch.separable),
        )

    def forward(self, aspp: torch.Tensor, low: torch.Tensor) -> torch.Tensor:
        """Return decoder features at the low-level (stride-4) resolution."""
        up = F.interpolate(aspp, size=low.shape[2:], mode="bilinear", align_corners=False)
        out: torch.Tensor = self.fuse(torch.cat([up, self.project(low)], dim=1))
        return out


class V3Head(nn.Module):
    """torchvision DeepLabHead after ASPP: one 3x3 conv at the output stride (no decoder)."""

    def __init__(self, arch: ArchConfig) -> None:
        super().__init__()
        self.head = ConvBNAct(arch.aspp_channels, arch.decoder_channels, 3)

    def forward(self, aspp: torch.Tensor, low: torch.Tensor) -> torch.Tensor:
        """Return head features at the ASPP resolution (low-level features are unused)."""
        del low
        out: torch.Tensor = self.head(aspp)
        return out


class DeepLab(nn.Module):
    """Backbone -> ASPP -> decoder -> 1x1 classifier -> logits at the input resolution."""

    def __init__(self, arch: ArchConfig) -> None:
        super().__init__()
        self.arch = arch
        self.backbone = MobileNetV3Features(
            arch.backbone, width_mult=arch.width_mult, dilated=arch.dilated
        )
        self.aspp = ASPP(self.backbone.out_channels, arch)
        self.decoder: nn.Module
        if arch.head == "deeplabv3plus":
            self.decoder = PlusDecoder(self.backbone.low_level_channels, arch)
        else:
            self.decoder = V3Head(arch)
        self.classifier = nn.Conv2d(arch.decoder_channels, arch.num_classes, 1)
        _init_weights(self)

    def forward(self, x: torch.Tensor, *, upsample: bool = True) -> torch.Tensor:
        """Return logits (N, classes, H, W) of a normalised batch (N, 3, H, W).

        With upsample=False the logits stay at the decoder's resolution (stride 4, or the
        output stride for head "deeplabv3"), for callers that resize once to another size.
        """
        low, high = self.backbone(x)
        logits: torch.Tensor = self.classifier(self.decoder(self.aspp(high), low))
        if not upsample:
            return logits
        return F.interpolate(logits, size=x.shape[2:], mode="bilinear", align_corners=False)


def build_model(arch: ArchConfig | str) -> DeepLab:
    """Build a network from an ArchConfig or a preset name."""
    if isinstance(arch, str):
        if arch not in PRESETS:
            raise ModelError(f"unknown architecture {arch!r}; choose one of {sorted(PRESETS)}")
        arch = PRESETS[arch]
    return DeepLab(arch)


def _init_weights(model: nn.Module) -> None:
    # torchvision's MobileNetV3 initialisation (kaiming fan-out convs, unit BN).
    for m in model.modules():
        if isinstance(m, nn.Conv2d):
            nn.init.kaiming_normal_(m.weight, mode="fan_out")
            if m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, nn.BatchNorm2d):
            nn.init.ones_(m.weight)
            nn.init.zeros_(m.bias)
