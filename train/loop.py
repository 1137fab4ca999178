"""The training loop, read top to bottom: weighted cross-entropy (Eq. 12), Adam or AdamW, fixed batches.

Both models go through the same function with the same batches (``train.data.batch_order``).
The weights kept are those of the epoch with the best validation macro F1 (the validation
split exists for that choice; the test split is never looked at here).
"""

from __future__ import annotations

import contextlib
import copy
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch
from sklearn.metrics import f1_score

from quadfdi.train.config import TrainConfig
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import Windows
from quadfdi.train.data import batch_order
from quadfdi.train.stream_gru_ema import WeightAverage
from quadfdi.models.networks import GRUClassifier
from quadfdi.models.motor import has_motor_head, motor_loss


def weighted_cross_entropy(logits: torch.Tensor, y: torch.Tensor, weights: torch.Tensor, eps: float) -> torch.Tensor:
    """Eq. (12): L = -(1/B) sum_b sum_k w_k y_bk log(p_bk + eps); logits (B, K), y (B,)."""
    p = torch.softmax(logits, dim=1)
    picked = p.gather(1, y[:, None]).squeeze(1)  # (B,) probability of the true class
    return -(weights[y] * torch.log(picked + eps)).mean()


@torch.no_grad()
def predict_proba(model: torch.nn.Module, x: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """Class probabilities (n, K) float64 for raw windows x (n, W, C); K = ``model.n_classes``."""
    model.eval()
    out = []
    for i in range(0, len(x), batch_size):
        logits = model(torch.from_numpy(np.ascontiguousarray(x[i:i + batch_size])))
        out.append(torch.softmax(logits.double(), dim=1).numpy())
    return np.concatenate(out) if out else np.zeros((0, model.n_classes))


@dataclass
class History:
    loss: list[float] = field(default_factory=list)  # mean training loss per epoch
    val_macro_f1: list[float] = field(default_factory=list)
    epoch_s: list[float] = field(default_factory=list)
    nfe_per_forward: list[float] = field(default_factory=list)  # CNODE only
    best_epoch: int = -1

    def to_dict(self, times: bool = True) -> dict:
        """The history as plain lists; ``times=False`` leaves out the wall-clock ``epoch_s``, which
        differs from run to run, so that what is stored in a checkpoint depends on data, config and
        seed alone (same seed, same checkpoint bytes)."""
        out = {"loss": self.loss, "val_macro_f1": self.val_macro_f1, "epoch_s": self.epoch_s,
               "nfe_per_forward": self.nfe_per_forward, "best_epoch": self.best_epoch}
        if not times:
            del out["epoch_s"]
        return out


def learning_rate(model: torch.nn.Module, cfg: TrainConfig) -> float:
    """The initial Adam rate of ``model``'s kind (the GRU trains best at a lower rate)."""
    return cfg.gru_lr if isinstance(model, GRUClassifier) else cfg.lr


def weight_decay(model: torch.nn.Module, cfg: TrainConfig) -> float:
    """The decoupled weight decay of ``model``'s kind (each network's recipe is searched on its own)."""
    return cfg.gru_weight_decay if isinstance(model, GRUClassifier) else cfg.weight_decay


def make_optimizer(model: torch.nn.Module, cfg: TrainConfig) -> torch.optim.Optimizer:
    """Adam at ``learning_rate``; with a ``weight_decay`` > 0 for the model's kind, AdamW (decay
    decoupled from the gradient's moments, scaled by the scheduled rate). 0 builds plain Adam."""
    decay = weight_decay(model, cfg)
    if decay > 0:
        return torch.optim.AdamW(model.parameters(), lr=learning_rate(model, cfg), weight_decay=decay)
    return torch.optim.Adam(model.parameters(), lr=learning_rate(model, cfg))


def _stop_if_diverged(value: torch.Tensor, model: torch.nn.Module, cfg: TrainConfig, epoch: int) -> None:
    """A non-finite loss or output means training diverged: stop with what to change, instead of
    a NaN that surfaces later as a traceback in the metrics."""
    if not bool(torch.isfinite(value).all()):
        name = "gru_lr" if isinstance(model, GRUClassifier) else "lr"
        raise QuadfdiError(f"training of the {type(model).__name__} diverged in epoch {epoch + 1} (non-finite loss "
                           f"or output) at train.{name}={learning_rate(model, cfg):g}: lower train.{name}")


def train_model(model: torch.nn.Module, train: Windows, val: Windows, cfg: TrainConfig, weights: np.ndarray,
                log: Callable[[str], None] = print, motor: np.ndarray | None = None,
                augment: Callable[[torch.Tensor, int, int], torch.Tensor] | None = None) -> History:
    """Train ``model`` in place for ``cfg.epochs`` epochs (fewer with ``cfg.patience``: early stopping
    on validation flights); keep the best-validation weights.

    A model with a motor head (models.motor) needs ``motor``, (n,) the target motor of each training
    window (-1: no motor loss); its loss is the class loss + cfg.motor_loss_weight x the motor
    cross-entropy. The epoch is still chosen on the validation macro F1 of the classes.
    ``augment(x, epoch, batch)`` (train.augment) changes each training batch, never the validation."""
    if has_motor_head(model) and (motor is None or len(motor) != len(train)):
        raise ValueError("a model with a motor head needs one target motor per training window")
    torch.manual_seed(cfg.seed)
    opt = make_optimizer(model, cfg)
    n_batches = -(-len(train) // cfg.batch_size)
    sched = None
    if cfg.lr_schedule == "cosine":
        # The validation F1 oscillates by several points from epoch to epoch at a constant rate;
        # annealing the rate over the fixed 14 epochs settles it.
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=cfg.epochs * n_batches)
    w = torch.as_tensor(weights, dtype=torch.float32)
    x_all = torch.from_numpy(train.x)
    y_all = torch.from_numpy(train.y)
    m_all = torch.from_numpy(np.asarray(motor, dtype=np.int64)) if has_motor_head(model) else None
    hist = History()
    best_f1, best_state = -1.0, None
    ema = WeightAverage(model, cfg.ema_decay) if cfg.ema_decay > 0 else None
    for epoch in range(cfg.epochs):
        model.train()
        t0 = time.perf_counter()
        losses, nfes = [], []
        for bi, idx in enumerate(batch_order(len(train), cfg.batch_size, cfg.seed, epoch)):
            idx_t = torch.from_numpy(idx)
            xb = x_all[idx_t] if augment is None else augment(x_all[idx_t], epoch, bi)
            z = model.features(xb) if m_all is not None else None
            logits = model(xb) if z is None else model.head(z)
            if hasattr(model, "nfe"):
                nfes.append(float(model.nfe))
            loss = weighted_cross_entropy(logits, y_all[idx_t], w, cfg.log_eps)
            if z is not None:
                loss = loss + cfg.motor_loss_weight * motor_loss(model.motor_head(z), m_all[idx_t])
            _stop_if_diverged(loss, model, cfg, epoch)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            if ema is not None:
                ema.update()
            if sched is not None:
                sched.step()
            losses.append(loss.item() * len(idx))
        hist.epoch_s.append(time.perf_counter() - t0)
        hist.loss.append(float(sum(losses) / len(train)))
        if nfes:
            hist.nfe_per_forward.append(float(np.mean(nfes)))
        with (ema.swapped() if ema is not None else contextlib.nullcontext()):  # validate, keep the average
            val_proba = predict_proba(model, val.x)
            _stop_if_diverged(torch.as_tensor(val_proba), model, cfg, epoch)
            val_pred = val_proba.argmax(1)
            f1 = float(f1_score(val.y, val_pred, labels=list(range(model.n_classes)), average="macro", zero_division=0))
            hist.val_macro_f1.append(f1)
            if f1 > best_f1:
                best_f1, best_state, hist.best_epoch = f1, copy.deepcopy(model.state_dict()), epoch
        nfe_txt = f", {hist.nfe_per_forward[-1]:.0f} NFE/forward" if nfes else ""
        log(f"  epoch {epoch + 1:2d}/{cfg.epochs}: loss {hist.loss[-1]:.4f}, val macro F1 {f1:.4f}, "
            f"{hist.epoch_s[-1]:.1f} s{nfe_txt}")
        if cfg.patience and epoch - hist.best_epoch >= cfg.patience:
            log(f"  early stop: no gain in validation macro F1 for {cfg.patience} epochs")
            break
    if best_state is not None:
        model.load_state_dict(best_state)
    model.eval()
    return hist
