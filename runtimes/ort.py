"""ONNX Runtime: the one session builder of the tree and the one way to run an exported graph
(export checks, parity, detect, bench workers and probes).

Imports only onnxruntime and numpy, so that a bench worker process that times ONNX Runtime does not
load torch into its memory baseline, and detect never pays for torch.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime as ort

from quadfdi.core.errors import QuadfdiError

# One thread by default: the graphs are small, and on a shared 2-core machine a second thread
# made PyTorch's GRU 50x slower (OpenMP spin-waiting against other processes).
THREADS = 1
CHUNK = 512  # windows per run() in batched mode: bounds the memory of a long flight


def session(model: bytes | str | Path, threads: int = THREADS, *, spinning: bool | None = None,
            profile_prefix: str | None = None) -> ort.InferenceSession:
    """A CPU session of ``model`` (serialized bytes or a file path): ``threads`` intra-op threads,
    one inter-op thread, sequential execution, warnings off.

    ``spinning`` sets ``session.intra_op.allow_spinning`` (None: ONNX Runtime's default);
    ``profile_prefix`` turns the per-node profiler on, writing to files with that prefix.
    """
    opts = ort.SessionOptions()
    opts.log_severity_level = 3
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    if spinning is not None:
        opts.add_session_config_entry("session.intra_op.allow_spinning", "1" if spinning else "0")
    if profile_prefix:
        opts.enable_profiling = True
        opts.profile_file_prefix = profile_prefix
    source = str(model) if isinstance(model, Path) else model
    return ort.InferenceSession(source, opts, providers=["CPUExecutionProvider"])


def load(path: str | Path, threads: int = THREADS) -> ort.InferenceSession:
    """A session of the graph file ``path``, or a one-line error for a missing, truncated or foreign file."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise QuadfdiError(f"cannot read {path}: {exc.strerror}") from None
    try:
        return session(data, threads)
    except Exception as exc:  # onnxruntime's own exception types: a truncated or foreign graph
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise QuadfdiError(f"{path} is not a loadable ONNX graph (truncated or foreign file?): {first}") from None


def outputs(graph: str | Path | ort.InferenceSession, x: np.ndarray, names: list[str],
            batch: int = CHUNK) -> list[np.ndarray]:
    """The outputs ``names`` (e.g. logits, proba, motor_logits) of windows ``x`` (n, W, C), float32,
    ``batch`` windows per call (1: one window at a time, as firmware runs them)."""
    sess = graph if isinstance(graph, ort.InferenceSession) else load(graph)
    parts = [sess.run(names, {"telemetry": x[i:i + batch]}) for i in range(0, len(x), batch)]
    if not parts:
        return [np.zeros((0, 0), np.float32) for _ in names]
    return [np.concatenate([p[j] for p in parts]).astype(np.float32) for j in range(len(names))]


def optimized_nodes(model: bytes | str | Path) -> dict[str, int]:
    """Node count of ``model`` after ONNX Runtime's graph optimizer (the default level, ORT_ENABLE_ALL,
    on the CPU provider): the session writes its optimized graph (``optimized_model_filepath``) and
    the nodes of that file are counted, in total and per op type (``"total"`` key), the graph's own
    nodes only; ``"body"`` counts the nodes inside subgraphs (a Scan's body), each body once, though
    it runs once per step."""
    import tempfile
    from collections import Counter

    import onnx

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "optimized.onnx"
        opts = ort.SessionOptions()
        opts.log_severity_level = 3
        opts.intra_op_num_threads = 1
        opts.optimized_model_filepath = str(out)
        source = str(model) if isinstance(model, Path) else model
        ort.InferenceSession(source, opts, providers=["CPUExecutionProvider"])
        nodes = onnx.load(str(out), load_external_data=False).graph.node
    counts = Counter(n.op_type for n in nodes)
    return {"total": len(nodes), "body": _subgraph_nodes(nodes), **dict(sorted(counts.items()))}


def _subgraph_nodes(nodes) -> int:
    """Nodes inside the subgraph attributes of ``nodes``, recursively."""
    import onnx

    graphs = [a.g for n in nodes for a in n.attribute if a.type == onnx.AttributeProto.GRAPH]
    return sum(len(g.node) + _subgraph_nodes(g.node) for g in graphs)
