"""The two classifiers of the paper: a controlled Neural ODE (Eq. 10) and a GRU (Eq. 11).

Both take RAW telemetry windows (batch, W, C) float32, check them (``check_windows``), normalise
them inside with the training split's per-channel mean and std (buffers ``mean``, ``std``, so
the exported graph carries its normalisation), and return logits (batch, n_classes).

Parameter names are a contract: export/ and firmware_ref/ read ``encoder``, ``field.lin1``,
``field.lin2``, ``head`` (CNODE) and ``gru``, ``head`` (GRU) from the state dict.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import torch
from torch import nn

from quadfdi.models.control import LinearPath, interp_matrix, knots
from quadfdi.models.regularise import drop_channels, drop_latent
from quadfdi.models.solvers import FIXED_METHODS, SolverSpec, fixed_method, integrate_fixed, nearest_index, stage_times
from quadfdi.models.window_check import check_windows

__all__ = ["MODEL_KINDS", "STD_FLOOR", "CNODE", "GRUClassifier", "SolverSpec", "VectorField", "build_model",
           "check_windows", "model_from_signature", "model_signature"]

MODEL_KINDS = ("cnode", "gru")

# A channel that is constant over the training split (std 0, e.g. a sensor that never moved in a
# short run) would divide by zero and turn every window into Inf/NaN. The simulator puts noise on
# every channel (Eq. 9), so real stds are orders of magnitude above 1e-6 and the floor only ever
# acts on such a degenerate channel. It is applied when the buffer is set, so ONNX Runtime and the
# C++ reference divide by the very same stored number.
STD_FLOOR = 1e-6


class _Normalised(nn.Module):
    """Per-channel normalisation buffers shared by both models: x_norm = (x - mean) / std."""

    def __init__(self, n_channels: int, window: int) -> None:
        super().__init__()
        if n_channels < 1 or window < 2:
            raise ValueError(f"need n_channels >= 1 and window >= 2, found {n_channels} and {window}")
        self.n_channels = int(n_channels)
        self.window = int(window)
        self.register_buffer("mean", torch.zeros(n_channels))  # (C,), training split only
        self.register_buffer("std", torch.ones(n_channels))  # (C,), floored at STD_FLOOR
        self.motor_head: nn.Linear | None = None  # models.motor.attach_motor_head: (B, width) -> (B, 4)
        self.dropout_in = self.dropout_latent = 0.0  # training-only rates (models.regularise); not state

    def set_normalisation(self, mean: Any, std: Any) -> None:
        """Store the training split's per-channel mean and std, (C,) each; std floored at STD_FLOOR."""
        m = torch.as_tensor(np.asarray(mean, dtype=np.float64))
        s = torch.as_tensor(np.asarray(std, dtype=np.float64))
        for name, v in (("mean", m), ("std", s)):
            if tuple(v.shape) != (self.n_channels,):
                raise ValueError(f"normalisation {name} must be ({self.n_channels},), found {tuple(v.shape)}")
            if not bool(torch.isfinite(v).all()):
                raise ValueError(f"normalisation {name} holds NaN or Inf")
        if bool((s < 0).any()):
            raise ValueError("normalisation std must be non-negative")
        with torch.no_grad():
            self.mean.copy_(m)
            self.std.copy_(s.clamp_min(STD_FLOOR))

    def normalise(self, x_raw: torch.Tensor) -> torch.Tensor:
        """(batch, W, C) raw -> (batch, W, C) normalised, after checking the windows."""
        check_windows(x_raw, self.n_channels, self.window)
        x = x_raw.to(self.mean.dtype)
        return (x - self.mean) / self.std


class VectorField(nn.Module):
    """f(z, u) = lin2(tanh(lin1([z, u]))): the latent dynamics f_theta of Eq. (10).

    z (batch, latent), u (batch, C) -> dz/dt (batch, latent). Concatenation order: z, then u.
    """

    def __init__(self, latent: int, n_channels: int, hidden: int) -> None:
        super().__init__()
        self.lin1 = nn.Linear(latent + n_channels, hidden)
        self.lin2 = nn.Linear(hidden, latent)

    def forward(self, z: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        return self.lin2(torch.tanh(self.lin1(torch.cat([z, u], dim=-1))))


class CNODE(_Normalised):
    """Controlled Neural ODE classifier (paper Eq. 10), neural-CDE style initial state.

    x_norm = (x_raw - mean) / std                      (batch, W, C)
    z0     = tanh(encoder(x_norm[:, 0]))               (batch, latent)  first normalised sample
    dz/dt  = field(z, u(t)),  t in [0, 1]               u: the linearly interpolated x_norm
    logits = head(z1)                                  (batch, n_classes)

    The solver is the attribute ``solver`` (a SolverSpec, replace it to change solver):
    fixed methods (euler, midpoint, rk4) run ``integrate_fixed`` with u read from
    U = interp_matrix(stage_times) @ x_norm, computed once per forward; adaptive methods
    (dopri5, bosh3) run torchdiffeq.odeint over a LinearPath, with ``options={"jump_t": knots}``
    when ``solver.jump_t`` (torchdiffeq 0.2.5's option; ``grid_points`` is gone).
    ``nfe`` counts vector-field evaluations of the last forward/trace.
    ``control`` names the control representation ("point": u at the stage times); variants with
    another one (``models.variants``) override it, and ``model_signature`` records it.
    """

    control = "point"

    def __init__(
        self,
        n_channels: int,
        window: int = 80,
        latent: int = 40,
        hidden: int = 64,
        n_classes: int = 4,
        solver: SolverSpec | None = None,
    ) -> None:
        super().__init__(n_channels, window)
        self.latent = int(latent)
        self.hidden = int(hidden)
        self.n_classes = int(n_classes)
        self.encoder = nn.Linear(n_channels, latent)
        self.field = VectorField(latent, n_channels, hidden)
        self.head = nn.Linear(latent, n_classes)
        self.solver = solver if solver is not None else SolverSpec()
        self.nfe = 0
        self._interp_cache: dict[tuple, tuple[np.ndarray, torch.Tensor]] = {}  # not state: rebuilt on demand

    # -- pieces -----------------------------------------------------------------------------
    def _f(self, z: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        self.nfe += 1
        return self.field(z, u)

    def _control_table(self, x_norm: torch.Tensor) -> tuple[np.ndarray, torch.Tensor]:
        """Stage times (T,) and the control there, U = M @ x_norm, (batch, T, C)."""
        key = (self.solver.method, self.solver.steps, x_norm.dtype, x_norm.device)
        if key not in self._interp_cache:
            times = stage_times(self.solver.method, self.solver.steps)
            m = torch.as_tensor(interp_matrix(times, self.window), dtype=x_norm.dtype, device=x_norm.device)
            self._interp_cache[key] = (times, m)  # (T,), (T, W)
        times, m = self._interp_cache[key]
        return times, torch.matmul(m, x_norm)  # (T, W) @ (B, W, C) -> (B, T, C)

    def _integrate_fixed(self, z0: torch.Tensor, x_norm: torch.Tensor, trace: list | None = None) -> torch.Tensor:
        times, u = self._control_table(x_norm)

        def f(t: float, z: torch.Tensor) -> torch.Tensor:
            return self._f(z, u[:, nearest_index(times, t)])

        return integrate_fixed(f, z0, self.solver.method, self.solver.steps, trace=trace)

    def _integrate_adaptive(self, z0: torch.Tensor, x_norm: torch.Tensor) -> torch.Tensor:
        # imported here: torchdiffeq loads scipy.integrate (0.3 s of a process's start), which the fixed-step
        # path every training, export and benchmark process of the RK4 models takes never needs
        from torchdiffeq import odeint

        path = LinearPath(x_norm)
        options = {}
        if self.solver.jump_t:
            options["jump_t"] = torch.as_tensor(knots(self.window), dtype=torch.float64)
        t = torch.tensor([0.0, 1.0], dtype=torch.float64, device=z0.device)
        zs = odeint(
            lambda tt, z: self._f(z, path(tt)),
            z0,
            t,
            rtol=self.solver.rtol,
            atol=self.solver.atol,
            method=self.solver.method,
            options=options,
        )
        return zs[-1]

    # -- public -----------------------------------------------------------------------------
    def forward(self, x_raw: torch.Tensor) -> torch.Tensor:
        """x_raw (batch, W, C) raw telemetry -> logits (batch, n_classes)."""
        return self.head(self.features(x_raw))

    def features(self, x_raw: torch.Tensor) -> torch.Tensor:
        """x_raw (batch, W, C) -> z1 (batch, latent), what the class and motor heads read."""
        self.nfe = 0
        x_norm = drop_channels(self.normalise(x_raw), self.dropout_in, self.training)
        z0 = torch.tanh(self.encoder(x_norm[:, 0]))
        z1 = self._integrate_fixed(z0, x_norm) if self.solver.is_fixed else self._integrate_adaptive(z0, x_norm)
        return drop_latent(z1, self.dropout_latent, self.training)

    @torch.no_grad()
    def trace(self, x_raw: torch.Tensor) -> dict[str, Any]:
        """Every intermediate of a fixed-step forward, for reference files and parity checks.

        Returns a dict of tensors (batch first unless said):
            x_norm (B, W, C); times (T,) float64 numpy, the stage times; u (B, T, C), the
            control at those times; z0 (B, L); stages (N, S, B, L), stages[k, i] the state at
            which stage i of step k evaluates the field (stages[k, 0] is the step's start state),
            at time stage_time[k, i]; stage_time (N, S) float64 numpy; z1 (B, L); logits (B, K).
        """
        if not self.solver.is_fixed:
            raise ValueError(f"trace needs a fixed-step solver ({', '.join(FIXED_METHODS)}); found {self.solver.method!r}")
        self.nfe = 0
        x_norm = self.normalise(x_raw)
        z0 = torch.tanh(self.encoder(x_norm[:, 0]))
        record: list[torch.Tensor] = []
        z1 = self._integrate_fixed(z0, x_norm, trace=record)
        spec = fixed_method(self.solver.method)
        n, s = self.solver.steps, spec.evals_per_step
        times, u = self._control_table(x_norm)
        offsets = np.asarray(spec.stage_offsets, dtype=np.float64)
        return {
            "x_norm": x_norm,
            "times": times,
            "u": u,
            "z0": z0,
            "stages": torch.stack(record[1:-1]).reshape(n, s, *z0.shape),
            "stage_time": (np.arange(n, dtype=np.float64)[:, None] + offsets[None, :]) / n,
            "z1": z1,
            "logits": self.head(z1),
        }

    def macs_breakdown(self, evals: int | None = None) -> dict[str, int]:
        """Multiply-accumulates per window, by part (weight-matrix products only).

        encoder C*L (one sample), field (L+C)*H + H*L per evaluation, head L*K. ``evals`` defaults
        to the fixed solver's N * evals_per_step; for an adaptive solver pass a measured NFE.
        Also reported, not in ``total``: ``control_matmul`` = T*W*C, the dense U = M @ X product
        of the deployed graph (only 2 of each row's W weights are non-zero). Not counted: biases,
        tanh, normalisation and the RK combinations (O(N*L) additions).
        """
        if evals is None:
            if not self.solver.is_fixed:
                raise ValueError(f"MACs of the adaptive solver {self.solver.method!r} depend on its NFE; pass evals=")
            evals = self.solver.steps * fixed_method(self.solver.method).evals_per_step
        c, l, h, k = self.n_channels, self.latent, self.hidden, self.n_classes
        parts = {
            "encoder": c * l,
            "field_per_eval": (l + c) * h + h * l,
            "evals": int(evals),
            "head": l * k,
        }
        parts["field"] = parts["evals"] * parts["field_per_eval"]
        parts["total"] = parts["encoder"] + parts["field"] + parts["head"]
        if self.solver.is_fixed:
            parts["control_matmul"] = len(stage_times(self.solver.method, self.solver.steps)) * self.window * c
        return parts

    def macs_per_window(self, evals: int | None = None) -> int:
        """encoder + evals * field + head MACs (see ``macs_breakdown`` for what is counted)."""
        return self.macs_breakdown(evals)["total"]


class GRUClassifier(_Normalised):
    """GRU baseline (paper Eq. 11): logits = head(h_W), the last hidden state.

    x_norm (batch, W, C) -> nn.GRU (batch_first) -> h_W (batch, H) -> head -> (batch, n_classes).

    PyTorch's GRU, which we use, differs from Eq. 11 as written in two conventions:
    - reset gate: n_t = tanh(W_in x_t + b_in + r_t * (W_hn h_{t-1} + b_hn)), i.e. r_t multiplies
      the recurrent product *after* the matmul (ONNX GRU ``linear_before_reset=1``); Eq. 11 writes
      W_h [r_t * h_{t-1}; x_t], the reset *before* it. The two are different functions, so the
      exported ONNX GRU node must set linear_before_reset=1 and the C++ reference must follow.
    - update gate: h_t = (1 - z_t) * n_t + z_t * h_{t-1}; Eq. 11's z_t is PyTorch's 1 - z_t
      (an equivalent re-parametrisation: negate the gate's weights and bias).
    """

    def __init__(self, n_channels: int, hidden: int = 80, n_classes: int = 4, window: int = 80) -> None:
        super().__init__(n_channels, window)
        self.hidden = int(hidden)
        self.n_classes = int(n_classes)
        self.gru = nn.GRU(n_channels, hidden, batch_first=True)
        self.head = nn.Linear(hidden, n_classes)

    def forward(self, x_raw: torch.Tensor) -> torch.Tensor:
        """x_raw (batch, W, C) raw telemetry -> logits (batch, n_classes)."""
        return self.head(self.features(x_raw))

    def features(self, x_raw: torch.Tensor) -> torch.Tensor:
        """x_raw (batch, W, C) -> h_W (batch, H), what the class and motor heads read."""
        _, h_last = self.gru(drop_channels(self.normalise(x_raw), self.dropout_in, self.training))  # (1, batch, H)
        return drop_latent(h_last[0], self.dropout_latent, self.training)

    @torch.no_grad()
    def trace(self, x_raw: torch.Tensor) -> dict[str, torch.Tensor]:
        """x_norm (B, W, C), h (B, W, H) every hidden state, logits (B, K)."""
        x_norm = self.normalise(x_raw)
        h, _ = self.gru(x_norm)
        return {"x_norm": x_norm, "h": h, "logits": self.head(h[:, -1])}

    def macs_per_window(self) -> int:
        """W * 3H(C + H) (the three gates' input and recurrent products) + H*K (head).

        Weight-matrix products only: biases, sigmoid/tanh and the gate products are not counted.
        """
        c, h = self.n_channels, self.hidden
        return self.window * 3 * h * (c + h) + h * self.n_classes


def build_model(kind: str, n_channels: int, cfg: Any, window: int = 80, n_classes: int = 4) -> nn.Module:
    """A fresh model of ``kind`` ("cnode" or "gru") sized by ``cfg``, the [train] section (its solver, steps,
    rtol, atol, jump_t, latent, hidden, gru_hidden; dropout_in, dropout_latent when it has them); ``window`` is
    sim.window, ``n_classes`` the data's class count (K outputs)."""
    if kind == "cnode":
        solver = SolverSpec(cfg.solver, cfg.steps, cfg.rtol, cfg.atol, cfg.jump_t)
        model = CNODE(n_channels, window=window, latent=cfg.latent, hidden=cfg.hidden, solver=solver, n_classes=n_classes)
    elif kind == "gru":
        model = GRUClassifier(n_channels, hidden=cfg.gru_hidden, window=window, n_classes=n_classes)
    else:
        raise ValueError(f"unknown model kind {kind!r}; valid: {', '.join(MODEL_KINDS)}")
    model.dropout_in, model.dropout_latent = getattr(cfg, "dropout_in", 0.0), getattr(cfg, "dropout_latent", 0.0)
    return model


def model_signature(model: nn.Module) -> dict[str, int | str]:
    """The architecture hyper-parameters (plain ints and strings) that rebuild ``model``.

    The solver is not part of it: a CNODE's weights are valid under any solver. Its control
    representation is (``control``: "point", or "average" for ``models.variants.AverageControlCNODE``):
    the same weights driven by another control are another model. ``n_motors`` (4): a motor head.
    """
    if isinstance(model, (CNODE, GRUClassifier)):
        kind = "cnode" if isinstance(model, CNODE) else "gru"
        sig = {"kind": kind, "n_channels": model.n_channels, "window": model.window}
        sizes = {"latent": model.latent, "hidden": model.hidden} if kind == "cnode" else {"hidden": model.hidden}
        extra = {"control": model.control} if kind == "cnode" else {}
        motor = {"n_motors": int(model.motor_head.out_features)} if model.motor_head is not None else {}
        return {**sig, **sizes, "n_classes": model.n_classes, **extra, **motor}
    raise TypeError(f"not a quadfdi model: {type(model).__name__}")


def model_from_signature(sig: dict[str, Any], solver: SolverSpec | None = None,
                         cnode_classes: Mapping[str, type] | None = None) -> nn.Module:
    """The (untrained) model that ``model_signature`` describes; ValueError on a bad signature.

    ``cnode_classes`` maps a CNODE's ``control`` to its class (``models.variants.CNODE_CLASSES``,
    which ``models.checkpoint`` passes); by default only the point control is known here. A
    signature without ``control`` (checkpoints written before it was recorded) is a point CNODE.
    """
    sig = dict(sig)
    kind = sig.pop("kind", None)
    keys = {"cnode": {"n_channels", "window", "latent", "hidden", "n_classes"},
            "gru": {"n_channels", "window", "hidden", "n_classes"}}
    if kind not in keys:
        raise ValueError(f"model signature kind must be one of {', '.join(MODEL_KINDS)}, found {kind!r}")
    control = sig.pop("control", "point") if kind == "cnode" else None
    n_motors = sig.pop("n_motors", None)  # the motor head (models.motor), absent without one
    if n_motors is not None and n_motors != 4:
        raise ValueError(f"{kind} signature n_motors must be 4, found {n_motors!r}")
    if set(sig) != keys[kind] or not all(isinstance(v, int) and not isinstance(v, bool) for v in sig.values()):
        raise ValueError(f"{kind} signature must hold integer {', '.join(sorted(keys[kind]))}; found {sig}")
    classes = {"point": CNODE, **(cnode_classes or {})}
    if kind == "cnode":
        if control not in classes:
            raise ValueError(f"cnode signature control must be one of {', '.join(classes)}, found {control!r}")
    model = classes[control](solver=solver, **sig) if kind == "cnode" else GRUClassifier(**sig)
    if n_motors is not None:
        model.motor_head = nn.Linear(model.head.in_features, n_motors)
    return model
