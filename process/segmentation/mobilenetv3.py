"""MobileNetV3 (Large and Small) feature extractor, laid out like torchvision's `features`.

The module tree (`features.{i}.block.{j}...`, BatchNorm eps 1e-3) matches torchvision's
`mobilenet_v3_large(dilated=True).features`, so its published checkpoints map onto it by a
prefix rename (see weights.py). The forward pass returns the stride-4 low-level features that
the DeepLabV3+ decoder fuses and the stride-16 (dilated last stage) or stride-32 output.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Final

import torch
from torch import nn

# BatchNorm settings of torchvision's MobileNetV3 (TF-style momentum).
_norm = partial(nn.BatchNorm2d, eps=0.001, momentum=0.01)


def make_divisible(value: float, divisor: int = 8) -> int:
    """Round a channel count to a multiple of `divisor`, never more than 10 % below `value`."""
    new = max(divisor, int(value + divisor / 2) // divisor * divisor)
    if new < 0.9 * value:
        new += divisor
    return new


@dataclass(frozen=True, slots=True)
class BlockSpec:
    """One inverted-residual block of the MobileNetV3 tables (paper Tables 1-2)."""

    in_ch: int
    kernel: int
    expanded: int
    out_ch: int
    use_se: bool
    hardswish: bool
    stride: int
    dilation: int


# (in, kernel, expanded, out, SE, activation HS?, stride); the last 3 rows are the C4 stage.
_LARGE: Final = (
    (16, 3, 16, 16, False, False, 1),
    (16, 3, 64, 24, False, False, 2),
    (24, 3, 72, 24, False, False, 1),
    (24, 5, 72, 40, True, False, 2),
    (40, 5, 120, 40, True, False, 1),
    (40, 5, 120, 40, True, False, 1),
    (40, 3, 240, 80, False, True, 2),
    (80, 3, 200, 80, False, True, 1),
    (80, 3, 184, 80, False, True, 1),
    (80, 3, 184, 80, False, True, 1),
    (80, 3, 480, 112, True, True, 1),
    (112, 3, 672, 112, True, True, 1),
    (112, 5, 672, 160, True, True, 2),
    (160, 5, 960, 160, True, True, 1),
    (160, 5, 960, 160, True, True, 1),
)
_SMALL: Final = (
    (16, 3, 16, 16, True, False, 2),
    (16, 3, 72, 24, False, False, 2),
    (24, 3, 88, 24, False, False, 1),
    (24, 5, 96, 40, True, True, 2),
    (40, 5, 240, 40, True, True, 1),
    (40, 5, 240, 40, True, True, 1),
    (40, 5, 120, 48, True, True, 1),
    (48, 5, 144, 48, True, True, 1),
    (48, 5, 288, 96, True, True, 2),
    (96, 5, 576, 96, True, True, 1),
    (96, 5, 576, 96, True, True, 1),
)
VARIANTS: Final = {"mobilenet_v3_large": _LARGE, "mobilenet_v3_small": _SMALL}
_LAST_STAGE_BLOCKS: Final = 3  # the C4 stage: dilated instead of strided at output stride 16


def block_specs(variant: str, *, width_mult: float, dilated: bool) -> list[BlockSpec]:
    """Return the block table of a variant with channels scaled and the last stage dilated."""
    rows = VARIANTS[variant]
    specs = []
    for i, (cin, k, exp, cout, se, hs, s) in enumerate(rows):
        dilation = 2 if dilated and i >= len(rows) - _LAST_STAGE_BLOCKS else 1
        c_in, c_exp, c_out = (make_divisible(c * width_mult) for c in (cin, exp, cout))
        specs.append(BlockSpec(c_in, k, c_exp, c_out, se, hs, s, dilation))
    return specs


class ConvBNAct(nn.Sequential):
    """Conv2d (no bias) + BatchNorm + optional activation; keys `0.weight`, `1.*` as torchvision."""

    def __init__(
        self,
        in_ch: int,
        out_ch: int,
        kernel: int = 1,
        *,
        stride: int = 1,
        dilation: int = 1,
        groups: int = 1,
        act: type[nn.Module] | None = nn.ReLU,
        norm: type[nn.Module] | partial[nn.BatchNorm2d] = nn.BatchNorm2d,
    ) -> None:
        padding = (kernel - 1) // 2 * dilation
        layers: list[nn.Module] = [
            nn.Conv2d(in_ch, out_ch, kernel, stride, padding, dilation, groups, bias=False),
            norm(out_ch),
        ]
        if act is not None:
            layers.append(act())
        super().__init__(*layers)


class SqueezeExcitation(nn.Module):
    """Channel attention of MobileNetV3: avg-pool, 1x1 ReLU, 1x1 hard-sigmoid, rescale."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        squeeze = make_divisible(channels // 4)
        self.fc1 = nn.Conv2d(channels, squeeze, 1)
        self.fc2 = nn.Conv2d(squeeze, channels, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Rescale the channels of x."""
        s = torch.relu(self.fc1(x.mean((2, 3), keepdim=True)))
        return x * nn.functional.hardsigmoid(self.fc2(s))


class InvertedResidual(nn.Module):
    """Expand 1x1, depthwise kxk (strided or dilated), optional SE, project 1x1, residual."""

    def __init__(self, spec: BlockSpec) -> None:
        super().__init__()
        act: type[nn.Module] = nn.Hardswish if spec.hardswish else nn.ReLU
        layers: list[nn.Module] = []
        if spec.expanded != spec.in_ch:
            layers.append(ConvBNAct(spec.in_ch, spec.expanded, 1, act=act, norm=_norm))
        stride = 1 if spec.dilation > 1 else spec.stride  # dilation replaces the stride
        layers.append(
            ConvBNAct(
                spec.expanded,
                spec.expanded,
                spec.kernel,
                stride=stride,
                dilation=spec.dilation,
                groups=spec.expanded,
                act=act,
                norm=_norm,
            )
        )
        if spec.use_se:
            layers.append(SqueezeExcitation(spec.expanded))
        layers.append(ConvBNAct(spec.expanded, spec.out_ch, 1, act=None, norm=_norm))
        self.block = nn.Sequential(*layers)
        self.use_residual = spec.stride == 1 and spec.in_ch == spec.out_ch
        self.out_channels = spec.out_ch

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Apply the block."""
        y: torch.Tensor = self.block(x)
        return y + x if self.use_residual else y


class MobileNetV3Features(nn.Module):
    """The convolutional part of MobileNetV3 returning (stride-4, stride-16 or 32) features."""

    def __init__(self, variant: str, *, width_mult: float = 1.0, dilated: bool = True) -> None:
        super().__init__()
        specs = block_specs(variant, width_mult=width_mult, dilated=dilated)
        layers: list[nn.Module] = [
            ConvBNAct(3, specs[0].in_ch, 3, stride=2, act=nn.Hardswish, norm=_norm)
        ]
        layers += [InvertedResidual(s) for s in specs]
        last_in = specs[-1].out_ch
        layers.append(ConvBNAct(last_in, 6 * last_in, 1, act=nn.Hardswish, norm=_norm))
        self.features = nn.Sequential(*layers)
        # Low-level output: the last layer before the first block that goes to stride 8.
        strides = [2] + [s.stride for s in specs]
        reach_8 = next(i for i in range(len(strides)) if _prod(strides[: i + 1]) >= 8)
        self.low_level_index = reach_8 - 1
        self.low_level_channels = _out_channels(layers[self.low_level_index])
        self.out_channels = 6 * last_in
        self.output_stride = 16 if dilated else 32

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Return (low-level features at stride 4, high-level features at the output stride)."""
        low = x
        for i, layer in enumerate(self.features):
            x = layer(x)
            if i == self.low_level_index:
                low = x
        return low, x


def _prod(values: list[int]) -> int:
    out = 1
    for v in values:
        out *= v
    return out


def _out_channels(layer: nn.Module) -> int:
    if isinstance(layer, InvertedResidual):
        return layer.out_channels
    assert isinstance(layer, nn.Sequential)
    conv = layer[0]
    assert isinstance(conv, nn.Conv2d)
    return conv.out_channels
