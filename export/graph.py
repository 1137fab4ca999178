"""A small graph builder over ``onnx.helper``, shared by the CNODE and GRU graph builders.

Why not an exporter: the dynamo exporter fixes the batch axis when traced with batch 1, writes
weights to a side file unless told not to, and once wrote ``linear_before_reset=0`` for a GRU.
Building the graph node by node leaves nothing to chance: every constant is an initializer
stored once (``const`` returns the existing name when asked again), every node has a readable
name, and ``finish`` sets the IR version that ONNX Runtime reads (onnx 1.23 writes 14 by default,
ONNX Runtime reads at most 13 here).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

IR_VERSION = 10  # ONNX Runtime 1.2x/1.3x read <= 13; 10 is what opset 18-21 graphs need
BATCH = "batch"  # the dynamic batch axis
MS_DOMAIN = "com.microsoft"  # ONNX Runtime's contrib operators (MatMulIntegerToFloat), opset 1

_ELEM = {np.dtype(np.float32): TensorProto.FLOAT, np.dtype(np.int8): TensorProto.INT8,
         np.dtype(np.uint8): TensorProto.UINT8,
         np.dtype(np.int32): TensorProto.INT32, np.dtype(np.int64): TensorProto.INT64}


@dataclass
class Graph:
    """Nodes, initializers and probe outputs of one graph under construction."""

    name: str
    nodes: list = field(default_factory=list)
    inits: dict = field(default_factory=dict)  # name -> np.ndarray
    probes: dict = field(default_factory=dict)  # probe name -> (tensor name, elem type, shape)
    probe_nodes: dict = field(default_factory=dict)  # probe name -> nodes only a model probing it runs
    _count: dict = field(default_factory=dict)

    def const(self, name: str, value: np.ndarray | float | int, dtype=np.float32) -> str:
        """An initializer, stored once: asking again for ``name`` returns it (values must agree)."""
        arr = np.asarray(value, dtype=dtype)
        if name in self.inits:
            if not np.array_equal(self.inits[name], arr) or self.inits[name].dtype != arr.dtype:
                raise ValueError(f"initializer {name!r} requested twice with different values")
            return name
        self.inits[name] = arr
        return name

    def node(self, op: str, inputs: list[str], n_out: int = 1, out: list[str] | None = None,
             domain: str = "", **attrs) -> list[str]:
        """Add one node; returns its output names (generated from the op type unless given).
        ``domain`` MS_DOMAIN for ONNX Runtime's contrib operators (MatMulIntegerToFloat)."""
        k = self._count.get(op, 0)
        self._count[op] = k + 1
        outs = out or [f"{op.lower()}_{k}" + (f"_{i}" if n_out > 1 else "") for i in range(n_out)]
        self.nodes.append(helper.make_node(op, inputs, outs, name=f"{op}_{k}", domain=domain or None, **attrs))
        return outs

    def op(self, op: str, *inputs: str, name: str | None = None, domain: str = "", **attrs) -> str:
        """Add a single-output node; ``name`` names its output tensor."""
        return self.node(op, list(inputs), out=[name] if name else None, domain=domain, **attrs)[0]

    def probe(self, key: str, tensor: str, shape: list, elem: int = TensorProto.FLOAT) -> None:
        """Remember an intermediate tensor that calibration or reference.bin may read."""
        self.probes[key] = (tensor, elem, shape)

    def probe_only(self, key: str, shape: list, build) -> None:
        """A probe whose tensor the graph itself does not compute: ``build()`` adds the nodes and
        returns the tensor; they leave the graph and only ``Built.with_probes([key])`` runs them."""
        start = len(self.nodes)
        tensor = build()
        self.probe_nodes[key] = self.nodes[start:]
        del self.nodes[start:]
        self.probe(key, tensor, shape)

    def finish(self, inputs: list, outputs: list, opset: int, doc: str) -> "Built":
        """The ModelProto (IR version set) and the probes recorded while building it."""
        inits = [numpy_helper.from_array(v, k) for k, v in self.inits.items()]
        g = helper.make_graph(self.nodes, self.name, inputs, outputs, inits)
        opsets = [helper.make_opsetid("", opset)]
        if any(n.domain == MS_DOMAIN for n in self.nodes):
            opsets.append(helper.make_opsetid(MS_DOMAIN, 1))
        model = helper.make_model(g, opset_imports=opsets,
                                  producer_name="quadfdi.export", doc_string=doc)
        model.ir_version = IR_VERSION
        return Built(model, dict(self.probes), dict(self.probe_nodes))


@dataclass(frozen=True)
class Built:
    """A built graph and its probes: key -> (tensor name, elem type, shape) of an intermediate."""

    model: onnx.ModelProto
    probes: dict
    probe_nodes: dict = field(default_factory=dict)  # key -> nodes added with that probe (Graph.probe_only)

    def with_probes(self, keys: list[str]) -> onnx.ModelProto:
        """A copy of the model that also outputs the probe tensors ``keys`` (calibration, reference)."""
        m = onnx.ModelProto()
        m.CopyFrom(self.model)
        have = {o.name for o in m.graph.output}
        for key in keys:
            tensor, elem, shape = self.probes[key]
            if tensor not in have:
                m.graph.node.extend(self.probe_nodes.get(key, []))  # inputs: graph input, initializers
                m.graph.output.append(helper.make_tensor_value_info(tensor, elem, shape))
                have.add(tensor)
        return m


def elem_type(dtype) -> int:
    return _ELEM[np.dtype(dtype)]


def telemetry_input(window: int, n_channels: int):
    """Input ``telemetry``: float32 (batch, window, channels), raw units."""
    return helper.make_tensor_value_info("telemetry", TensorProto.FLOAT, [BATCH, window, n_channels])


def class_outputs(n_classes: int) -> list:
    """Outputs ``logits`` and ``proba``: float32 (batch, n_classes)."""
    return [helper.make_tensor_value_info(n, TensorProto.FLOAT, [BATCH, n_classes]) for n in ("logits", "proba")]



def contrib_ops(model: onnx.ModelProto) -> list[str]:
    """Sorted op types of ``model`` outside the default ONNX domain, subgraphs included (for the manifest)."""
    return sorted({f"{n.domain}.{n.op_type}" for n in all_nodes(model.graph) if n.domain not in ("", "ai.onnx")})


def subgraph_ops(model: onnx.ModelProto) -> list[str]:
    """Sorted op types of ``model`` that run a subgraph (the int8 GRU's ``Scan``; for the manifest)."""
    return sorted({n.op_type for n in all_nodes(model.graph)
                   if any(a.type == onnx.AttributeProto.GRAPH for a in n.attribute)})


def all_nodes(graph: onnx.GraphProto) -> list:
    """The nodes of ``graph`` and, recursively, of its nodes' subgraphs (a Scan's body)."""
    out = []
    for n in graph.node:
        out.append(n)
        out += [m for a in n.attribute if a.type == onnx.AttributeProto.GRAPH for m in all_nodes(a.g)]
    return out


def all_initializers(graph: onnx.GraphProto) -> list:
    """The initializers of ``graph`` and of its subgraphs (a Scan body's own constants)."""
    return list(graph.initializer) + [t for n in graph.node for a in n.attribute
                                      if a.type == onnx.AttributeProto.GRAPH for t in all_initializers(a.g)]
