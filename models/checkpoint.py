"""Checkpoints: state dict + architecture + normalisation + config, loadable with weights_only=True.

A checkpoint is a plain dict of tensors, ints, floats, strings, lists and dicts (no pickled
classes), so ``torch.load(path, weights_only=True)`` reads it; the architecture is saved with it
(nanoGPT style) so the model is rebuilt without the original config.
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import torch

from quadfdi.core.atomic import atomic_path
from quadfdi.core.contracts import CLASS_NAMES
from quadfdi.core.errors import QuadfdiError
from quadfdi.models.networks import model_from_signature, model_signature
from quadfdi.models.variants import CNODE_CLASSES

CHECKPOINT_VERSION = 1


def save_checkpoint(path: str | Path, model: torch.nn.Module, config: dict, channel_names: list[str],
                    extra: dict[str, Any] | None = None, class_names: list[str] | tuple[str, ...] | None = None) -> None:
    """Write ``model`` (with its normalisation buffers) and its metadata atomically; ``class_names``
    (the data's, label order; default the paper's four) must match the model's output width."""
    names = list(CLASS_NAMES if class_names is None else class_names)
    if len(names) != model.n_classes:
        raise ValueError(f"{len(names)} class names for a model with {model.n_classes} outputs")
    blob = {
        "version": CHECKPOINT_VERSION,
        "architecture": model_signature(model),
        "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
        "config": config,
        "channel_names": list(channel_names),
        "class_names": names,
        "normalisation": {"mean": model.mean.tolist(), "std": model.std.tolist()},
        **(extra or {}),
    }
    if hasattr(model, "solver"):
        blob["solver"] = {k: getattr(model.solver, k) for k in ("method", "steps", "rtol", "atol", "jump_t")}
    with atomic_path(path, "wb") as fh:
        torch.save(blob, fh)


def load_checkpoint(path: str | Path, kind: str | None = None) -> tuple[torch.nn.Module, dict[str, Any]]:
    """Rebuild the model of checkpoint ``path``; ``kind`` ('cnode'/'gru') is checked when given.

    A CNODE comes back in the class of its control representation (``models.variants.CNODE_CLASSES``),
    so a step-average model loads like any other.
    """
    p = Path(path)
    if not p.is_file():
        raise QuadfdiError(f"checkpoint {p} does not exist (run `quadfdi train` first)")
    try:
        blob = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a corrupt file, some with an empty message
        if "weights only load failed" in str(exc).lower() or isinstance(exc, pickle.UnpicklingError):
            # torch's own advice (retry with weights_only=False) would run the file's code: not for a user
            raise QuadfdiError(f"checkpoint {p} holds pickled objects besides tensors: not a quadfdi checkpoint "
                               "(quadfdi never unpickles code), refused") from None
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise QuadfdiError(f"checkpoint {p} cannot be read (truncated, empty or foreign file?): {first}") from None
    if not isinstance(blob, dict) or blob.get("version") != CHECKPOINT_VERSION or "architecture" not in blob:
        raise QuadfdiError(f"checkpoint {p} is not a quadfdi checkpoint of version {CHECKPOINT_VERSION}")
    arch = blob["architecture"]
    if kind is not None and arch.get("kind") != kind:
        raise QuadfdiError(f"checkpoint {p} holds a {arch.get('kind')!r} model, expected {kind!r}")
    bad = [k for k, v in arch.items() if isinstance(v, int) and not isinstance(v, bool) and v < 0] \
        if isinstance(arch, dict) else ["architecture"]
    if bad:
        raise QuadfdiError(f"checkpoint {p}: architecture field {bad[0]!r} must not be negative, found {arch[bad[0]]}")
    try:
        model = model_from_signature(arch, cnode_classes=CNODE_CLASSES)
    except Exception as exc:  # a forged size reaches torch, which raises RuntimeError and others
        raise QuadfdiError(f"checkpoint {p} has an invalid architecture: {_first_line(exc)}") from None
    state = blob.get("state_dict")
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise QuadfdiError(f"checkpoint {p}: field 'state_dict' must map names to tensors")
    nonfinite = [k for k, v in state.items() if v.is_floating_point() and not bool(torch.isfinite(v).all())]
    if nonfinite:
        raise QuadfdiError(f"checkpoint {p}: weight {nonfinite[0]!r} holds NaN or Inf (expected finite values)")
    try:
        model.load_state_dict(state)
    except Exception as exc:
        raise QuadfdiError(f"checkpoint {p} does not match its architecture: {_first_line(exc)}") from None
    if "solver" in blob and hasattr(model, "solver"):
        model.solver = type(model.solver)(**blob["solver"])
    model.eval()
    return model, blob


def checkpoint_class_names(blob: dict[str, Any]) -> list[str]:
    """The class names of a loaded checkpoint, label order: its ``class_names``, or the paper's four
    for a checkpoint written before they were stored (only a 4-output model can be one)."""
    if "class_names" in blob:
        return [str(c) for c in blob["class_names"]]
    k = int(blob["architecture"].get("n_classes", len(CLASS_NAMES)))
    if k != len(CLASS_NAMES):
        raise QuadfdiError(f"checkpoint with {k} outputs stores no class_names: re-run quadfdi train")
    return list(CLASS_NAMES)


def _first_line(exc: BaseException) -> str:
    return (str(exc).splitlines() or [type(exc).__name__])[0]


def check_dataset_matches(blob: dict[str, Any], channel_names: list[str], where: str) -> None:
    """A checkpoint only applies to telemetry with the channels it was trained on."""
    expected = list(blob["channel_names"])
    if len(expected) != len(channel_names):
        raise QuadfdiError(f"{where}: the model expects {len(expected)} channels, the dataset has {len(channel_names)}")
    if expected != list(channel_names):
        diff = next(i for i, (a, b) in enumerate(zip(expected, channel_names)) if a != b)
        raise QuadfdiError(f"{where}: channel {diff} is {channel_names[diff]!r} in the dataset, "
                           f"{expected[diff]!r} in the model")
