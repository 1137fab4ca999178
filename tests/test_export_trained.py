"""`quadfdi export` of TRAINED models (the other export tests use random weights, whose logits are
small and whose argmax is close to arbitrary): train two epochs on the small run, export, then
check the written graphs against PyTorch independently of the export's own verification."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest
import torch

from quadfdi.core.contracts import CLASS_LABELS
from quadfdi.formats.manifest import check_files, load_manifest
from quadfdi.formats.dataset import load_dataset, make_windows
from tests.conftest import trained_export_run
from quadfdi.models.checkpoint import load_checkpoint
from quadfdi.models.networks import SolverSpec

# int8 against fp32: at least 90 % of the test windows keep their fp32 class. Quantization moves
# a logit by a small fraction of the logit range (a few % here), so a window changes class only
# when its two best fp32 logits are that close; after two epochs on the small run a few of its
# ~50 test windows may sit that close, and one flip costs ~2 %. The paper-scale model keeps
# > 99 % (docs/formats.md, "Activation encoding"); 90 % still fails on a broken scale or weight layout,
# which scrambles most windows.
MIN_INT8_ARGMAX_AGREEMENT = 0.90
# Trained, not random: macro F1 of the fp32 graphs on the test split above what predicting the
# majority class gives (about 0.2 with four classes).
MIN_TRAINED_MACRO_F1 = 0.4


@pytest.fixture(scope="module")
def trained_export(small_run, tmp_path_factory) -> Path:
    return trained_export_run(small_run, tmp_path_factory.mktemp("trained_export") / "run", "train.epochs=2",
                              "train.batch_size=48")


def _ort_logits(path: Path, x: np.ndarray) -> np.ndarray:
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    return sess.run(["logits"], {"telemetry": x})[0]


def _torch_logits(run: Path, kind: str, steps: int, x: np.ndarray) -> np.ndarray:
    model, _ = load_checkpoint(run / f"{kind}.pt", kind)
    if kind == "cnode":
        model.solver = SolverSpec(method="rk4", steps=steps)  # the scheme and N the graph unrolls
    with torch.no_grad():
        return model(torch.from_numpy(x)).numpy()


@pytest.mark.parametrize("kind", ["cnode", "gru"])
def test_trained_export_matches_pytorch_and_keeps_the_class_in_int8(trained_export, kind):
    folder = trained_export / "export"
    m = load_manifest(folder / "manifest.json")
    check_files(m, folder)
    test = make_windows(load_dataset(trained_export / "dataset.npz"), "test")
    assert m["verification"]["test_windows"] == len(test) > 0

    fp32 = _ort_logits(folder / m["artifacts"][f"{kind}_fp32"], test.x)
    int8 = _ort_logits(folder / m["artifacts"][f"{kind}_int8"], test.x)
    ref = _torch_logits(trained_export, kind, m["solver"]["steps"], test.x)

    # fp32 graph on disk against the checkpoint, within the bound the manifest records but on at most
    # the windows it allows past it (judged against float32 rounding: export.verify.judged_parity)
    recorded = m["verification"][f"{kind}_fp32_vs_pytorch"]
    over = int(np.sum(np.abs(fp32.astype(np.float64) - ref).max(1) > recorded["bound"]))
    assert over <= recorded["over_bound_allowed"] and (over == 0 or "over_bound_rounding_ratio" in recorded), \
        (over, recorded)
    assert recorded["passed"] and recorded["max_abs_logit"] > 1.0  # trained logits, not near zero

    # the model is trained: clearly better than a constant prediction
    from sklearn.metrics import f1_score

    f1 = f1_score(test.y, fp32.argmax(1), labels=list(CLASS_LABELS), average="macro", zero_division=0)
    assert f1 >= MIN_TRAINED_MACRO_F1, f1

    # int8 against fp32: agreement above the stated threshold, and as recorded in the manifest
    agree = float(np.mean(int8.argmax(1) == fp32.argmax(1)))
    assert agree >= MIN_INT8_ARGMAX_AGREEMENT, agree
    assert agree == pytest.approx(m["verification"][f"{kind}_int8_vs_fp32"]["argmax_agreement"])
    # a window may change class only where its fp32 top-two margin is within the int8 error
    flipped = int8.argmax(1) != fp32.argmax(1)
    if flipped.any():
        top2 = np.sort(fp32[flipped], axis=1)[:, -2:]
        err = np.abs(int8[flipped] - fp32[flipped]).max(axis=1)
        assert np.all(top2[:, 1] - top2[:, 0] <= 2 * err)
