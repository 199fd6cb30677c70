"""Cut the trailing resize/ArgMax ops off a DeepLab .tflite graph, so its logits are its output.

Published DeepLab models end in `logits -> ResizeBilinear (to 513x513) [-> ArgMax]`. Resizing
151 ADE20K class channels to 513x513 costs a quarter of that network's time, and an ArgMax end
hides the scores we need (reading them means running the graph without the XNNPACK delegate,
5x slower). Here the model's single output is pointed at the logits tensor and the trailing ops
are dropped from its operator list: both are in-place edits of two flatbuffer vectors.

Written by hand with `flatbuffers` (already a dependency of ai-edge-litert): no maintained
library edits a .tflite graph short of TensorFlow itself. Field numbers follow TFLite's
schema.fbs: Model.subgraphs = 2; SubGraph.outputs = 2, SubGraph.operators = 3.
"""

from __future__ import annotations

from typing import Final

from flatbuffers import encode, packer, table

TRAILING_OPS: Final = ("RESIZE_BILINEAR", "ARG_MAX")
_MODEL_SUBGRAPHS: Final = 2
_SUBGRAPH_OUTPUTS: Final = 2
_SUBGRAPH_OPERATORS: Final = 3


def _field(tab: table.Table, index: int) -> int:
    """Return the offset of field `index` in a flatbuffer table (0 when absent)."""
    return int(tab.Offset(4 + 2 * index))


def cut_graph(model: bytes, *, output_tensor: int, n_operators: int) -> bytes:
    """Return the model with one output, `output_tensor`, and only its first `n_operators` ops.

    Raises:
        ValueError: the model is not a one-subgraph, one-output graph of more operators.
    """
    buf = bytearray(model)
    root = table.Table(buf, encode.Get(packer.uoffset, buf, 0))
    subgraphs = _field(root, _MODEL_SUBGRAPHS)
    if not subgraphs or root.VectorLen(subgraphs) != 1:
        raise ValueError("expected a model of one subgraph")
    graph = table.Table(buf, root.Indirect(root.Vector(subgraphs)))
    outputs, operators = _field(graph, _SUBGRAPH_OUTPUTS), _field(graph, _SUBGRAPH_OPERATORS)
    if not outputs or graph.VectorLen(outputs) != 1:
        raise ValueError("expected a graph of one output")
    if not operators or not 0 < n_operators <= graph.VectorLen(operators):
        raise ValueError(f"cannot keep {n_operators} operators of the graph")
    encode.Write(packer.int32, buf, graph.Vector(outputs), output_tensor)
    encode.Write(packer.uoffset, buf, graph.Vector(operators) - 4, n_operators)  # its length
    return bytes(buf)


def logits_end(ops: list[dict[str, object]], output: int) -> tuple[int, int]:
    """Return (logits tensor, operators before the trailing resize/ArgMax ops) of a graph.

    `ops` are an interpreter's operator details in execution order; `output` its output
    tensor. A graph that does not end in such ops is returned whole: (output, len(ops)).
    """
    tensor, n = output, len(ops)
    while n > 0:
        op = ops[n - 1]
        inputs, outputs = list(op["inputs"]), list(op["outputs"])  # type: ignore[call-overload]
        if op["op_name"] not in TRAILING_OPS or outputs != [tensor]:
            break
        tensor, n = int(inputs[0]), n - 1
    return tensor, n
