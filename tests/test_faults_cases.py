"""Bad inputs as a table: a careless or unlucky user's edit of a published run, the
command that follows, and the words its one-line error must contain. Each case runs the real
dispatcher (``quadfdi.cli.main``) in process -- importing torch once, not once per case -- and
checks one line on stderr, no traceback (an uncaught exception fails the test), and that the run
folder is still in its published state."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
from pathlib import Path

import pytest

from tests.faultkit import copy_run, snapshot


def inproc(*args: str) -> tuple[int, str]:
    from quadfdi.cli import main

    handlers = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGXFSZ)}
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            rc = main(list(args))
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
    return rc, err.getvalue()


def forge(run: Path, rel: str) -> None:
    """Update the record listing ``rel`` to the file's current hash: a file the record vouches for,
    so the reader's own checks (not the hash) must refuse it."""
    from quadfdi.core.records import sha256_file

    for rec_path in (run / ".stages").glob("*.json"):
        rec = json.loads(rec_path.read_text())
        for e in rec["outputs"]:
            if e["path"] == rel:
                e["sha256"], e["bytes"] = sha256_file(run / rel), (run / rel).stat().st_size
                rec_path.write_text(json.dumps(rec))


def edit(path: Path, fn) -> None:
    path.write_text(fn(path.read_text()))


def flip_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def relink(path: Path) -> None:
    target = path.with_name("elsewhere.bin")
    os.replace(path, target)
    path.symlink_to(target)


def torch_edit(path: Path, fn) -> None:
    import torch

    blob = torch.load(path, weights_only=True)
    fn(blob)
    torch.save(blob, path)


def nan_weight(blob: dict) -> None:
    key = next(k for k, v in blob["state_dict"].items() if v.is_floating_point() and k not in ("mean", "std"))
    blob["state_dict"][key] = blob["state_dict"][key].clone().fill_(float("nan"))


def truncate_with_manifest(run: Path) -> None:
    """Truncate an int8 graph and update the manifest's sha256 (but not the stage record)."""
    from quadfdi.core.records import sha256_file

    onnx = run / "export" / "gru.int8.onnx"
    onnx.write_bytes(onnx.read_bytes()[:1000])
    man = json.loads((run / "export" / "manifest.json").read_text())
    man["files"]["gru.int8.onnx"].update(sha256=sha256_file(onnx), bytes=1000)
    (run / "export" / "manifest.json").write_text(json.dumps(man))


_OTHER_SIM: list[Path] = []  # the fault_sims "new" run, set by the test that uses it


def republish_sim(run: Path) -> None:
    """Another dataset published under the trained models (as `quadfdi sim` with another config)."""
    import shutil

    for name in ("config.toml", "dataset.npz", ".stages/sim.json"):
        shutil.copy(_OTHER_SIM[0] / name, run / name)


SIM_CASES = [  # (case, mutation of the sim-only run, command after --run/--out RUN, words of the error)
    ("empty config.toml", lambda r: (r / "config.toml").write_text(""), ["train"], "is empty"),
    ("config.toml not TOML", lambda r: (r / "config.toml").write_text("[sim\n"), ["train"], "not valid TOML"),
    ("config.toml [sim] edited", lambda r: edit(r / "config.toml", lambda t: t.replace("n_traj = 4", "n_traj = 5")),
     ["train"], "[sim].n_traj"),
    ("--set sim.* on train", None, ["train", "--set", "sim.n_traj=5"], "[sim].n_traj"),
    ("dataset.npz byte flipped", lambda r: flip_byte(r / "dataset.npz"), ["train"], "sha256"),
    ("dataset.npz truncated", lambda r: (r / "dataset.npz").write_bytes((r / "dataset.npz").read_bytes()[:5000]),
     ["train"], "sha256"),
    ("dataset.npz deleted", lambda r: (r / "dataset.npz").unlink(), ["train"], "dataset.npz is missing"),
    ("dataset.npz a symlink", lambda r: relink(r / "dataset.npz"), ["train"], "not a regular file"),
    ("sim record deleted", lambda r: (r / ".stages/sim.json").unlink(), ["train"], "not a published output"),
    ("sim record corrupt", lambda r: (r / ".stages/sim.json").write_text("{"), ["train"], "stage record"),
    ("sim.window=1", None, ["sim", "--set", "sim.window=1"], "sim.window must be 2"),
    ("negative seed", None, ["sim", "--set", "sim.seed=-1"], "sim.seed must not be negative"),
    ("huge n_traj", None, ["sim", "--set", "sim.n_traj=100000000000"], "sim.n_traj must be at most"),
    ("n_traj beyond memory", None, ["sim", "--set", "sim.n_traj=500000000"], "memory"),
    ("train.threads=100000", None, ["train", "--set", "train.threads=100000"], "train.threads must be at most"),
    ("train --seed -1", None, ["train", "--seed", "-1"], "train.seed must not be negative"),
    ("negative train.seeds", None, ["train", "--set", "train.seeds=[0, -1]"], "train.seeds"),
    ("export.steps=65", None, ["export", "--set", "export.steps=65"], "export.steps must be at most 64"),
    ("export --steps 65", None, ["export", "--steps", "65"], "export.steps must be at most 64"),
    ("unknown key", None, ["sim", "--set", "sim.n_trajs=4"], "unknown key sim.n_trajs"),
    ("export before train", None, ["export"], "cnode.pt does not exist"),
]

TRAINED_CASES = [
    ("empty cnode.pt", lambda r: ((r / "cnode.pt").write_bytes(b""), forge(r, "cnode.pt")), ["export"],
     "cannot be read"),
    ("NaN weight", lambda r: (torch_edit(r / "cnode.pt", nan_weight), forge(r, "cnode.pt")), ["export"], "NaN"),
    ("negative size", lambda r: (torch_edit(r / "cnode.pt", lambda b: b["architecture"].update(latent=-4)),
                                 forge(r, "cnode.pt")), ["export"], "must not be negative"),
    ("cnode.pt replaced", lambda r: (r / "cnode.pt").write_bytes((r / "gru.pt").read_bytes()), ["export"], "sha256"),
    ("truncated ONNX, manifest sha updated", truncate_with_manifest, ["parity", "--no-mcu"], "sha256"),
    ("weights.bin edited", lambda r: flip_byte(r / "export/weights.bin"), ["parity", "--no-mcu"], "sha256"),
    ("metrics.json a folder", lambda r: ((r / "metrics.json").unlink(), (r / "metrics.json").mkdir()),
     ["train", "--set", "train.epochs=1"], "metrics.json is a folder"),
    ("history.json a symlink", lambda r: relink(r / "history.json"), ["train", "--set", "train.epochs=1"],
     "refusing to replace"),
    ("checkpoints of an older dataset", republish_sim, ["export"], "re-run quadfdi train"),
    ("diverging training", None, ["train", "--model", "cnode", "--set", "train.epochs=1", "--set", "train.lr=1e30"],
     "lower train.lr"),
]


def _check_case(run: Path, mutate, command: list[str], words: str) -> None:
    if mutate is not None:
        mutate(run)
    before = snapshot(run)
    flag = "--out" if command[0] == "sim" else "--run"
    extra = ["--config", str(run / "config.toml")] if command[0] == "sim" else []
    rc, err = inproc(command[0], flag, str(run), *extra, *command[1:])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and words in lines[0], err
    assert snapshot(run) == before  # a refused command changes nothing
    assert not list(run.glob(".staging/*")) and not list(run.glob(".publish/*"))


@pytest.mark.parametrize("case,mutate,command,words", SIM_CASES, ids=[c[0] for c in SIM_CASES])
def test_sim_run_case(fault_sims, tmp_path, case, mutate, command, words):
    _check_case(copy_run(fault_sims["old"], tmp_path / "run"), mutate, command, words)


@pytest.mark.parametrize("case,mutate,command,words", TRAINED_CASES, ids=[c[0] for c in TRAINED_CASES])
def test_trained_run_case(fault_exported, fault_sims, tmp_path, case, mutate, command, words):
    _OTHER_SIM[:] = [fault_sims["new"]]
    _check_case(copy_run(fault_exported, tmp_path / "run"), mutate, command, words)
