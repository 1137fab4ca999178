"""The streaming GRU's training settings (train/stream_gru_fit.py), torch-free so that building the
command-line parser (``quadfdi train sgru`` takes one flag per field) imports nothing heavy. Not a
[section] of core/config.py (at its line cap): the settings are flags, recorded in the checkpoint and
in predictions/sgru_sim<S>_train<T>.json."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StreamFitConfig:
    hidden: int = 60  # 3H(C+H)+HK = 15 600 MACs per sample at C = 25, K = 5: under 1/6 of the windowed GRU per second
    epochs: int = 120  # with 250-sample segments: the optimiser steps of 30 epochs of 1,000 (docs/training.md)
    batch: int = 32  # flights per batch
    segment: int = 250  # samples per training segment (10 s at 25 Hz; 1,000 until wt-sgrub: validation chose 250)
    tbptt: int = 125  # samples per truncated-backpropagation chunk (5 s)
    warmup: int = 50  # loss-free steps at the start of a mid-flight segment (2 s)
    zero_start: float = 0.5  # share of segments that start at take-off
    noise_start: float = 0.5  # share of mid-flight segments that start at a random state
    lr: float = 3e-3
    clip: float = 1.0
    weight_decay: float = 0.0  # AdamW's decoupled weight decay (0: Adam)
    head_dropout: float = 0.0  # dropout on h before the head, training only
    log_eps: float = 1e-8
    onset_weight: float = 1.0  # loss weight of the first onset_span steps of a fault run (1: off; train/stream_gru_onset.py)
    onset_span: int = 250  # steps (10 s at 25 Hz) after the label turns to a fault that get onset_weight
    ema_decay: float = 0.0  # weight moving average per optimiser step, validated and kept (0: off; train/stream_gru_ema.py)
    class_mix: str = "steps"  # class weights over every training step, or "sampled": the sampler's steps (train/stream_gru_segments.py)
    onset_segments: float = 0.0  # share of fault flights' mid-flight segments placed around the onset (0: off)
    start_span: str = "fit"  # mid-flight segment starts: where a whole segment fits, or "any" sample (cut at the end)
    motor_aux: float = 0.5  # weight of a training-only motor head's loss (0: off; train/stream_gru_motor.py); 0.5 chosen on validation (docs/training.md)
    seed: int = 0
    threads: int = 1

    def validate(self) -> None:
        if min(self.hidden, self.epochs, self.batch, self.segment, self.tbptt) < 1 or self.warmup < 0:
            raise ValueError(f"stream GRU settings must be positive: {self}")
        if not (0 <= self.zero_start <= 1 and 0 <= self.noise_start <= 1 and 0 <= self.head_dropout < 1):
            raise ValueError("zero_start, noise_start and head_dropout are probabilities (head_dropout < 1)")
        if self.onset_weight <= 0 or self.onset_span < 1:
            raise ValueError(f"onset_weight must be positive and onset_span at least 1, found {self.onset_weight}, "
                             f"{self.onset_span}")
        if not 0 <= self.ema_decay < 1:
            raise ValueError(f"ema_decay must lie in [0, 1), found {self.ema_decay}")
        if self.class_mix not in ("steps", "sampled"):
            raise ValueError(f"class_mix must be 'steps' or 'sampled', found {self.class_mix!r}")
        if self.class_mix == "sampled" and self.onset_weight != 1.0:
            raise ValueError("class_mix 'sampled' and onset_weight != 1 each set the class weights: choose one")
        if not 0 <= self.onset_segments <= 1:
            raise ValueError(f"onset_segments is a probability, found {self.onset_segments}")
        if self.start_span not in ("fit", "any"):
            raise ValueError(f"start_span must be 'fit' or 'any', found {self.start_span!r}")
        if self.motor_aux < 0:
            raise ValueError(f"motor_aux must not be negative, found {self.motor_aux}")
        if self.weight_decay < 0:
            raise ValueError(f"weight_decay must not be negative, found {self.weight_decay}")
