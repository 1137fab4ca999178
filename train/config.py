"""The training stage's sections.

- [train]: the windowed CNODE and GRU (paper Table 2 and Sections II-D to II-F; docs/training.md).
- [sgru]: the streaming GRU of ``quadfdi train sgru`` (train/stream_gru_fit.py says what each setting does;
  docs/training.md "Streaming GRU").
- [scnode]: the streaming CNODE of ``quadfdi train scnode`` (train/stream_cnode_fit.py): the [sgru] keys
  (segments, truncated backpropagation, start states, ...) with its own widths and defaults. The command's flags (``--hidden 40``) override the run's [sgru]
  as ``--set sgru.hidden=40`` does; the settings used are recorded in the checkpoint and in
  predictions/sgru_sim<S>_train<T>.json.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.limits import (FIRMWARE_MAX_STEPS, MAX_BATCH, MAX_CNODE_HIDDEN, MAX_EPOCHS, MAX_GRU_HIDDEN,
                                 MAX_LATENT, MAX_THREADS)
from quadfdi.core.profiles import check_profile
from quadfdi.core.sections import at_most, choice, not_negative, positive


@dataclass(frozen=True)
class TrainConfig:
    """Model and training settings (paper Table 2 and Sections II-D to II-F)."""

    seed: int = 0
    model: str = "both"  # cnode | gru | both
    epochs: int = 14
    batch_size: int = 96
    lr: float = 2e-2  # Adam, initial learning rate of the CNODE (a sweep: docs/training.md)
    gru_lr: float = 3e-3  # Adam, initial learning rate of the GRU (at 1e-2 it lost 1 point of F1)
    lr_schedule: str = "cosine"  # constant | cosine (decays to 0 over the epochs, per batch)
    latent: int = 40  # CNODE latent dimension
    hidden: int = 64  # CNODE vector-field hidden width
    gru_hidden: int = 80
    solver: str = "rk4"  # training solver of the CNODE: dopri5 | bosh3 | rk4 | euler | midpoint
    steps: int = 8  # fixed-step solvers: N steps over [0, 1]
    rtol: float = 1e-3  # adaptive solvers
    atol: float = 1e-4
    jump_t: bool = True  # adaptive solvers: tell torchdiffeq where the path's knots are
    log_eps: float = 1e-8  # the epsilon of Eq. (12)
    # One intra-op thread: tiny matrices (batch 96 x 64); oversubscribed OpenMP made the GRU ~50x slower.
    threads: int = 1
    seeds: tuple[int, ...] = (0, 1, 2)  # the multi-seed study
    max_train_windows: int = 0  # cap: a seeded subsample of the training windows (train.data); 0 = all
    profile: str = "paper"  # the models' input channels (core.profiles, docs/profiles.md): paper | flightlog-min | flightlog-nocur | flightlog-esc
    # The motor head (models.motor, docs/training.md): "auto" = on when the data has a rotor-side class, "off" never.
    motor_head: str = "off"
    motor_loss_weight: float = 0.5  # weight of the motor cross-entropy added to the class loss
    # Training-only motor-share wander (train.augment, docs/training.md "Motor-share wander"): the largest per-window
    # amplitude of the multiplicative noise on m1_rel..m4_rel (0 = off) and its correlation time.
    share_wander: float = 0.0
    share_wander_tau_s: float = 0.3
    # `quadfdi train baselines` also fits logreg_physics_ref and gbt_ref: physics features relative to each vehicle's
    # reference (train/features_ref.py; datasets whose vehicles have reference flights, others skip them).
    baselines_reference: bool = False
    # Regularisation (docs/training.md "Recipe search"); the defaults change nothing.
    weight_decay: float = 0.0  # the CNODE's AdamW decoupled weight decay on every parameter (0: plain Adam)
    gru_weight_decay: float = 0.0  # the GRU's (each network's recipe is searched on its own, as lr and gru_lr)
    dropout_in: float = 0.0  # training only: each normalised input channel of a window zeroed with this probability
    dropout_latent: float = 0.0  # training only: dropout on the CNODE's z1 / the GRU's h_W before the heads
    # Early stopping: end training once validation macro F1 has not risen for this many epochs (0: every epoch);
    # the learning-rate schedule still spans `epochs`, and the best epoch's weights are kept either way.
    patience: int = 0
    # A moving average of the weights per optimiser step (0: off; train/stream_gru_ema.py, as [sgru] ema_decay):
    # validation, the epoch kept and every output use the averaged weights.
    ema_decay: float = 0.0
    # "all": every output; "fit": the checkpoints, history and test metrics only, no prediction sets or
    # mask-pattern scores (a recipe search's points, `quadfdi sweep --stages train`: later stages need "all").
    outputs: str = "all"

    def validate(self) -> None:
        positive(self, "epochs", "batch_size", "lr", "latent", "hidden", "gru_hidden", "steps", "rtol", "atol", "threads", "gru_lr")
        not_negative(self, "seed", "max_train_windows", "patience")
        choice(self, "outputs", ("all", "fit"))
        if min(self.seeds, default=0) < 0:
            raise QuadfdiError(f"train.seeds must not be negative, found {list(self.seeds)}")
        at_most(self, MAX_THREADS, "threads")
        at_most(self, MAX_LATENT, "latent")
        at_most(self, MAX_CNODE_HIDDEN, "hidden")
        at_most(self, MAX_GRU_HIDDEN, "gru_hidden")
        at_most(self, FIRMWARE_MAX_STEPS, "steps")
        at_most(self, MAX_BATCH, "batch_size")
        at_most(self, MAX_EPOCHS, "epochs")
        choice(self, "model", ("cnode", "gru", "both"))
        choice(self, "lr_schedule", ("constant", "cosine"))
        choice(self, "solver", ("dopri5", "bosh3", "rk4", "euler", "midpoint"))
        check_profile(self.profile)
        choice(self, "motor_head", ("auto", "off"))
        not_negative(self, "motor_loss_weight", "share_wander")
        positive(self, "share_wander_tau_s")
        not_negative(self, "weight_decay", "gru_weight_decay")
        for name in ("dropout_in", "dropout_latent", "ema_decay"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise QuadfdiError(f"train.{name} must lie in [0, 1), found {getattr(self, name)}")


@dataclass(frozen=True)
class StreamFitConfig:
    """The [sgru] section: how the streaming GRU is trained (train/stream_gru_fit.py)."""

    SECTION: ClassVar[str] = "sgru"  # the section's name in this class's messages

    hidden: int = 60  # 3H(C+H)+HK = 15 600 MACs per sample at C = 25, K = 5: under 1/6 of the windowed GRU per second
    epochs: int = 120  # with 250-sample segments: the optimiser steps of 30 epochs of 1,000 (docs/training.md)
    batch: int = 32  # flights per batch
    segment: int = 250  # samples per training segment (10 s at 25 Hz; chosen over 1,000 on validation, docs/training.md)
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
        positive(self, "hidden", "epochs", "batch", "segment", "tbptt", "lr", "clip", "log_eps", "threads", "onset_weight",
                 "onset_span")
        not_negative(self, "warmup", "weight_decay", "motor_aux", "seed")
        at_most(self, MAX_THREADS, "threads")
        at_most(self, MAX_GRU_HIDDEN, "hidden")
        at_most(self, MAX_BATCH, "batch")
        at_most(self, MAX_EPOCHS, "epochs")
        for name in ("zero_start", "noise_start", "onset_segments"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise QuadfdiError(f"{self.SECTION}.{name} is a probability in [0, 1], found {getattr(self, name)}")
        for name in ("head_dropout", "ema_decay"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise QuadfdiError(f"{self.SECTION}.{name} must lie in [0, 1), found {getattr(self, name)}")
        choice(self, "class_mix", ("steps", "sampled"))
        choice(self, "start_span", ("fit", "any"))
        if self.class_mix == "sampled" and self.onset_weight != 1.0:
            raise QuadfdiError(f"{self.SECTION}.class_mix = 'sampled' and {self.SECTION}.onset_weight != 1 each set "
                               "the class weights: choose one")


@dataclass(frozen=True)
class StreamCnodeConfig(StreamFitConfig):
    """The [scnode] section: how the streaming CNODE is trained (train/stream_cnode_fit.py); every [sgru]
    key means the same here, ``hidden`` is the vector field's width and ``latent`` the state's."""

    SECTION: ClassVar[str] = "scnode"
    latent: int = 24  # L: 4 x 2LH + HC + LK = 10,536 MACs per sample at H = 48, C = 25, K = 5 (models/stream_cnode.py)
    hidden: int = 48  # H: the field's hidden width; L and H sized for 1 % of the M4's 40 ms period (docs/training.md)
    dt: float = 0.0625  # integration time per sample (models.stream_cnode.DT)
    leak: bool = True  # a learned decay per latent dimension in the field (models/stream_cnode.py): z bounded for int8
    epochs: int = 120  # as [sgru]; above 40 on validation (docs/training.md)

    def validate(self) -> None:
        super().validate()
        positive(self, "latent", "dt")
        at_most(self, MAX_LATENT, "latent")
        at_most(self, MAX_CNODE_HIDDEN, "hidden")
        if self.dt > 1.0:
            raise QuadfdiError(f"scnode.dt must lie in (0, 1], found {self.dt}")
