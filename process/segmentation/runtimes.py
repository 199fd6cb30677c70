"""Inference runtimes: torch (CPU/CUDA), onnxruntime (an ONNX export) and TFLite (ai-edge-litert).

Each runtime takes a batch of uint8 RGB images (N, h, w, 3) already at the network's input size
and returns label probabilities (N, NUM_LABELS, h', w') as a torch tensor, at the network's output
resolution (stride 4 for DeepLabV3+): class softmax summed into RECORDING.md labels through the
checkpoint's class -> label map. For inference BatchNorm is folded into the convolutions.
"""

from __future__ import annotations

import io
import logging
import warnings
from pathlib import Path
from typing import Any, Protocol, cast

import numpy as np
import numpy.typing as npt
import torch
from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval

from capture.recording import NUM_LABELS
from process.errors import ModelError
from process.segmentation.weights import Checkpoint, build_from_checkpoint, label_matrix

logger = logging.getLogger(__name__)


class Runtime(Protocol):
    """What the Segmenter needs of a runtime."""

    fixed_input_size: tuple[int, int] | None  # (width, height) the model requires, if any
    align_corners: bool  # whether the output grid's corner samples are the input's corners

    def __call__(self, batch: npt.NDArray[np.uint8]) -> torch.Tensor:
        """Return label probabilities (N, L, h, w) for images (N, h, w, 3)."""
        ...


class DeployModule(nn.Module):
    """uint8 NHWC RGB in, label probabilities out: normalisation, network, softmax, label map."""

    mean: torch.Tensor
    inv_std: torch.Tensor
    to_labels: torch.Tensor

    def __init__(self, ckpt: Checkpoint, *, channels_last: bool = True) -> None:
        super().__init__()
        self.net = fold_batchnorm(build_from_checkpoint(ckpt))
        self.register_buffer("mean", torch.tensor(ckpt.mean).view(1, 3, 1, 1) * 255.0)
        self.register_buffer("inv_std", 1.0 / (torch.tensor(ckpt.std).view(1, 3, 1, 1) * 255.0))
        self.identity = ckpt.class_to_label == tuple(range(NUM_LABELS))
        self.register_buffer("to_labels", label_matrix(ckpt.class_to_label))
        self.channels_last = channels_last

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Return label probabilities (N, L, h, w) at the output stride for uint8 (N, H, W, 3)."""
        x = images.permute(0, 3, 1, 2).float()  # an NHWC-strided view: already channels_last
        if not self.channels_last:
            x = x.contiguous()
        x = (x - self.mean) * self.inv_std
        # Probabilities at the decoder's stride; the Segmenter resizes them once to the image.
        probs = torch.softmax(self.net(x, upsample=False), dim=1)
        if self.identity:
            return probs
        return torch.einsum("lc,nchw->nlhw", self.to_labels, probs)


def fold_batchnorm(model: nn.Module) -> nn.Module:
    """Fold every eval-mode BatchNorm that follows a Conv2d into the conv's weights, in place."""
    for module in model.modules():
        if not isinstance(module, nn.Sequential):
            continue
        for i in range(len(module) - 1):
            conv, bn = module[i], module[i + 1]
            if isinstance(conv, nn.Conv2d) and isinstance(bn, nn.BatchNorm2d):
                module[i] = fuse_conv_bn_eval(conv.eval(), bn.eval())
                module[i + 1] = nn.Identity()
    return model


def pick_device(device: str) -> torch.device:
    """Return the torch device for "auto" (CUDA when present), "cpu" or "cuda"."""
    if device == "cuda" and not torch.cuda.is_available():
        raise ModelError(
            "device 'cuda' was asked for but torch sees no CUDA device; use --device cpu or auto"
        )
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    return torch.device(device)


class TorchRuntime:
    """Run the network with torch in inference mode, channels_last on CPU when asked."""

    fixed_input_size: tuple[int, int] | None = None
    align_corners = False

    def __init__(
        self, ckpt: Checkpoint, *, device: str = "auto", channels_last: bool = True
    ) -> None:
        self.device = pick_device(device)
        self.module = DeployModule(ckpt, channels_last=channels_last).to(self.device).eval()
        if channels_last:
            self.module = self.module.to(memory_format=torch.channels_last)  # type: ignore[call-overload]

    def __call__(self, batch: npt.NDArray[np.uint8]) -> torch.Tensor:
        """Return label probabilities (N, L, h, w) on the runtime's device."""
        x = torch.from_numpy(np.ascontiguousarray(batch)).to(self.device, non_blocking=True)
        with torch.inference_mode():
            out: torch.Tensor = self.module(x)
        return out


def export_onnx(
    ckpt: Checkpoint, dst: Path | io.BytesIO, *, example_hw: tuple[int, int] = (240, 320)
) -> None:
    """Export the deploy module (uint8 NHWC in, label probabilities out) with dynamic N, H, W."""
    module = DeployModule(ckpt, channels_last=False).eval()
    example = torch.zeros((1, *example_hw, 3), dtype=torch.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notice
        torch.onnx.export(
            module,
            (example,),
            cast(Any, dst),  # a BytesIO works; the annotation says path only
            dynamo=False,  # the torch.export-based exporter needs onnxscript, not a dependency
            input_names=["image"],
            output_names=["label_probs"],
            dynamic_axes={
                "image": {0: "n", 1: "h", 2: "w"},
                "label_probs": {0: "n", 2: "h", 3: "w"},
            },
            opset_version=17,
        )


class OnnxRuntime:
    """Run an ONNX export of a checkpoint with onnxruntime's CPU provider."""

    fixed_input_size: tuple[int, int] | None = None
    align_corners = False

    def __init__(self, model: Checkpoint | Path, *, threads: int = 0) -> None:
        try:
            import onnxruntime as ort
        except ImportError as err:
            raise ImportError("the onnx backend needs onnxruntime: pip install '.[onnx]'") from err
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        if isinstance(model, Checkpoint):
            buf = io.BytesIO()
            export_onnx(model, buf)
            source: Any = buf.getvalue()
        else:
            source = str(model)
        try:
            self.session = ort.InferenceSession(source, opts, providers=["CPUExecutionProvider"])
        except Exception as err:  # onnxruntime raises its own Fail/InvalidGraph types
            raise ModelError(
                f"onnxruntime cannot load the model ({str(err)[:120]}): {model}"
            ) from err

    def __call__(self, batch: npt.NDArray[np.uint8]) -> torch.Tensor:
        """Return label probabilities (N, L, h, w) as a CPU tensor."""
        (out,) = self.session.run(None, {"image": np.ascontiguousarray(batch)})
        return torch.from_numpy(out)
