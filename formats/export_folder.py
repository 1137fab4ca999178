"""The one reader of an export folder (``RUN/export``, what ``quadfdi export`` publishes).

    ex = Export.open("runs/r/export")  # manifest.json checked, every file it lists against its sha256
    ex.policy("gru")                   # ({threshold, k, n, clear_m, latch}, where it came from)
    ex.profile()                       # the channel profile's name
    ex.artifact("cnode", "int8")       # the path of an ONNX graph inside the folder
    ex.weights()                       # weights.bin (formats.weights_bin.WeightsFile)
    ex.onboard()                       # weights.bin's on-board record (formats.onboard.onboard_dict)

Every reader of an export (detect, stream-file, parity, bench, the Cortex-M stream generator) goes
through it, so an export written before a key is read the same way everywhere: no ``profile`` is the
paper profile; no ``alarm_per_model`` runs the manifest's ``alarm`` for every network, and no
``alarm`` the [alarm] defaults (core.alarm.resolve_policy, the rule the on-board record's
``formats.onboard.policy_of`` and the C++ ``fwref::policy_for`` share); no ``motor_head`` is a model
without the head; a weights.bin without the on-board record is refused in one line by ``onboard()``.
A missing manifest, another schema version or a file changed after the export is refused in one
line by ``open``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfdi.core.alarm import resolve_policy, rotor_columns
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.records import PUBLISH
from quadfdi.core.profiles import DEFAULT_PROFILE
from quadfdi.formats.manifest import check_files, load_manifest
from quadfdi.formats.onboard import record_dict
from quadfdi.formats.weights_bin import WeightsFile, read_weights

MANIFEST = "manifest.json"
WEIGHTS = "weights.bin"
MANIFEST_ALARM = "manifest alarm"  # the source of a network's policy that is the manifest's single ``alarm``


class Export:
    """An opened export folder: ``root`` and its checked ``manifest`` (the dict as written)."""

    def __init__(self, root: Path, manifest: dict) -> None:
        self.root, self.manifest = root, manifest
        self._weights: WeightsFile | None = None

    @classmethod
    def open(cls, folder: str | Path) -> Export:
        """Load manifest.json (formats.manifest: its schema version) and check every file it lists. The
        export of a run folder whose publish was interrupted (its ``.publish`` holds a stage: new files may
        stand beside the old manifest) is refused with what finishes it: ``quadfdi check``."""
        root = Path(folder)
        pending = root.parent / PUBLISH
        if pending.is_dir() and any(pending.iterdir()):
            raise QuadfdiError(f"{root.parent} holds an interrupted publish ({pending}): run `quadfdi check --run "
                               f"{root.parent}` to finish it, then read {root}")
        manifest = load_manifest(root / MANIFEST)
        check_files(manifest, root)
        return cls(root, manifest)

    def policy(self, net: str) -> tuple[dict, str]:
        """(policy, source) of ``net``: its ``alarm_per_model`` entry (source "config" or "evaluation.json
        sha256 ..."), else the manifest's ``alarm`` ("manifest alarm": an export written before the
        per-network policies, or a network it does not list), over the [alarm] defaults."""
        per = self.manifest.get("alarm_per_model") or {}
        pol, own = resolve_policy(net, {n: e["policy"] for n, e in per.items()}, self.manifest.get("alarm"),
                                  f"manifest alarm ({net}).")
        return pol, str(per[net]["source"]) if own else MANIFEST_ALARM

    def profile(self) -> str:
        """The models' channel profile (core.profiles); ``paper`` for an export written before profiles."""
        return str((self.manifest.get("profile") or {}).get("name", DEFAULT_PROFILE))

    def artifact(self, net: str, precision: str) -> Path:
        """The ONNX graph of ``net`` at ``precision`` (manifest ``artifacts``), a path inside the folder."""
        arts = self.manifest["artifacts"]
        key = f"{net}_{precision}"
        if key not in arts:
            raise QuadfdiError(f"{self.root / MANIFEST} lists no artifact {key} (it has {', '.join(arts)})")
        return self.root / arts[key]

    @property
    def weights_path(self) -> Path:
        return self.root / WEIGHTS

    def weights(self) -> WeightsFile:
        """weights.bin, read (and checked: formats.weights_bin) once."""
        if self._weights is None:
            self._weights = read_weights(self.weights_path)
        return self._weights

    def onboard(self) -> dict:
        """weights.bin's on-board record, or a one-line refusal for an export written before it."""
        return record_dict(self.weights().onboard, self.weights_path)

    def has_motor(self, net: str) -> bool:
        """Whether the exported ``net`` has a motor head (manifest ``motor_head``)."""
        return net in ((self.manifest.get("motor_head") or {}).get("models") or [])

    def rotor_side(self) -> np.ndarray:
        """(K,) bool: the classes whose alarm reports a motor (manifest ``motor_head.rotor_side_classes``;
        none without a head)."""
        names = (self.manifest.get("motor_head") or {}).get("rotor_side_classes") or []
        return rotor_columns(self.class_names, list(names))

    @property
    def class_names(self) -> list[str]:
        return [str(c) for c in self.manifest["class_names"]]

    @property
    def channel_names(self) -> list[str]:
        return [str(c["name"]) for c in self.manifest["channels"]]

    @property
    def window(self) -> int:
        return int(self.manifest["window"])

    @property
    def stride(self) -> int:
        return int(self.manifest["config"]["sim"]["stride"])

    @property
    def sample_dt_s(self) -> float:
        return float(self.manifest["sample_dt_s"])

    @property
    def steps(self) -> int:
        """The CNODE graph's RK4 steps."""
        return int(self.manifest["solver"]["steps"])


def read_record(weights: str | Path) -> dict:
    """The on-board record of a weights.bin file alone, outside an export folder (its manifest is not
    read): what a test of a hand-made weights.bin compares with the C++ reader."""
    return record_dict(read_weights(weights).onboard, weights)
