"""TFLite runtime for published DeepLab PASCAL VOC models (Google's deeplabv3_mnv2_pascal_quant).

Such models take a fixed-size uint8 image (quantised to [-1, 1] inside) and end in an ArgMax.
To get a per-pixel confidence we read the tensor that feeds the ArgMax (the class logits, already
resized to the input size), dequantise it and take its softmax. The 21 VOC classes become
RECORDING.md labels through VOC_TO_LABEL.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import torch

from capture.recording import VOC_TO_LABEL
from process.errors import ModelError
from process.segmentation.weights import label_matrix


class TfliteRuntime:
    """Run a DeepLab VOC .tflite model with ai-edge-litert, one image at a time."""

    def __init__(
        self, path: Path, *, threads: int = 0, class_to_label: tuple[int, ...] = VOC_TO_LABEL
    ) -> None:
        try:
            from ai_edge_litert.interpreter import Interpreter, OpResolverType
        except ImportError as err:
            raise ImportError(
                "the tflite backend needs ai-edge-litert: pip install '.[tflite]'"
            ) from err
        try:
            # Without the default XNNPACK delegate intermediate tensors stay readable.
            self.interp: Any = Interpreter(
                model_path=str(path),
                num_threads=threads or None,
                experimental_op_resolver_type=OpResolverType.BUILTIN_WITHOUT_DEFAULT_DELEGATES,
                experimental_preserve_all_tensors=True,
            )
            self.interp.allocate_tensors()
        except (ValueError, RuntimeError) as err:
            raise ModelError(
                f"cannot load the TFLite model ({str(err)[:120]}); expected a .tflite file: {path}"
            ) from err
        inp = self.interp.get_input_details()[0]
        _, h, w, _ = (int(v) for v in inp["shape"])
        self.fixed_input_size: tuple[int, int] | None = (w, h)
        self._input = inp
        self._logits = self._logits_tensor()
        n_classes = int(self._logits["shape"][-1])
        if n_classes != len(class_to_label):
            raise ModelError(
                f"TFLite model has {n_classes} classes, expected {len(class_to_label)} (VOC); "
                f"pass a VOC model: {path}"
            )
        self.to_labels = label_matrix(class_to_label)

    def _logits_tensor(self) -> dict[str, Any]:
        out = self.interp.get_output_details()[0]
        index = int(out["index"])
        if np.issubdtype(out["dtype"], np.integer) and len(out["shape"]) == 3:  # ends in ArgMax
            feeding = [op for op in self.interp._get_ops_details() if index in list(op["outputs"])]
            index = int(feeding[0]["inputs"][0])
        details: dict[str, Any] = next(
            t for t in self.interp.get_tensor_details() if t["index"] == index
        )
        return details

    def __call__(self, batch: npt.NDArray[np.uint8]) -> torch.Tensor:
        """Return label probabilities (N, L, h, w) for images at the model's input size."""
        return torch.cat([self._one(image) for image in batch])

    def _one(self, image: npt.NDArray[np.uint8]) -> torch.Tensor:
        x: npt.NDArray[Any] = image[None]
        if self._input["dtype"] != np.uint8:
            x = (x.astype(np.float32) / 127.5 - 1.0).astype(
                self._input["dtype"]
            )  # TF DeepLab range
        self.interp.set_tensor(self._input["index"], x)
        self.interp.invoke()
        raw = torch.from_numpy(self.interp.get_tensor(self._logits["index"]).astype(np.float32))
        scale, zero = self._logits["quantization"]
        logits = (raw - zero) * scale if scale else raw
        if logits.ndim == 3:
            logits = logits[None]
        probs = torch.softmax(logits.permute(0, 3, 1, 2), dim=1)  # NHWC -> NCHW
        return torch.einsum("lc,nchw->nlhw", self.to_labels, probs)
