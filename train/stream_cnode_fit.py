"""Training the streaming CNODE (models/stream_cnode.py) for streaming use, the streaming GRU's recipe
(train/stream_gru_fit.py) with the latent state z in the place of h; the keys are the [scnode] section's
(``StreamCnodeConfig``, train/config.py).

- Segments (train/stream_gru_segments.py): ``segment`` samples per flight of a batch, from take-off with
  probability ``zero_start``, else from a drawn sample; a mid-flight segment's first sample is held
  (v_{t-1} = v_t, as after a reset on board) and its first ``warmup`` steps carry no loss.
- Start states: z = 0 from take-off; mid-flight z = 0 or, with probability ``noise_start``, a random
  state tanh(N(0, 1)) * ``NOISE_SCALE`` (the stream's state reaches a few units, a GRU's h at most 1).
- Truncated BPTT in chunks of ``tbptt`` steps: z detached between chunks, the chunk's previous raw sample
  carried so that the control is interpolated across the cut exactly as without it.
- The run's channel profile (models.inputs.profiled_dataset): training on every channel of the profile,
  and for a masked profile (core.profiles.is_masked) one mask pattern drawn per segment
  (train.masks.draw_patterns, Masker: the windowed networks' per-window draw, here per segment, from the
  generator stream (seed, MASK_KEY)), the availability channels normalised at mean 0, std 1; validation
  and the prediction set read each flight under its own pattern (``patterns=True``: what export
  calibrates on and parity replays).
- Labels, Eq. (12)'s weighted loss, onset emphasis, class mix, motor auxiliary head, EMA, selection on
  validation macro F1 at the windows' ends, stream from take-off: as the streaming GRU.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable

import numpy as np
import torch
from sklearn.metrics import f1_score

from quadfdi.core.contracts import SPLIT_TRAIN, SPLIT_VALIDATION
from quadfdi.formats.dataset import Dataset, class_names
from quadfdi.models.stream_cnode import StreamCNODE
from quadfdi.train.config import StreamCnodeConfig
from quadfdi.models.motor import rotor_side
from quadfdi.train.data import fit_normalisation
from quadfdi.train.stream_gru_ema import WeightAverage
from quadfdi.train.stream_gru_fit import (StreamHistory, chunk_update, step_labels, stream_class_weights,
                                          window_end_index)
from quadfdi.train.stream_gru_motor import MotorAux, step_motor_targets
from quadfdi.train.stream_gru_onset import step_weights
from quadfdi.train.stream_gru_segments import draw_segments, first_fault, loss_mask, segment_columns

NOISE_SCALE = 2.0
MASK_KEY = 0x5C0D


@torch.no_grad()
def stream_logits(model: StreamCNODE, tel: np.ndarray, flights_per_chunk: int = 64) -> np.ndarray:
    """(n, T, K) float32: the logits of a stream started at z = 0 on every flight of ``tel`` (n, T, C)."""
    model.eval()
    out = [model(torch.from_numpy(np.ascontiguousarray(tel[i:i + flights_per_chunk], dtype=np.float32)))[0].numpy()
           for i in range(0, len(tel), flights_per_chunk)]
    return np.concatenate(out) if out else np.zeros((0, tel.shape[1], model.n_classes), np.float32)


def val_macro_f1(model: StreamCNODE, ds: Dataset, rows: np.ndarray, ends: np.ndarray) -> float:
    """Macro F1 of the stream's argmax at the window ends ``ends`` of the flights ``rows``."""
    logits = stream_logits(model, ds["telemetry"][rows])[:, ends]
    y = step_labels(ds, rows)[:, ends]
    return float(f1_score(y.ravel(), logits.argmax(-1).ravel(), labels=list(range(model.n_classes)),
                          average="macro", zero_division=0))


def _batch_loss(model: StreamCNODE, opt, x: torch.Tensor, y: torch.Tensor, mask: torch.Tensor, z: torch.Tensor,
                w: torch.Tensor, cfg: StreamCnodeConfig, m, ema, aux, ym) -> float:
    """One segment batch in chunks of ``tbptt`` steps, an optimiser step per chunk; the summed loss."""
    total, x_prev = 0.0, None
    params = [p for g in opt.param_groups for p in g["params"]]
    for c0 in range(0, x.shape[1], cfg.tbptt):
        sl = slice(c0, c0 + cfg.tbptt)
        zs, z = model.features(x[:, sl], z, x_prev)
        x_prev, z = x[:, sl][:, -1], z.detach()
        total += chunk_update(model, zs, sl, y, mask, w, cfg, opt, params, m, ema, aux, ym, "streaming CNODE")
    return total


def _masker(profile: str, ds: Dataset):
    from quadfdi.core.profiles import is_masked
    from quadfdi.train.masks import Masker

    return Masker(profile, ds.channel_names) if is_masked(profile) else None


def _normalisation(ds: Dataset, profile: str) -> tuple[np.ndarray, np.ndarray]:
    from quadfdi.core.profiles import is_masked
    from quadfdi.train.masks import fixed_availability

    mean, std = fit_normalisation(ds)
    return fixed_availability(profile, mean, std) if is_masked(profile) else (mean, std)


def fit_stream_cnode(ds: Dataset, val_ds: Dataset, cfg: StreamCnodeConfig, profile: str = "paper",
                     log: Callable[[str], None] = print) -> tuple[StreamCNODE, StreamHistory]:
    """Train on the training flights of ``ds`` (the profile's inputs, every channel), select on the
    validation flights of ``val_ds`` (the same flights, each under its own mask pattern for a masked
    profile; ``ds`` itself otherwise); keep the best-validation epoch."""
    from quadfdi.train.masks import draw_patterns

    cfg.validate()
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(0x5690,)))
    mask_rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(MASK_KEY,)))
    split = np.asarray(ds["split"])
    train_rows, val_rows = np.flatnonzero(split == SPLIT_TRAIN), np.flatnonzero(split == SPLIT_VALIDATION)
    if len(train_rows) == 0 or len(val_rows) == 0:
        raise ValueError("the streaming CNODE needs training and validation flights")
    n_classes = len(class_names(ds.arrays))
    model = StreamCNODE(ds.n_channels, cfg.latent, cfg.hidden, n_classes, cfg.dt, cfg.leak)
    model.set_normalisation(*_normalisation(ds, profile))
    model.head_dropout = cfg.head_dropout
    masker = _masker(profile, ds)
    tel = ds["telemetry"][train_rows]  # (n, T, C) float32, raw: the model normalises inside
    lab = step_labels(ds, train_rows)
    sw = step_weights(lab, cfg.onset_weight, cfg.onset_span)
    w = torch.as_tensor(stream_class_weights(lab, sw, cfg, n_classes))
    onset, ends, n_t = first_fault(lab), window_end_index(ds), tel.shape[1]
    seg = min(cfg.segment, n_t)
    names = class_names(ds.arrays)
    aux = None  # the training-only motor head on z (train/stream_gru_motor.py), when there is a rotor-side class
    if cfg.motor_aux > 0 and rotor_side(names).any():
        aux = MotorAux(cfg.latent, cfg.motor_aux, step_motor_targets(lab, train_rows, ds["fault_motor"], names))
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
            x = np.ascontiguousarray(tel[idx[:, None], cols])
            if masker is not None:
                x = masker.apply(x, draw_patterns(mask_rng, len(idx)))
            mask = torch.from_numpy(loss_mask(start, mid, seg, cfg.warmup, n_t))
            noisy = mid & (rng.random(len(idx)) < cfg.noise_start)
            z0 = np.where(noisy[:, None], NOISE_SCALE * np.tanh(rng.standard_normal((len(idx), cfg.latent))), 0.0)
            m = None if sw is None else torch.from_numpy(sw[idx[:, None], cols])
            ym = None if aux is None else torch.from_numpy(aux.targets[idx[:, None], cols])
            total += _batch_loss(model, opt, torch.from_numpy(x), torch.from_numpy(lab[idx[:, None], cols]), mask,
                                 torch.as_tensor(z0, dtype=torch.float32), w, cfg, m, ema, aux, ym)
            for _ in range(-(-seg // cfg.tbptt)):
                sched.step()
            count += int(mask.sum())
        hist.epoch_s.append(time.perf_counter() - t0)
        hist.loss.append(total / max(count, 1))
        if ema is None:
            f1, state = val_macro_f1(model, val_ds, val_rows, ends), copy.deepcopy(model.state_dict())
        else:
            with ema.swapped():
                f1, state = val_macro_f1(model, val_ds, val_rows, ends), copy.deepcopy(ema.shadow)
        hist.val_macro_f1.append(f1)
        if f1 > best_f1:
            best_f1, best_state, hist.best_epoch = f1, state, epoch
        log(f"  epoch {epoch + 1:2d}/{cfg.epochs}: loss {hist.loss[-1]:.4f}, val macro F1 {f1:.4f}, "
            f"{hist.epoch_s[-1]:.1f} s")
    model.load_state_dict(best_state)
    model.eval()
    return model, hist
