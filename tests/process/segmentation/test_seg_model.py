from __future__ import annotations

import pytest
import torch
from torch.utils.flop_counter import FlopCounterMode

from process.errors import ModelError
from process.segmentation.deeplab import (
    PRESETS,
    ArchConfig,
    DeepLab,
    SeparableConvBNReLU,
    build_model,
)
from process.segmentation.mobilenetv3 import MobileNetV3Features, make_divisible
from process.segmentation.weights import parameter_count

# torchvision mobilenet_v3_large(dilated=True): (output channels, stride w.r.t. the input) per
# features[i], from the MobileNetV3 paper's Table 1 with the last stage dilated (stride 16).
LARGE_DILATED = [
    (16, 2), (16, 2), (24, 4), (24, 4), (40, 8), (40, 8), (40, 8), (80, 16), (80, 16), (80, 16),
    (80, 16), (112, 16), (112, 16), (160, 16), (160, 16), (160, 16), (960, 16),
]  # fmt: skip
SMALL = [
    (16, 2), (16, 4), (24, 8), (24, 8), (40, 16), (40, 16), (40, 16), (48, 16), (48, 16),
    (96, 32), (96, 32), (96, 32), (576, 32),
]  # fmt: skip


def _trace(features: torch.nn.Sequential, x: torch.Tensor) -> list[tuple[int, int]]:
    out = []
    h = x.shape[2]
    for layer in features:
        x = layer(x)
        out.append((x.shape[1], h // x.shape[2]))
    return out


@torch.no_grad()
def test_every_large_block_has_torchvision_channels_and_stride() -> None:
    net = MobileNetV3Features("mobilenet_v3_large").eval()
    assert _trace(net.features, torch.zeros(1, 3, 64, 64)) == LARGE_DILATED


@torch.no_grad()
def test_every_small_block_without_dilation_has_paper_channels_and_stride() -> None:
    net = MobileNetV3Features("mobilenet_v3_small", dilated=False).eval()
    assert _trace(net.features, torch.zeros(1, 3, 64, 64)) == SMALL


@torch.no_grad()
@pytest.mark.parametrize(
    ("variant", "dilated", "low_ch", "high_ch", "stride"),
    [
        ("mobilenet_v3_large", True, 24, 960, 16),
        ("mobilenet_v3_large", False, 24, 960, 32),
        ("mobilenet_v3_small", True, 16, 576, 16),
    ],
)
def test_backbone_returns_stride4_low_level_and_output_stride(
    variant: str, dilated: bool, low_ch: int, high_ch: int, stride: int
) -> None:
    net = MobileNetV3Features(variant, dilated=dilated).eval()
    low, high = net(torch.zeros(2, 3, 128, 96))
    assert low.shape == (2, low_ch, 32, 24)
    assert high.shape == (2, high_ch, 128 // stride, 96 // stride)
    assert net.output_stride == stride


def test_width_multiplier_scales_channels_to_multiples_of_8() -> None:
    net = MobileNetV3Features("mobilenet_v3_large", width_mult=0.5)
    assert net.low_level_channels == make_divisible(24 * 0.5) == 16
    assert net.out_channels == 6 * make_divisible(160 * 0.5) == 480


def test_make_divisible_matches_torchvision_examples() -> None:
    assert [make_divisible(v) for v in (16, 24 * 0.75, 672 // 4, 120 // 4, 3.2)] == [
        16,
        24,
        168,
        32,
        8,
    ]


@torch.no_grad()
def test_aspp_decoder_and_classifier_resolutions() -> None:
    net = build_model("deeplabv3plus_lite_mobilenet_v3_large").eval()
    low, high = net.backbone(torch.zeros(1, 3, 96, 128))
    aspp = net.aspp(high)
    assert aspp.shape == (1, 128, 6, 8)  # stride 16, aspp_channels
    assert len(net.aspp.convs) == 5  # 1x1, three atrous, image pooling
    fused = net.decoder(aspp, low)
    assert fused.shape == (1, 128, 24, 32)  # stride 4
    assert net(torch.zeros(1, 3, 96, 128)).shape == (1, 11, 96, 128)


def test_atrous_rates_are_dilations_of_the_aspp_branches() -> None:
    net = build_model("deeplabv3plus_mobilenet_v3_large")
    dilations = [branch[0].dilation for branch in list(net.aspp.convs)[1:4]]  # type: ignore[index]
    assert dilations == [(6, 6), (12, 12), (18, 18)]


def test_lite_variant_uses_depthwise_separable_convs() -> None:
    net = build_model("deeplabv3plus_lite_mobilenet_v3_large")
    assert all(isinstance(b, SeparableConvBNReLU) for b in list(net.aspp.convs)[1:4])
    depthwise = list(net.aspp.convs)[1][0][0]  # type: ignore[index]
    assert depthwise.groups == depthwise.in_channels == 960
    assert (
        parameter_count(net) < parameter_count(build_model("deeplabv3plus_mobilenet_v3_large")) / 2
    )


@torch.no_grad()
@pytest.mark.parametrize(("height", "width"), [(480, 640), (377, 513), (33, 47)])
def test_forward_keeps_any_input_size(height: int, width: int) -> None:
    net = build_model("deeplabv3plus_lite_mobilenet_v3_small").eval()
    assert net(torch.zeros(1, 3, height, width)).shape == (1, 11, height, width)


@torch.no_grad()
def test_full_deeplabv3plus_forward_at_640x480() -> None:
    net = build_model("deeplabv3plus_mobilenet_v3_large").eval()
    out = net(torch.rand(1, 3, 480, 640))
    assert out.shape == (1, 11, 480, 640)
    assert torch.isfinite(out).all()


def test_torchvision_layout_has_the_published_parameter_count() -> None:
    # torchvision: 11,029,328 parameters including the training-only aux FCN head
    # (conv 10x40x3x3, BN 2x10, conv 21x10 + 21 bias = 3,851), which we drop.
    assert parameter_count(build_model("deeplabv3_mobilenet_v3_large")) == 11_029_328 - 3_851


@torch.no_grad()
def test_torchvision_layout_has_the_published_compute() -> None:
    # torchvision lists 10.45 "GFLOPS" (multiply-adds) for deeplabv3_mobilenet_v3_large at 520x520.
    counter = FlopCounterMode(display=False)
    with counter:
        build_model("deeplabv3_mobilenet_v3_large").eval()(torch.zeros(1, 3, 520, 520))
    assert counter.get_total_flops() / 2e9 == pytest.approx(10.45, rel=0.01)


def test_arch_config_round_trips_and_rejects_bad_values() -> None:
    arch = PRESETS["deeplabv3plus_lite_mobilenet_v3_large"]
    assert ArchConfig.from_json(arch.to_json()) == arch
    with pytest.raises(ModelError, match="backbone"):
        ArchConfig(backbone="resnet50")
    with pytest.raises(ModelError, match="unknown architecture keys"):
        ArchConfig.from_json('{"depth": 3}')
    with pytest.raises(ModelError, match="choose one of"):
        build_model("unet")
    assert isinstance(build_model(ArchConfig(num_classes=3)), DeepLab)
