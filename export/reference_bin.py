"""reference.bin: a few test windows with every intermediate, for the C++ parity program.

In the spirit of llm.c's test_gpt2.c: inputs, intermediate states and logits that the C++
reference must reproduce tensor by tensor. Container: formats/binfmt.py (magic b"QFDIREF\\0",
version 1). Sections:

- inputs (model none): dims [n, W, C, 0...]; ``telemetry`` (n, W, C) raw float32, ``label``
  (n,) int32, ``test_index`` (n,) int32 (row in the test split's windows).
- cnode fp32 and cnode int8: dims as weights.bin's CNODE sections with dims[7] = n;
  ``x_norm`` (n, W, C), ``u`` (n, S, C), ``z0`` (n, L), ``stages`` (n, 4N, L) -- stages[:, 4k + i]
  is the state at which stage i of RK4 step k evaluates the field (stage 0 = the step's start
  state) --, ``z1`` (n, L), ``logits`` (n, K), ``proba`` (n, K).
- gru fp32 and gru int8: dims as weights.bin's GRU sections with dims[7] = n; ``x_norm``,
  ``h`` (n, W, H) the hidden state after every step, ``logits``, ``proba``.

fp32 values come from PyTorch (the reference; classic RK4 with the same N), int8 values from the
int8 ONNX graph run by ONNX Runtime (the float tensors at those points, before they are
quantized), so the C++ int8 code is checked against what the deployed int8 model computes.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from quadfdi.formats.binfmt import Section, pack
from quadfdi.formats.weights_bin import cnode_dims, gru_dims
from quadfdi.formats.weights_layout import REFERENCE_MAGIC, REFERENCE_VERSION

if TYPE_CHECKING:  # the reader needs neither torch nor onnx (runtimes/mcu_weights_src.py uses it)
    import torch

    from quadfdi.export.graph import Built
    from quadfdi.export.onnx_cnode import CnodeParams
    from quadfdi.export.onnx_gru import GruParams

MAGIC, VERSION = REFERENCE_MAGIC, REFERENCE_VERSION  # formats/weights_layout.py


def pick_windows(y: np.ndarray, n: int) -> np.ndarray:
    """``n`` test-window indices (increasing): the first window of each class present, then the
    earliest others."""
    firsts = [int(np.flatnonzero(y == c)[0]) for c in np.unique(y)]
    rest = [i for i in range(len(y)) if i not in set(firsts)]
    return np.array(sorted((firsts + rest)[:n]), dtype=np.int64)


def _softmax(z: np.ndarray) -> np.ndarray:
    e = np.exp(z - z.max(axis=1, keepdims=True))
    return e / e.sum(axis=1, keepdims=True)


def _run_probes(built: Built, keys: list[str], x: np.ndarray) -> dict[str, np.ndarray]:
    from quadfdi.runtimes.ort import session

    sess = session(built.with_probes(keys).SerializeToString())
    outs = sess.run(["logits", "proba"] + [built.probes[k][0] for k in keys], {"telemetry": x})
    return dict(zip(["logits", "proba"] + keys, outs))


def cnode_fp32_tensors(model: torch.nn.Module, x: np.ndarray) -> dict[str, np.ndarray]:
    """PyTorch's trace of the CNODE (its solver must be classic RK4 with the graph's N)."""
    import torch

    from quadfdi.models.threads import torch_threads
    from quadfdi.runtimes.ort import THREADS

    with torch_threads(THREADS):
        tr = model.trace(torch.from_numpy(x))
    st = tr["stages"]  # (N, 4, B, L)
    n, s, b, latent = st.shape
    logits = tr["logits"].numpy()
    return {"x_norm": tr["x_norm"].numpy(), "u": tr["u"].numpy(), "z0": tr["z0"].numpy(),
            "stages": st.permute(2, 0, 1, 3).reshape(b, n * s, latent).numpy(), "z1": tr["z1"].numpy(),
            "logits": logits, "proba": torch.softmax(tr["logits"], dim=1).numpy()}


def cnode_int8_tensors(built: Built, p: CnodeParams, x: np.ndarray) -> dict[str, np.ndarray]:
    keys = ["x_norm", "u", "z0", "z1"] + [f"stage{e}" for e in range(p.n_stages)]
    r = _run_probes(built, keys, x)
    flat = lambda a: a.reshape(a.shape[0], -1)  # noqa: E731  (B, L) whether the probe is (B, L) or (B, 1, L)
    return {"x_norm": r["x_norm"], "u": r["u"], "z0": flat(r["z0"]),
            "stages": np.stack([flat(r[f"stage{e}"]) for e in range(p.n_stages)], axis=1),
            "z1": flat(r["z1"]), "logits": r["logits"], "proba": r["proba"]}


def gru_fp32_tensors(model: torch.nn.Module, x: np.ndarray) -> dict[str, np.ndarray]:
    import torch

    from quadfdi.models.threads import torch_threads
    from quadfdi.runtimes.ort import THREADS

    with torch_threads(THREADS):
        tr = model.trace(torch.from_numpy(x))
    return {"x_norm": tr["x_norm"].numpy(), "h": tr["h"].numpy(), "logits": tr["logits"].numpy(),
            "proba": torch.softmax(tr["logits"], dim=1).numpy()}


def gru_int8_tensors(built: Built, p: GruParams, x: np.ndarray) -> dict[str, np.ndarray]:
    r = _run_probes(built, ["x_norm", "h_all"], x)  # h_all: (W, B, H), every step's hidden state
    return {"x_norm": r["x_norm"], "h": np.ascontiguousarray(r["h_all"].transpose(1, 0, 2)),
            "logits": r["logits"], "proba": r["proba"]}


def _section(model: str, precision: str, dims: tuple[int, ...], n: int, tensors: dict[str, np.ndarray]) -> Section:
    s = Section(model, precision, dims[:7] + (n,))
    for name, arr in tensors.items():
        s.add(name, np.asarray(arr, np.float32))
    return s


def reference_bytes(x: np.ndarray, y: np.ndarray, index: np.ndarray, cnode: torch.nn.Module, cp: CnodeParams,
                    cnode_int8: Built, gru: torch.nn.Module, gp: GruParams, gru_int8: Built) -> bytes:
    """The file's bytes for windows ``x`` (n, W, C) raw, labels ``y``, test-split rows ``index``."""
    n, w, c = x.shape
    inputs = Section("none", "none", (n, w, c, 0, 0, 0, 0, 0))
    inputs.add("telemetry", x, np.float32)
    inputs.add("label", y, np.int32)
    inputs.add("test_index", index, np.int32)
    return pack(MAGIC, VERSION, [
        inputs,
        _section("cnode", "fp32", cnode_dims(cp), n, cnode_fp32_tensors(cnode, x)),
        _section("cnode", "int8", cnode_dims(cp), n, cnode_int8_tensors(cnode_int8, cp, x)),
        _section("gru", "fp32", gru_dims(gp), n, gru_fp32_tensors(gru, x)),
        _section("gru", "int8", gru_dims(gp), n, gru_int8_tensors(gru_int8, gp, x)),
    ])
