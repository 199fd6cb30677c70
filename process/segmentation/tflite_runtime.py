"""TFLite runtime for published DeepLab models: Google's PASCAL VOC int8 one, the ADE20K float one.

Such models take a fixed-size image (uint8, or float RGB scaled to [-1, 1]) and end in a resize of
their class logits to the input size, sometimes followed by an ArgMax. Those trailing ops are cut
off at load (`tflite_graph`): the network's logits are its output and every op runs in the
XNNPACK delegate. The logits (float or quantised, any class count) are dequantised, brought to
the stride-4 grid of the input (VOC's stride-16 logits upsampled, corner-aligned as DeepLab's own
resize), and their softmax is summed into RECORDING.md labels through a class -> label map
chosen by class count (`label_map_for`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt
import torch
from torch.nn import functional as F  # noqa: N812 (the torch convention)

from capture.recording import VOC_TO_LABEL
from process.errors import ModelError
from process.segmentation.ade20k import ADE20K_CLASS_TO_LABEL
from process.segmentation.tflite_graph import cut_graph, logits_end
from process.segmentation.weights import label_matrix

OUTPUT_STRIDE: Final = 4  # label probabilities on the input's stride-4 grid (129x129 for 513)
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
            "(PASCAL VOC or ADE20K DeepLab), or give its map, one label 0-10 per class, as "
            f"segmentation.class_to_label in --config: {path}"
        )
    return KNOWN_LABEL_MAPS[n_classes][1]


class TfliteRuntime:
    """Run a DeepLab .tflite model with ai-edge-litert, one image at a time."""

    align_corners = True  # the output grid's corners are the input's (DeepLab's 513 = 128*4+1)

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
        self.interp: Any = self._load()
        inp = self.interp.get_input_details()[0]
        _, h, w, _ = (int(v) for v in inp["shape"])
        self.fixed_input_size: tuple[int, int] | None = (w, h)
        self.output_size = ((h - 1) // OUTPUT_STRIDE + 1, (w - 1) // OUTPUT_STRIDE + 1)
        self._input = inp
        self._logits: dict[str, Any] = self.interp.get_output_details()[0]
        if len(self._logits["shape"]) != 4:
            raise ModelError(
                f"TFLite model output has shape {list(self._logits['shape'])}, expected "
                f"(1, H, W, classes) scores, or scores resized and ArgMax-ed: {self.path}"
            )
        self.n_classes = int(self._logits["shape"][-1])
        if class_to_label is None:
            class_to_label = label_map_for(self.n_classes, path)
        if self.n_classes != len(class_to_label):
            raise ModelError(
                f"TFLite model has {self.n_classes} classes but the label map has "
                f"{len(class_to_label)}; give one label per class (segmentation.class_to_label): "
                f"{path}"
            )
        self.to_labels = label_matrix(relabel(class_to_label) if relabel else class_to_label)

    def _load(self) -> Any:
        try:
            from ai_edge_litert.interpreter import Interpreter, OpResolverType
        except ImportError as err:
            raise ImportError(
                "the tflite backend needs ai-edge-litert: pip install '.[tflite]'"
            ) from err
        try:
            model = self.path.read_bytes()
            probe = Interpreter(
                model_content=model,
                experimental_op_resolver_type=OpResolverType.BUILTIN_WITHOUT_DEFAULT_DELEGATES,
            )
            ops = probe._get_ops_details()
            logits, n_ops = logits_end(ops, int(probe.get_output_details()[0]["index"]))
            if n_ops < len(ops):
                model = cut_graph(model, output_tensor=logits, n_operators=n_ops)
            interp = Interpreter(model_content=model, num_threads=self.threads or None)
            interp.allocate_tensors()
        except (ValueError, RuntimeError, OSError) as err:
            raise ModelError(
                f"cannot load the TFLite model ({str(err)[:120]}); expected a .tflite file: "
                f"{self.path}"
            ) from err
        return interp

    def __call__(self, batch: npt.NDArray[np.uint8]) -> torch.Tensor:
        """Return label probabilities (N, L, h, w) on the stride-4 grid of the input size."""
        return torch.cat([self._one(image) for image in batch])

    def _one(self, image: npt.NDArray[np.uint8]) -> torch.Tensor:
        x: npt.NDArray[Any] = image[None]
        if self._input["dtype"] != np.uint8:
            x = (x.astype(np.float32) / 127.5 - 1.0).astype(self._input["dtype"])  # TF DeepLab
        self.interp.set_tensor(self._input["index"], x)
        self.interp.invoke()
        raw = self.interp.get_tensor(self._logits["index"])
        logits = torch.from_numpy(raw.astype(np.float32))  # NHWC
        scale, zero = self._logits["quantization"]
        if scale:
            logits = (logits - zero) * scale
        if logits.shape[1:3] != self.output_size:
            logits = F.interpolate(
                logits.permute(0, 3, 1, 2),
                size=self.output_size,
                mode="bilinear",
                align_corners=True,
            ).permute(0, 2, 3, 1)
        probs = torch.softmax(logits, dim=-1)  # over the contiguous class axis
        return torch.einsum("lc,nhwc->nlhw", self.to_labels, probs)
