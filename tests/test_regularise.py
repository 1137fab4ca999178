"""The recipe's regularisation keys: weight decay (AdamW), input-channel and latent dropout.

Off by default (the same optimiser and the same weights as without the keys), dropout only while
training (the eval logits and the exported graph do not depend on the rates), bounds refused in one line.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

import quadfdi.train.loop as loop
from quadfdi.core.config import Config, load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import Windows
from quadfdi.models.networks import build_model
from tests.conftest import quadfdi

C, W = 6, 20


def _windows(n: int = 40, seed: int = 0) -> Windows:
    rng = np.random.default_rng(seed)
    z = np.zeros(n, dtype=np.int64)
    return Windows(x=rng.standard_normal((n, W, C)).astype(np.float32), y=rng.integers(0, 4, n), traj=np.arange(n),
                   start=z, t_end=z.astype(np.float64))


def _trained(kind: str, sets: list[str]) -> dict:
    cfg = load_config(None, ["train.epochs=2", "train.gru_hidden=8", "train.latent=6", "train.hidden=8",
                             "train.steps=2", "train.batch_size=16", *sets]).train
    torch.manual_seed(0)
    model = build_model(kind, C, cfg, window=W, n_classes=4)
    loop.train_model(model, _windows(), _windows(seed=1), cfg, np.ones(4, np.float32), log=lambda s: None)
    return model.state_dict()


def test_defaults_change_nothing():
    cfg = Config().train
    assert (cfg.weight_decay, cfg.dropout_in, cfg.dropout_latent) == (0.0, 0.0, 0.0)
    model = build_model("gru", C, cfg, window=W, n_classes=4)
    assert type(loop.make_optimizer(model, cfg)) is torch.optim.Adam


@pytest.mark.parametrize("kind", ["cnode", "gru"])
def test_weight_decay_zero_is_the_adam_of_before_bit_for_bit(kind, monkeypatch):
    key = "train.gru_weight_decay" if kind == "gru" else "train.weight_decay"
    now = _trained(kind, [f"{key}=0"])
    decayed = _trained(kind, [f"{key}=0.1"])
    other = _trained(kind, ["train.weight_decay=0.1" if kind == "gru" else "train.gru_weight_decay=0.1"])
    monkeypatch.setattr(loop, "make_optimizer",  # the optimiser line as it was before weight decay existed
                        lambda m, cfg: torch.optim.Adam(m.parameters(), lr=loop.learning_rate(m, cfg)))
    before = _trained(kind, [])
    assert all(torch.equal(now[k], before[k]) for k in before)
    assert all(torch.equal(other[k], before[k]) for k in before)  # the other network's key leaves this one alone
    assert any(not torch.equal(decayed[k], before[k]) for k in before)


@pytest.mark.parametrize("kind", ["cnode", "gru"])
def test_dropout_is_identity_in_eval_and_acts_in_training(kind):
    cfg = load_config(None, ["train.latent=6", "train.hidden=8", "train.gru_hidden=8", "train.steps=2"]).train
    torch.manual_seed(0)
    plain = build_model(kind, C, cfg, window=W, n_classes=4)
    rates = load_config(None, ["train.latent=6", "train.hidden=8", "train.gru_hidden=8", "train.steps=2",
                               "train.dropout_in=0.5", "train.dropout_latent=0.5"]).train
    dropped = build_model(kind, C, rates, window=W, n_classes=4)
    dropped.load_state_dict(plain.state_dict())
    x = torch.from_numpy(_windows(8).x)
    plain.eval(), dropped.eval()
    with torch.no_grad():
        assert torch.equal(plain(x), dropped(x))
        assert set(plain.state_dict()) == set(dropped.state_dict())
        dropped.train()
        assert not torch.equal(plain(x), dropped(x))


def test_build_model_reads_the_rates():
    cfg = load_config(None, ["train.dropout_in=0.1", "train.dropout_latent=0.3"]).train
    for kind in ("cnode", "gru"):
        m = build_model(kind, C, cfg, window=W, n_classes=4)
        assert (m.dropout_in, m.dropout_latent) == (0.1, 0.3)


@pytest.mark.parametrize("override", ["train.weight_decay=-0.01", "train.dropout_in=1.0", "train.dropout_latent=-0.1"])
def test_bounds_refused(override):
    with pytest.raises(QuadfdiError):
        load_config(None, [override])


def test_cli_refuses_a_bad_rate_in_one_line(tmp_path):
    res = quadfdi("sim", "--out", str(tmp_path / "run"), "--set", "train.dropout_in=1.5")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and not (tmp_path / "run").exists()
    assert "train.dropout_in must lie in [0, 1), found 1.5" in res.stderr


def test_the_exported_graph_does_not_depend_on_the_rates():
    from quadfdi.export.onnx_cnode import build_cnode, cnode_params
    from quadfdi.export.onnx_gru import build_gru_fp32, gru_params

    def graphs(sets: list[str]) -> tuple[bytes, bytes]:
        cfg = load_config(None, ["train.latent=6", "train.hidden=8", "train.gru_hidden=8", *sets]).train
        torch.manual_seed(0)
        cnode, gru = (build_model(k, C, cfg, window=W, n_classes=4) for k in ("cnode", "gru"))
        return (build_cnode(cnode_params(cnode, 2), 18).model.SerializeToString(),
                build_gru_fp32(gru_params(gru), 18).model.SerializeToString())

    assert graphs([]) == graphs(["train.dropout_in=0.3", "train.dropout_latent=0.5"])


def _history(sets: list[str]) -> "loop.History":
    cfg = load_config(None, ["train.epochs=8", "train.latent=6", "train.hidden=8", "train.steps=2",
                             "train.batch_size=16", *sets]).train
    torch.manual_seed(0)
    model = build_model("cnode", C, cfg, window=W, n_classes=4)
    return loop.train_model(model, _windows(), _windows(seed=1), cfg, np.ones(4, np.float32), log=lambda s: None)


def test_patience_stops_after_that_many_epochs_without_gain():
    full = _history([])
    stopped = _history(["train.patience=1"])
    assert len(full.val_macro_f1) == 8
    # the same epochs up to the first one that did not beat the best so far, then the stop
    first_flat = next(e for e in range(1, 8) if full.val_macro_f1[e] <= max(full.val_macro_f1[:e]))
    assert stopped.val_macro_f1 == full.val_macro_f1[:first_flat + 1]
    assert stopped.best_epoch == int(np.argmax(stopped.val_macro_f1))


def test_outputs_and_patience_bounds_are_refused_in_one_line():
    res = quadfdi("sim", "--out", "/nonexistent/run", "--set", "train.outputs=some")  # checked before any work
    assert res.returncode == 2 and "train.outputs" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    with pytest.raises(QuadfdiError, match="patience"):
        load_config(None, ["train.patience=-1"])


def _fit(kind: str, sets: list[str]) -> tuple[torch.nn.Module, "loop.History", Windows]:
    cfg = load_config(None, ["train.epochs=3", "train.gru_hidden=8", "train.latent=6", "train.hidden=8",
                             "train.steps=2", "train.batch_size=16", *sets]).train
    torch.manual_seed(0)
    model, val = build_model(kind, C, cfg, window=W, n_classes=4), _windows(seed=1)
    return model, loop.train_model(model, _windows(), val, cfg, np.ones(4, np.float32), log=lambda s: None), val


@pytest.mark.parametrize("kind", ["cnode", "gru"])
def test_the_weight_average_is_validated_kept_and_off_by_default(kind):
    """``train.ema_decay``: the kept weights are the average's at the best epoch (its validation macro F1 is
    what the history says); 0 changes nothing."""
    from sklearn.metrics import f1_score

    model, hist, val = _fit(kind, ["train.ema_decay=0.9"])
    pred = loop.predict_proba(model, val.x).argmax(1)
    assert f1_score(val.y, pred, labels=list(range(4)), average="macro", zero_division=0) == \
        hist.val_macro_f1[hist.best_epoch]
    plain, off = _fit(kind, [])[0].state_dict(), _fit(kind, ["train.ema_decay=0"])[0].state_dict()
    assert any(not torch.equal(model.state_dict()[k], plain[k]) for k in plain)
    assert all(torch.equal(off[k], plain[k]) for k in plain)
    with pytest.raises(QuadfdiError, match=r"train.ema_decay must lie in \[0, 1\)"):
        load_config(None, ["train.ema_decay=1.0"])
