"""TFLite runtime for published DeepLab models: Google's PASCAL VOC int8 one, the ADE20K float one.

Such models take a fixed-size image (uint8, or float RGB scaled to [-1, 1]) and end either in
class scores (float or quantised, any class count) or in an ArgMax. For an ArgMax model we read
the tensor that feeds the ArgMax (the class logits, already resized to the input size); that
needs the interpreter without its default XNNPACK delegate, so only such models pay for it. The
logits are dequantised, subsampled by `OUTPUT_STRIDE` (they are a bilinear upsampling of the
network's stride-8 output, so nothing is lost and the softmax costs a quarter), and their
softmax is summed into RECORDING.md labels through a class -> label map chosen by class count
(`label_map_for`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt
import torch

from capture.recording import VOC_TO_LABEL
from process.errors import ModelError
from process.segmentation.ade20k import ADE20K_CLASS_TO_LABEL
from process.segmentation.weights import label_matrix

OUTPUT_STRIDE: Final = 2  # subsample the 513x513 logits to 257x257
KNOWN_LABEL_MAPS: Final[dict[int, tuple[str, tuple[int, ...]]]] = {
    len(VOC_TO_LABEL): ("PASCAL VOC", VOC_TO_LABEL),
    len(ADE20K_CLASS_TO_LABEL): ("ADE20K", ADE20K_CLASS_TO_LABEL),
}


def label_map_for(n_classes: int, path: Path) -> tuple[int, ...]:
    """Return the class -> label map of a model with this many output classes."""
    if n_classes not in KNOWN_LABEL_MAPS:
        known = ", ".join(f"{n} ({name})" for n, (name, _) in KNOWN_LABEL_MAPS.items())
        raise ModelError(
            f"TFLite model has {n_classes} classes; expected one of {known} "
            f"(pass a PASCAL VOC or ADE20K DeepLab model): {path}"
        )
    return KNOWN_LABEL_MAPS[n_classes][1]


class TfliteRuntime:
    """Run a DeepLab .tflite model with ai-edge-litert, one image at a time."""

    def __init__(
        self,
        path: Path,
        *,
        threads: int = 0,
        class_to_label: tuple[int, ...] | None = None,
        relabel: Callable[[tuple[int, ...]], tuple[int, ...]] | None = None,
    ) -> None:
        """Load the model; the class map defaults to the one of its class count."""
        self.path = path
        self.threads = threads
        self.interp: Any = self._load(preserve=False)
        if self._ends_in_argmax():  # the logits feeding the ArgMax must stay readable
            self.interp = self._load(preserve=True)
        inp = self.interp.get_input_details()[0]
        _, h, w, _ = (int(v) for v in inp["shape"])
        self.fixed_input_size: tuple[int, int] | None = (w, h)
        self._input = inp
        self._logits = self._logits_tensor()
        self.n_classes = int(self._logits["shape"][-1])
        if class_to_label is None:
            class_to_label = label_map_for(self.n_classes, path)
        if self.n_classes != len(class_to_label):
            raise ModelError(
                f"TFLite model has {self.n_classes} classes but the label map has "
                f"{len(class_to_label)}; pass a map of one label per class: {path}"
            )
        self.to_labels = label_matrix(relabel(class_to_label) if relabel else class_to_label)

    def _load(self, *, preserve: bool) -> Any:
        try:
            from ai_edge_litert.interpreter import Interpreter, OpResolverType
        except ImportError as err:
            raise ImportError(
                "the tflite backend needs ai-edge-litert: pip install '.[tflite]'"
            ) from err
        resolver = (
            OpResolverType.BUILTIN_WITHOUT_DEFAULT_DELEGATES if preserve else OpResolverType.AUTO
        )
        try:
            interp = Interpreter(
                model_path=str(self.path),
                num_threads=self.threads or None,
                experimental_op_resolver_type=resolver,
                experimental_preserve_all_tensors=preserve,
            )
            interp.allocate_tensors()
        except (ValueError, RuntimeError) as err:
            raise ModelError(
                f"cannot load the TFLite model ({str(err)[:120]}); expected a .tflite file: "
                f"{self.path}"
            ) from err
        return interp

    def _ends_in_argmax(self) -> bool:
        out = self.interp.get_output_details()[0]
        return bool(np.issubdtype(out["dtype"], np.integer) and len(out["shape"]) == 3)

    def _logits_tensor(self) -> dict[str, Any]:
        out = self.interp.get_output_details()[0]
        index = int(out["index"])
        if self._ends_in_argmax():
            feeding = [op for op in self.interp._get_ops_details() if index in list(op["outputs"])]
            index = int(feeding[0]["inputs"][0])
        details: dict[str, Any] = next(
            t for t in self.interp.get_tensor_details() if t["index"] == index
        )
        if len(details["shape"]) not in (3, 4):
            raise ModelError(
                f"TFLite model output has shape {list(details['shape'])}, expected "
                f"(1, H, W, classes) scores or an (1, H, W) ArgMax: {self.path}"
            )
        return details

    def __call__(self, batch: npt.NDArray[np.uint8]) -> torch.Tensor:
        """Return label probabilities (N, L, h, w) for images at the model's input size."""
        return torch.cat([self._one(image) for image in batch])

    def _one(self, image: npt.NDArray[np.uint8]) -> torch.Tensor:
        x: npt.NDArray[Any] = image[None]
        if self._input["dtype"] != np.uint8:
            x = (x.astype(np.float32) / 127.5 - 1.0).astype(self._input["dtype"])  # TF DeepLab
        self.interp.set_tensor(self._input["index"], x)
        self.interp.invoke()
        raw = self.interp.get_tensor(self._logits["index"])
        raw = raw[..., ::OUTPUT_STRIDE, ::OUTPUT_STRIDE, :]
        logits = torch.from_numpy(np.ascontiguousarray(raw, dtype=np.float32))
        scale, zero = self._logits["quantization"]
        if scale:
            logits = (logits - zero) * scale
        if logits.ndim == 3:
            logits = logits[None]
        probs = torch.softmax(logits, dim=-1)  # NHWC
        return torch.einsum("lc,nhwc->nlhw", self.to_labels, probs)
