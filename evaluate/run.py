"""``evaluate_run``: the evaluation stage, published as a unit into <run>/evaluation/.

Inputs are the prediction sets and datasets the index lists. Those a stage published are
verified against their records (core.stage consume); every one is listed in evaluation.json with
its sha256. The code's git commit (and whether the tree had uncommitted changes) is recorded:
the protocol is frozen before a test evaluation, and the commit is how that is checked.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Callable

from quadfdi.core import records
from quadfdi.core.config import Config
from quadfdi.core.jsonio import write_json
from quadfdi.core.resources import source_tree
from quadfdi.core.atomic import write_text
from quadfdi.formats.predictions import INDEX_NAME
from quadfdi.core.stage import stage
from quadfdi.evaluate.deployment import deployment
from quadfdi.evaluate.figures import SWEEP_PNG, sweep_figure
from quadfdi.evaluate.load import load_run
from quadfdi.evaluate.protocol import evaluate_sets
from quadfdi.evaluate.report import JSON_NAME, MD_NAME, markdown

SCHEMA_VERSION = 1


def git_state() -> tuple[str | None, bool]:
    """(HEAD commit of the code, whether the working tree differs from it); (None, True) outside git,
    as for an installed wheel (whose site-packages may well lie inside some other git tree)."""
    root = source_tree()
    if root is None:
        return None, True
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "status", "--porcelain"], cwd=root, capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None, True
    if head.returncode != 0:
        return None, True
    return head.stdout.strip(), bool(dirty.stdout.strip()) or dirty.returncode != 0


def _inputs(st, root: Path, rels: list[str]) -> list[dict]:
    out = []
    for rel in sorted(set(rels)):
        if records.producer_of(root, rel) is not None:
            st.consume(rel)  # verified against the record of the stage that published it
            entry = st.inputs[rel]
            out.append({"path": rel, "sha256": entry["sha256"], "published_by": entry["stage"]})
        else:
            out.append({"path": rel, "sha256": records.sha256_file(root / rel), "published_by": None})
    return out


def evaluate_run(root: Path, cfg: Config, command: str, log: Callable[[str], None] = print) -> list[Path]:
    """Evaluate every indexed prediction set of the run; return the written files (final paths)."""
    root = Path(root)
    sections = {"alarm": cfg.to_dict()["alarm"], "evaluate": cfg.to_dict()["evaluate"]}
    if not _prediction_paths(root):  # the one-line error before any staging
        load_run(root)
    with stage(root, "evaluate", sections, targets=(str(JSON_NAME), str(MD_NAME))) as st:
        sets, infos = load_run(root)
        log(f"evaluate: {len(sets)} prediction sets of {len({s.model for s in sets})} models on {len(infos)} datasets")
        inputs = _inputs(st, root, [s.dataset for s in sets] + [e for e in _prediction_paths(root)])
        commit, dirty = git_state()
        ev = {"schema_version": SCHEMA_VERSION, "git_commit": commit, "git_dirty": dirty, "command": command,
              "config": sections, "inputs": inputs, "index": str(INDEX_NAME),
              "protocol": {"bootstrap": cfg.evaluate.bootstrap, "seed": cfg.evaluate.seed, "ci": cfg.evaluate.ci,
                           "target_fa_per_h": cfg.evaluate.target_fa_per_h, "unit": "flight",
                           "train_seeds": "averaged per flight before resampling",
                           "sim_seeds": "flights of every dataset are units of one pool"}}
        ev.update(evaluate_sets(sets, infos, cfg))
        ev["deployment"] = deployment(ev["results"], ev["paired"], _entries(root), inputs)  # windowed or streaming, on validation
        out = st.path(str(JSON_NAME)).parent
        write_json(out / JSON_NAME.name, ev)
        write_text(out / MD_NAME.name, markdown(ev) + "\n")
        sweep_figure(ev["models"], cfg.evaluate.target_fa_per_h, out / SWEEP_PNG)
    return [root / JSON_NAME, root / MD_NAME, root / JSON_NAME.parent / SWEEP_PNG]


def _entries(root: Path) -> list[dict]:
    from quadfdi.formats.predictions import read_index

    return read_index(root)


def _prediction_paths(root: Path) -> list[str]:
    return [e["predictions"] for e in _entries(root)]
