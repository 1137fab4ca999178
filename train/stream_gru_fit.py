"""Training the streaming GRU for streaming use: long segments of whole flights, truncated
backpropagation through time, random start points and start states, a label at every step. The
settings named below are the keys of the [sgru] section (``StreamFitConfig``, train/config.py).

- Segments: each batch takes ``batch`` training flights; each flight contributes one segment of
  ``segment`` samples that starts at sample 0 with probability ``zero_start`` (a stream that starts
  at take-off, as the evaluation does), else at a uniformly drawn sample.
- Start states: a segment from sample 0 starts at h = 0; a segment from mid-flight starts at h = 0
  (probability 1 - ``noise_start``) or at a random state tanh(N(0, 1)) (``noise_start``), and its
  first ``warmup`` steps carry no loss, so the model learns to forget a wrong or empty state.
- Truncated BPTT: the segment runs in chunks of ``tbptt`` steps, h detached between chunks.
- Labels per step: the dataset's window-label rule applied at the step's sample
  (``formats.dataset.gather_windows``: the flight's class when ``severity[t] >= severity_threshold``,
  else Healthy): the label of a window ending at t is the label of step t.
- Loss: Eq. (12)'s weighted cross-entropy over every labelled step, inverse-frequency class weights
  from the training steps; Adam, cosine rate, gradient norm clipped at ``clip``. Optional onset
  emphasis (``onset_weight`` > 1): more weight on the first ``onset_span`` steps of every fault run,
  class shares kept (train/stream_gru_onset.py); off by default.
- Options (train/stream_gru_segments.py, train/stream_gru_motor.py): segments placed around the onset
  (``onset_segments``), starting anywhere and cut at the flight's end (``start_span = "any"``), class
  weights over the drawn steps (``class_mix = "sampled"``), a training-only motor head whose loss is
  added (``motor_aux``, on by default: chosen on validation, docs/training.md; the logged loss includes it).
- Selection: the epoch whose validation macro F1 (the stream's decision at the validation windows'
  ends, stream started at h = 0 at take-off) is best. With ``ema_decay`` > 0 the weights validated
  and kept are an exponential moving average of the trained ones (train/stream_gru_ema.py); off by
  default.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from sklearn.metrics import f1_score

from quadfdi.core.contracts import SPLIT_TRAIN, SPLIT_VALIDATION
from quadfdi.formats.dataset import Dataset, class_names, window_starts
from quadfdi.train.data import class_weights, fit_normalisation
from quadfdi.models.motor import rotor_side
from quadfdi.models.stream_gru import StreamGRU
from quadfdi.train.config import StreamFitConfig
from quadfdi.train.stream_gru_ema import WeightAverage
from quadfdi.train.stream_gru_motor import MotorAux, step_motor_targets
from quadfdi.train.stream_gru_onset import (
    step_weighted_cross_entropy,
    step_weights,
    weighted_class_weights,
)
from quadfdi.train.stream_gru_segments import (
    draw_segments,
    first_fault,
    loss_mask,
    sampled_class_weights,
    segment_columns,
)


@dataclass
class StreamHistory:
    loss: list[float] = field(default_factory=list)
    val_macro_f1: list[float] = field(default_factory=list)
    epoch_s: list[float] = field(default_factory=list)
    best_epoch: int = -1


def step_labels(ds: Dataset, rows: np.ndarray) -> np.ndarray:
    """(n, T) int64: the window-label rule at every sample of the flights ``rows``."""
    rows = np.asarray(rows, dtype=np.int64)
    fault = ds["severity"][rows] >= ds.severity_threshold
    return np.where(fault, ds["fault_class"][rows].astype(np.int64)[:, None], 0).astype(np.int64)


@torch.no_grad()
def stream_logits(model: StreamGRU, tel: np.ndarray, flights_per_chunk: int = 64) -> np.ndarray:
    """(n, T, K) float32: the logits of a stream started at h = 0 on every flight of ``tel`` (n, T, C)."""
    model.eval()
    out = [model(torch.from_numpy(np.ascontiguousarray(tel[i:i + flights_per_chunk], dtype=np.float32)))[0].numpy()
           for i in range(0, len(tel), flights_per_chunk)]
    return np.concatenate(out) if out else np.zeros((0, tel.shape[1], model.n_classes), np.float32)


def window_end_index(ds: Dataset) -> np.ndarray:
    """Sample index of every window end of a flight (start + W - 1), in ``window_starts`` order."""
    w = ds.config.sim.window
    return window_starts(ds["telemetry"].shape[1], w, ds.config.sim.stride) + w - 1


def _val_f1(model: StreamGRU, ds: Dataset, rows: np.ndarray, ends: np.ndarray) -> float:
    logits = stream_logits(model, ds["telemetry"][rows])[:, ends]
    y = step_labels(ds, rows)[:, ends]
    return float(f1_score(y.ravel(), logits.argmax(-1).ravel(), labels=list(range(model.n_classes)),
                          average="macro", zero_division=0))


def _val_f1_state(model: StreamGRU, ema: WeightAverage | None, ds: Dataset, rows: np.ndarray,
                  ends: np.ndarray) -> tuple[float, dict]:
    """Validation macro F1 of the weights the epoch would keep (the average's with ``ema``), and a copy of them."""
    if ema is None:
        return _val_f1(model, ds, rows, ends), copy.deepcopy(model.state_dict())
    with ema.swapped():
        return _val_f1(model, ds, rows, ends), copy.deepcopy(ema.shadow)


def _batch_loss(model: StreamGRU, opt, x: torch.Tensor, y: torch.Tensor, mask: torch.Tensor, h: torch.Tensor,
                w: torch.Tensor, cfg: StreamFitConfig, m: torch.Tensor | None = None,
                ema: WeightAverage | None = None, aux: MotorAux | None = None, ym: torch.Tensor | None = None) -> float:
    """One segment batch: chunks of ``tbptt`` steps, an optimiser step per chunk; the summed loss.
    ``m`` (B, T): the onset emphasis's step weights (train/stream_gru_onset.py), None without;
    ``ema``: the weight average updated after every optimiser step, None without; ``aux``, ``ym`` (B, T):
    the training-only motor head and its step targets (train/stream_gru_motor.py; its loss is in the sum)."""
    total = 0.0
    params = [p for g in opt.param_groups for p in g["params"]]
    for c0 in range(0, x.shape[1], cfg.tbptt):
        sl = slice(c0, c0 + cfg.tbptt)
        hs, h = model.features(x[:, sl], h)
        logits = model.classify(hs)  # before the mask's test: the head's dropout draws as it always has
        h = h.detach()
        total += chunk_update(model, hs, sl, y, mask, w, cfg, opt, params, m, ema, aux, ym, "streaming GRU", logits)
    return total


def chunk_update(model, feats: torch.Tensor, sl: slice, y: torch.Tensor, mask: torch.Tensor, w: torch.Tensor, cfg,
                 opt, params: list, m: torch.Tensor | None, ema: WeightAverage | None, aux: MotorAux | None,
                 ym: torch.Tensor | None, what: str, logits: torch.Tensor | None = None) -> float:
    """One truncated-backpropagation chunk of a streaming network (its features ``feats`` (B, t, F) over the
    steps ``sl``; ``logits`` its head's, else computed once a step is unmasked): the masked, step-weighted loss
    (plus the motor head's), one clipped optimiser step, the weight average's update; the chunk's summed loss
    (0 when every step is masked)."""
    keep = mask[:, sl].reshape(-1)
    if not bool(keep.any()):
        return 0.0
    if logits is None:
        logits = model.classify(feats)
    mk = None if m is None else m[:, sl].reshape(-1)[keep]
    loss = step_weighted_cross_entropy(logits.reshape(-1, model.n_classes)[keep], y[:, sl].reshape(-1)[keep], w,
                                       mk, cfg.log_eps)
    if aux is not None:
        loss = loss + aux.loss(feats.reshape(-1, feats.shape[-1])[keep], ym[:, sl].reshape(-1)[keep])
    if not bool(torch.isfinite(loss)):
        raise ValueError(f"{what} training diverged (non-finite loss) at lr {cfg.lr:g}: lower it")
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(params, cfg.clip)
    opt.step()
    if ema is not None:
        ema.update()
    return loss.item() * int(keep.sum())


def stream_class_weights(lab: np.ndarray, sw: np.ndarray | None, cfg, n_classes: int) -> np.ndarray:
    """Eq. (12)'s class weights: over every training step (default), the onset emphasis's weighted steps,
    or (``class_mix = "sampled"``) the steps the segment sampler draws (train/stream_gru_segments.py)."""
    if sw is not None:
        return weighted_class_weights(lab, sw, n_classes)
    if cfg.class_mix == "sampled":
        return sampled_class_weights(lab, cfg, n_classes)
    return class_weights(lab.ravel(), n_classes)


def _motor_aux(ds: Dataset, cfg: StreamFitConfig, lab: np.ndarray, rows: np.ndarray) -> MotorAux | None:
    """The training-only motor head (``motor_aux`` > 0 and a rotor-side class in the data), else None."""
    names = class_names(ds.arrays)
    if cfg.motor_aux <= 0 or not rotor_side(names).any():
        return None
    return MotorAux(cfg.hidden, cfg.motor_aux, step_motor_targets(lab, rows, ds["fault_motor"], names))


def fit_stream_gru(ds: Dataset, cfg: StreamFitConfig, log: Callable[[str], None] = print) -> tuple[StreamGRU, StreamHistory]:
    """Train a streaming GRU on the training flights of ``ds``; keep the best-validation epoch."""
    cfg.validate()
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(0x5690,)))
    split = np.asarray(ds["split"])
    train_rows, val_rows = np.flatnonzero(split == SPLIT_TRAIN), np.flatnonzero(split == SPLIT_VALIDATION)
    if len(train_rows) == 0 or len(val_rows) == 0:
        raise ValueError("the streaming GRU needs training and validation flights")
    n_classes = len(class_names(ds.arrays))
    model = StreamGRU(ds.n_channels, cfg.hidden, n_classes)
    model.set_normalisation(*fit_normalisation(ds))
    model.head_dropout = cfg.head_dropout
    tel = ds["telemetry"][train_rows]  # (n, T, C) float32, raw: the model normalises inside
    lab = step_labels(ds, train_rows)
    sw = step_weights(lab, cfg.onset_weight, cfg.onset_span)  # None: no onset emphasis (the default)
    w = torch.as_tensor(stream_class_weights(lab, sw, cfg, n_classes))
    onset = first_fault(lab)
    ends = window_end_index(ds)
    n_t = tel.shape[1]
    seg = min(cfg.segment, n_t)
    aux = _motor_aux(ds, cfg, lab, train_rows)
    params = list(model.parameters()) + ([] if aux is None else list(aux.parameters()))
    opt = torch.optim.AdamW(params, lr=cfg.lr, weight_decay=cfg.weight_decay)
    n_opt = cfg.epochs * (-(-len(train_rows) // cfg.batch)) * (-(-seg // cfg.tbptt))
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=n_opt)
    hist, best_f1, best_state = StreamHistory(), -1.0, None
    ema = WeightAverage(model, cfg.ema_decay) if cfg.ema_decay > 0 else None
    for epoch in range(cfg.epochs):
        model.train()
        t0, total, count = time.perf_counter(), 0.0, 0
        perm = rng.permutation(len(train_rows))
        for b0 in range(0, len(perm), cfg.batch):
            idx = perm[b0:b0 + cfg.batch]
            start, mid = draw_segments(rng, n_t, onset[idx], cfg)
            cols = segment_columns(start, seg, n_t)
            x = torch.from_numpy(np.ascontiguousarray(tel[idx[:, None], cols]))
            y = torch.from_numpy(lab[idx[:, None], cols])
            mask = torch.from_numpy(loss_mask(start, mid, seg, cfg.warmup, n_t))
            noisy = mid & (rng.random(len(idx)) < cfg.noise_start)
            h0 = np.where(noisy[:, None], np.tanh(rng.standard_normal((len(idx), cfg.hidden))), 0.0)
            m = None if sw is None else torch.from_numpy(sw[idx[:, None], cols])
            ym = None if aux is None else torch.from_numpy(aux.targets[idx[:, None], cols])
            total += _batch_loss(model, opt, x, y, mask, torch.as_tensor(h0, dtype=torch.float32), w, cfg, m, ema, aux, ym)
            for _ in range(-(-seg // cfg.tbptt)):
                sched.step()
            count += int(mask.sum())
        hist.epoch_s.append(time.perf_counter() - t0)
        hist.loss.append(total / max(count, 1))
        f1, state = _val_f1_state(model, ema, ds, val_rows, ends)
        hist.val_macro_f1.append(f1)
        if f1 > best_f1:
            best_f1, best_state, hist.best_epoch = f1, state, epoch
        log(f"  epoch {epoch + 1:2d}/{cfg.epochs}: loss {hist.loss[-1]:.4f}, val macro F1 {f1:.4f}, "
            f"{hist.epoch_s[-1]:.1f} s")
    model.load_state_dict(best_state)
    model.eval()
    return model, hist


def config_dict(cfg: StreamFitConfig) -> dict:
    return asdict(cfg)
