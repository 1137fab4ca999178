"""Checkpoints: state dict + architecture + normalisation + config, loadable with weights_only=True.

A checkpoint is a plain dict of tensors, ints, floats, strings, lists and dicts (no pickled
classes), so ``torch.load(path, weights_only=True)`` reads it; the architecture is saved with it
(nanoGPT style) so the model is rebuilt without the original config.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from quadfdi.atomic import atomic_path
from quadfdi.errors import QuadfdiError

CHECKPOINT_VERSION = 1


def architecture(model: torch.nn.Module) -> dict[str, Any]:
    """The constructor arguments of ``model`` as plain values."""
    from train.models import CNODE, GRUClassifier

    if isinstance(model, CNODE):
        return {"kind": "cnode", "n_channels": model.encoder.in_features, "window": int(model.window),
                "latent": model.encoder.out_features, "hidden": model.field.lin1.out_features,
                "n_classes": model.head.out_features}
    if isinstance(model, GRUClassifier):
        return {"kind": "gru", "n_channels": model.gru.input_size, "hidden": model.gru.hidden_size,
                "n_classes": model.head.out_features}
    raise TypeError(f"not a quadfdi model: {type(model).__name__}")


def model_from_architecture(arch: dict[str, Any]) -> torch.nn.Module:
    from train.models import CNODE, GRUClassifier

    if arch["kind"] == "cnode":
        return CNODE(arch["n_channels"], window=arch["window"], latent=arch["latent"], hidden=arch["hidden"],
                     n_classes=arch["n_classes"])
    return GRUClassifier(arch["n_channels"], hidden=arch["hidden"], n_classes=arch["n_classes"])


def save_checkpoint(path: str | Path, model: torch.nn.Module, config: dict, channel_names: list[str],
                    extra: dict[str, Any] | None = None) -> None:
    """Write ``model`` (with its normalisation buffers) and its metadata atomically."""
    blob = {
        "version": CHECKPOINT_VERSION,
        "architecture": architecture(model),
        "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
        "config": config,
        "channel_names": list(channel_names),
        "normalisation": {"mean": model.mean.tolist(), "std": model.std.tolist()},
        **(extra or {}),
    }
    if hasattr(model, "solver"):
        blob["solver"] = {k: getattr(model.solver, k) for k in ("method", "steps", "rtol", "atol", "jump_t")}
    with atomic_path(path, "wb") as fh:
        torch.save(blob, fh)


def load_checkpoint(path: str | Path, kind: str | None = None) -> tuple[torch.nn.Module, dict[str, Any]]:
    """Rebuild the model of checkpoint ``path``; ``kind`` ('cnode'/'gru') is checked when given."""
    p = Path(path)
    if not p.is_file():
        raise QuadfdiError(f"checkpoint {p} does not exist (run `quadfdi train` first)")
    try:
        blob = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a corrupt file
        raise QuadfdiError(f"checkpoint {p} cannot be read (truncated or foreign file?): {str(exc).splitlines()[0]}") from None
    if not isinstance(blob, dict) or blob.get("version") != CHECKPOINT_VERSION or "architecture" not in blob:
        raise QuadfdiError(f"checkpoint {p} is not a quadfdi checkpoint of version {CHECKPOINT_VERSION}")
    arch = blob["architecture"]
    if kind is not None and arch.get("kind") != kind:
        raise QuadfdiError(f"checkpoint {p} holds a {arch.get('kind')!r} model, expected {kind!r}")
    model = model_from_architecture(arch)
    try:
        model.load_state_dict(blob["state_dict"])
    except RuntimeError as exc:
        raise QuadfdiError(f"checkpoint {p} does not match its architecture: {str(exc).splitlines()[0]}") from None
    if "solver" in blob and hasattr(model, "solver"):
        model.solver = type(model.solver)(**blob["solver"])
    model.eval()
    return model, blob


def check_dataset_matches(blob: dict[str, Any], channel_names: list[str], where: str) -> None:
    """A checkpoint only applies to telemetry with the channels it was trained on."""
    expected = list(blob["channel_names"])
    if len(expected) != len(channel_names):
        raise QuadfdiError(f"{where}: the model expects {len(expected)} channels, the dataset has {len(channel_names)}")
    if expected != list(channel_names):
        diff = next(i for i, (a, b) in enumerate(zip(expected, channel_names)) if a != b)
        raise QuadfdiError(f"{where}: channel {diff} is {channel_names[diff]!r} in the dataset, "
                           f"{expected[diff]!r} in the model")
