"""manifest.json: what the export folder holds and how it was checked (docs/formats.md).

Top-level keys, in this order: ``schema_version``, ``producer``, ``channels`` (name, unit),
``n_channels``, ``window``, ``sample_dt_s``, ``class_names``, ``normalisation`` (per model: mean,
std), ``solver`` (classic RK4, N, stage times), ``opset``, ``ir_version``, ``io`` (input and output
tensors), ``artifacts`` (cnode_fp32, cnode_int8, gru_fp32, gru_int8 -> file names relative to the
export folder), ``files`` (name -> sha256, bytes), ``models`` (architecture, MACs),
``quantization`` (scheme, calibration, coverage), ``verification``, ``metrics`` (test split, per
artifact), ``reference`` (the test windows in reference.bin), ``config``, ``profile`` (the input
channels, ``profile_entry``), ``alarm`` (the default alarm policy: core.alarm, the [alarm] section's
keys; what a reader that predates ``alarm_per_model`` runs), ``alarm_per_model`` (network -> {policy,
source}: export/alarm_policies.py; absent in an export written before it), ``deployment`` (the
windowed-or-streaming member deployed per network family as ``quadfdi evaluate`` chose it on
validation, with the sha256 of that evaluation.json: export/deployment.py; null with
``deployment_note`` saying why when there was none to read; absent before it existed), and
only for models with a motor head (models.motor) ``motor_head`` (``motor_entry``; ``io.outputs``
then also lists ``motor_logits``).
A reader must check ``schema_version`` first: ``load_manifest`` refuses any other version.
``deployed(manifest, evaluation_path)`` is what a reader acting on the deployment calls: it refuses an
evaluation.json whose sha256 is no longer the one the deployment was read from.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json, write_json
from quadfdi.core.records import confined, relative_ok

SCHEMA_VERSION = 1
ARTIFACT_KEYS = ("cnode_fp32", "cnode_int8", "gru_fp32", "gru_int8")


def file_entry(data: bytes) -> dict:
    return {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}


def write_manifest(path: str | Path, manifest: dict) -> None:
    write_json(path, manifest, indent=2)


def load_manifest(path: str | Path) -> dict:
    """Read manifest.json; one-line QuadfdiError if missing, not JSON, or of another schema version."""
    p = Path(path)
    if not p.exists():
        raise QuadfdiError(f"manifest {p} does not exist (run `quadfdi export` first)")
    data = read_json(p, "manifest")
    if not isinstance(data, dict) or "schema_version" not in data:
        raise QuadfdiError(f"manifest {p} has no schema_version: not a quadfdi export manifest")
    if data["schema_version"] != SCHEMA_VERSION:
        raise QuadfdiError(f"manifest {p} has schema version {data['schema_version']!r}, this quadfdi reads "
                           f"schema version {SCHEMA_VERSION} (re-run `quadfdi export`)")
    missing = [k for k in ARTIFACT_KEYS if k not in data.get("artifacts", {})]
    if missing:
        raise QuadfdiError(f"manifest {p} lacks artifacts {', '.join(missing)}")
    files = data.get("files")
    if not isinstance(files, dict):
        raise QuadfdiError(f"manifest {p} has no files table: not a quadfdi export manifest")
    for key, name in data["artifacts"].items():
        if not relative_ok(name) or name not in files:
            raise QuadfdiError(f"manifest {p}: artifact {key} is {name!r}, not a file of the export folder that the "
                               "manifest's files table hashes: refused")
    for name, entry in files.items():
        if not relative_ok(name) or not isinstance(entry, dict) or not isinstance(entry.get("sha256"), str):
            raise QuadfdiError(f"manifest {p}: files lists {name!r}, not a file inside the export folder with its "
                               "sha256: refused")
    _check_deployment(data.get("deployment"), p)
    return data


def _check_deployment(dep, p: Path) -> None:
    """``deployment`` is absent, null, or names evaluation.json's sha256 and, per family, a chosen
    member among its candidates (or null)."""
    if dep is None:
        return
    fams = dep.get("families") if isinstance(dep, dict) else None
    if not isinstance(fams, dict) or not isinstance(dep.get("evaluation_sha256"), str):
        raise QuadfdiError(f"manifest {p}: deployment is neither null nor a choice with its evaluation.json sha256")
    for fam, f in fams.items():
        if not isinstance(f, dict) or not isinstance(f.get("candidates"), dict) or (
                f.get("chosen") is not None and f["chosen"] not in f["candidates"]):
            raise QuadfdiError(f"manifest {p}: deployment.families.{fam} chooses a member that is not a candidate")


def deployed(manifest: dict, evaluation_path: str | Path) -> dict[str, str | None]:
    """Family -> deployed member of ``manifest`` (load_manifest's); a one-line QuadfdiError when it has
    no deployment or ``evaluation_path`` is not the evaluation.json it was read from."""
    dep = manifest.get("deployment")
    if dep is None:
        why = manifest.get("deployment_note", "exported before the choice existed")
        raise QuadfdiError(f"the export records no deployed member: {why}")
    path = Path(evaluation_path)
    got = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None
    if got != dep["evaluation_sha256"]:
        found = "missing" if got is None else f"sha256 {got[:16]}..."
        raise QuadfdiError(f"{path} is {found}, the export's deployment was read from sha256 "
                           f"{dep['evaluation_sha256'][:16]}...: re-run quadfdi export")
    return {fam: f.get("chosen") for fam, f in dep["families"].items()}


WINDOWED_NETS = ("cnode", "gru")  # the windowed networks every export holds; ties go to the first


def validation_scores(manifest: dict) -> dict[str, float]:
    """Each windowed network's window macro F1 on the validation flights as the manifest's ``deployment``
    records it (what ``quadfdi evaluate`` chose the deployed members by); {} without a deployment."""
    fams = ((manifest.get("deployment") or {}).get("families") or {})
    out = {}
    for net in WINDOWED_NETS:
        c = ((fams.get(net) or {}).get("candidates") or {}).get(net)
        value = (c.get("macro_f1") or {}).get("value") if isinstance(c, dict) else None
        if isinstance(value, (int, float)):
            out[net] = float(value)
    return out


def better_network(manifest: dict) -> tuple[str, str]:
    """The windowed network ``quadfdi detect`` runs unless told: the one with the higher validation
    score (``validation_scores``), ties to the CNODE; the CNODE when the export records no score for
    both. Returns (network, why in words)."""
    scores = validation_scores(manifest)
    if len(scores) < len(WINDOWED_NETS):
        why = manifest.get("deployment_note") or "no validation score for both windowed networks"
        return WINDOWED_NETS[0], f"the export records no validation scores to choose by ({why})"
    best = max(WINDOWED_NETS, key=lambda n: (scores[n], -WINDOWED_NETS.index(n)))
    text = ", ".join(f"{n} {scores[n]:.4f}" for n in WINDOWED_NETS)
    return best, f"higher window macro F1 on the validation flights in the export's deployment ({text})"


def check_files(manifest: dict, folder: str | Path) -> None:
    """Every file the manifest lists exists in ``folder`` with its sha256 (one-line error otherwise)."""
    root = Path(folder)
    for name, entry in manifest["files"].items():
        f = confined(root, name, "the manifest")
        if not f.is_file() or f.is_symlink():
            raise QuadfdiError(f"{f} is listed in the manifest but missing")
        if hashlib.sha256(f.read_bytes()).hexdigest() != entry["sha256"]:
            raise QuadfdiError(f"{f} does not match its sha256 in the manifest (changed after export?)")
