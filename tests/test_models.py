"""The CNODE and GRU classifiers, against independent references.

- CNODE: our fixed-step solvers against torchdiffeq ('euler', 'midpoint' on the same linear path)
  and against a tight-tolerance dopri5 reference; evaluation counts; the trace.
- GRU: the last-state logits against a hand-written recurrence with the reset gate applied after
  the recurrent matmul (ONNX linear_before_reset=1), which catches a wrong reset convention.
- Both: shapes, normalisation inside, boundary validation, MACs, signatures and checkpoints.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
import torch
from torchdiffeq import odeint

from quadfdi.train.config import TrainConfig
from quadfdi.models.control import LinearPath, interp_matrix
from quadfdi.models.networks import (
    CNODE,
    MODEL_KINDS,
    STD_FLOOR,
    GRUClassifier,
    SolverSpec,
    build_model,
    check_windows,
    model_from_signature,
    model_signature,
)
from quadfdi.models.solvers import stage_times

C = 23  # channels of the telemetry contract
W = 80


def _raw(batch: int = 4, channels: int = C, seed: int = 0, dtype=torch.float32) -> torch.Tensor:
    """Random raw telemetry with per-channel offsets and scales far from (0, 1)."""
    g = torch.Generator().manual_seed(seed)
    scale = torch.rand(channels, generator=g, dtype=torch.float64) * 10 + 0.1
    offset = torch.randn(channels, generator=g, dtype=torch.float64) * 50
    return (torch.randn(batch, W, channels, generator=g, dtype=torch.float64) * scale + offset).to(dtype)


def _smooth(batch: int, channels: int, seed: int = 1) -> torch.Tensor:
    """Smooth windows (sinusoids), float64: here the fixed-step solvers converge cleanly."""
    g = torch.Generator().manual_seed(seed)
    t = torch.linspace(0, 1, W, dtype=torch.float64)[None, :, None]
    freq = torch.rand(batch, 1, channels, generator=g, dtype=torch.float64) * 6 + 1
    phase = torch.rand(batch, 1, channels, generator=g, dtype=torch.float64) * 6
    return 2 * torch.sin(freq * t + phase)


def _normalised(model, x):
    mean, std = x.double().mean(dim=(0, 1)), x.double().std(dim=(0, 1))
    model.set_normalisation(mean.numpy(), std.numpy())
    return model


def _seeded_model(kind: str, batch: int):
    """A model of ``kind`` (seed 0, default sizes) normalised on ``batch`` raw windows, and those windows."""
    torch.manual_seed(0)
    model = build_model(kind, C, TrainConfig())
    x = _raw(batch)
    return _normalised(model, x), x


@pytest.fixture
def cnode() -> CNODE:
    torch.manual_seed(0)
    return CNODE(C)


# ---------------------------------------------------------------------------------------------
# Shapes, normalisation, validation
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "spec",
    [SolverSpec("rk4", 8), SolverSpec("euler", 3), SolverSpec("midpoint", 5), SolverSpec("dopri5"),
     SolverSpec("dopri5", jump_t=False), SolverSpec("bosh3")],
    ids=lambda s: f"{s.method}-{s.steps if s.is_fixed else ('jump' if s.jump_t else 'nojump')}",
)
def test_cnode_logits_shape_and_gradients(cnode, spec):
    x = _raw(3)
    _normalised(cnode, x)
    cnode.solver = spec
    logits = cnode(x)
    assert logits.shape == (3, 4) and logits.dtype == torch.float32 and torch.isfinite(logits).all()
    logits.sum().backward()
    for name, p in cnode.named_parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all(), name


def test_gru_logits_shape_and_gradients():
    torch.manual_seed(0)
    model = GRUClassifier(C)
    x = _raw(3)
    _normalised(model, x)
    logits = model(x)
    assert logits.shape == (3, 4)
    logits.sum().backward()
    assert all(p.grad is not None for p in model.parameters())


@pytest.mark.parametrize("kind", MODEL_KINDS)
def test_normalisation_is_inside_the_model(kind):
    model, x = _seeded_model(kind, 5)
    identity = build_model(kind, C, TrainConfig())
    identity.load_state_dict(model.state_dict())
    identity.set_normalisation(np.zeros(C), np.ones(C))
    x_norm = ((x.double() - model.mean.double()) / model.std.double()).float()
    with torch.no_grad():
        torch.testing.assert_close(model(x), identity(x_norm), rtol=1e-4, atol=1e-5)
        # and the normalisation is not a no-op for these windows
        assert (model(x) - identity(x)).abs().max() > 1e-3


def test_std_floor_and_normalisation_checks(cnode):
    std = np.ones(C)
    std[4] = 0.0  # a channel that never moved in the training split
    cnode.set_normalisation(np.zeros(C), std)
    assert cnode.std[4].item() == pytest.approx(STD_FLOOR)
    assert torch.isfinite(cnode(_raw(2))).all()
    with pytest.raises(ValueError, match=r"mean must be \(23,\), found \(22,\)"):
        cnode.set_normalisation(np.zeros(22), np.ones(22))
    with pytest.raises(ValueError, match="NaN or Inf"):
        cnode.set_normalisation(np.full(C, np.nan), np.ones(C))
    with pytest.raises(ValueError, match="non-negative"):
        cnode.set_normalisation(np.zeros(C), -np.ones(C))


@pytest.mark.parametrize("kind", MODEL_KINDS)
def test_bad_windows_raise_value_error_naming_both_shapes(kind):
    model = build_model(kind, C, TrainConfig())
    with pytest.raises(ValueError) as err:
        model(torch.zeros(96, 80, 22))
    assert "telemetry windows must be (batch, 80, 23), found (96, 80, 22)" in str(err.value)
    assert "22 channels instead of 23" in str(err.value)
    with pytest.raises(ValueError, match=r"found \(96, 60, 23\): 60 samples instead of 80"):
        model(torch.zeros(96, 60, 23))
    with pytest.raises(ValueError, match=r"found \(80, 23\): 2 axes instead of 3"):
        model(torch.zeros(80, 23))
    with pytest.raises(ValueError, match="an empty batch"):
        model(torch.zeros(0, 80, 23))
    x = torch.zeros(2, 80, 23)
    x[1, 7, 3] = float("inf")
    with pytest.raises(ValueError, match="1 NaN or Inf value.*window 1, sample 7, channel 3"):
        model(x)


def test_check_windows_on_numpy():
    check_windows(np.zeros((2, 80, 23), dtype=np.float32), 23, 80)
    x = np.zeros((2, 80, 23))
    x[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="window 0, sample 0, channel 0"):
        check_windows(x, 23, 80)
    with pytest.raises(ValueError, match=r"\(batch, 80, 23\), found \(2, 80, 24\)"):
        check_windows(np.zeros((2, 80, 24)), 23, 80)


@pytest.mark.parametrize("as_tensor", [False, True])
def test_check_windows_is_exact_where_the_sum_overflows_or_cancels(as_tensor):
    """The check reads the sum first: finite values whose sum overflows pass, and an Inf beside a -Inf (a
    NaN sum) or a lone NaN among huge values is still found, at its place."""
    wrap = (lambda a: torch.from_numpy(a)) if as_tensor else (lambda a: a)
    big = np.full((2, 80, 23), 3e38, dtype=np.float32)  # every value finite, the float32 sum is Inf
    check_windows(wrap(big), 23, 80)
    x = big.copy()
    x[1, 2, 3], x[1, 4, 5] = np.inf, -np.inf
    with pytest.raises(ValueError, match="2 NaN or Inf value.*window 1, sample 2, channel 3"):
        check_windows(wrap(x), 23, 80)
    x = np.zeros((2, 80, 23), dtype=np.float32)
    x[0, 9, 1] = np.nan
    with pytest.raises(ValueError, match="1 NaN or Inf value.*window 0, sample 9, channel 1"):
        check_windows(wrap(x), 23, 80)
    check_windows(np.zeros((2, 80, 23), dtype=np.int64), 23, 80)  # integers: always finite


# ---------------------------------------------------------------------------------------------
# CNODE numerics against torchdiffeq
# ---------------------------------------------------------------------------------------------


def _torchdiffeq_cnode(model: CNODE, x_raw: torch.Tensor, method: str, **kw) -> torch.Tensor:
    """The same CNODE assembled by hand and integrated by torchdiffeq over a LinearPath."""
    x_norm = (x_raw - model.mean) / model.std
    path = LinearPath(x_norm)
    z0 = torch.tanh(model.encoder(x_norm[:, 0]))
    z1 = odeint(lambda t, z: model.field(z, path(t)), z0, kw.pop("t"), method=method, **kw)[-1]
    return model.head(z1)


@pytest.mark.parametrize("method", ["euler", "midpoint"])
@pytest.mark.parametrize("n", [1, 8, 13])
def test_cnode_euler_midpoint_equal_torchdiffeq(cnode, method, n):
    model = cnode.double()
    x = _raw(3, dtype=torch.float64)
    _normalised(model, x)
    model.solver = SolverSpec(method, n)
    with torch.no_grad():
        ours = model(x)
        theirs = _torchdiffeq_cnode(model, x, method, t=torch.linspace(0, 1, n + 1, dtype=torch.float64))
    torch.testing.assert_close(ours, theirs, rtol=1e-12, atol=1e-12)


def _reference(model: CNODE, x: torch.Tensor) -> torch.Tensor:
    model.solver = SolverSpec("dopri5", rtol=1e-11, atol=1e-11, jump_t=True)
    return model(x)


@torch.no_grad()
def test_cnode_rk4_converges_to_tight_dopri5_on_smooth_windows():
    torch.manual_seed(0)
    model = CNODE(5).double()
    x = _smooth(3, 5)
    ref = _reference(model, x)
    errors = []
    for n in (2, 4, 8, 16, 32, 79):
        model.solver = SolverSpec("rk4", n)
        errors.append((model(x) - ref).abs().max().item())
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[2] < 1e-4 and errors[-1] < 1e-8, errors


@torch.no_grad()
def test_cnode_rk4_is_fourth_order_when_steps_align_with_the_knots():
    # On rough (white-noise) windows the path's kinks inside a step limit any fixed method's
    # order; with N a multiple of W - 1 = 79 every step lies inside one segment, the field is
    # smooth within each step, and classic RK4 is 4th order again.
    torch.manual_seed(0)
    model = CNODE(5).double()
    x = _raw(3, channels=5, dtype=torch.float64)
    _normalised(model, x)
    ref = _reference(model, x)
    errors = []
    for n in (79, 158):
        model.solver = SolverSpec("rk4", n)
        errors.append((model(x) - ref).abs().max().item())
    assert errors[1] < errors[0] / 10, errors  # 2^4 = 16 in theory


@torch.no_grad()
def test_adaptive_with_and_without_jump_t(cnode):
    x = _raw(2)
    _normalised(cnode, x)
    cnode.solver = SolverSpec("dopri5", rtol=1e-3, atol=1e-4, jump_t=True)
    with_knots = cnode(x)
    nfe_knots = cnode.nfe
    # every one of the 79 segments takes at least one step (6 new evaluations for dopri5, FSAL),
    # plus one re-evaluation after each of the 78 knots
    assert nfe_knots >= 79 * 6 + 78
    cnode.solver = SolverSpec("dopri5", rtol=1e-3, atol=1e-4, jump_t=False)
    without = cnode(x)
    assert 0 < cnode.nfe < nfe_knots
    cnode.solver = SolverSpec("rk4", 79)  # a close reference for these tolerances
    ref = cnode(x)
    assert (with_knots - ref).abs().max() < 1e-3
    assert torch.isfinite(without).all()


@pytest.mark.parametrize("method,per_step", [("rk4", 4), ("midpoint", 2), ("euler", 1)])
@pytest.mark.parametrize("n", [1, 8])
def test_nfe_counts_fixed(cnode, method, per_step, n):
    cnode.solver = SolverSpec(method, n)
    x = _raw(2)
    cnode(x)
    assert cnode.nfe == per_step * n
    cnode(x)  # reset per forward, not accumulated
    assert cnode.nfe == per_step * n


def test_nfe_counts_adaptive(cnode):
    cnode.solver = SolverSpec("dopri5", jump_t=False)
    cnode(_raw(2))
    assert cnode.nfe > 0


@torch.no_grad()
def test_trace_holds_every_rk4_stage(cnode):
    model = cnode.double()
    x = _raw(3, dtype=torch.float64)
    _normalised(model, x)
    n = 4
    model.solver = SolverSpec("rk4", n)
    tr = model.trace(x)
    assert model.nfe == 4 * n
    torch.testing.assert_close(tr["logits"], model(x))
    x_norm = (x - model.mean) / model.std
    torch.testing.assert_close(tr["x_norm"], x_norm)
    torch.testing.assert_close(tr["z0"], torch.tanh(model.encoder(x_norm[:, 0])))
    assert tr["stages"].shape == (n, 4, 3, 40)
    np.testing.assert_allclose(tr["times"], stage_times("rk4", n))
    np.testing.assert_allclose(tr["stage_time"][1], [0.25, 0.375, 0.375, 0.5])
    torch.testing.assert_close(tr["u"], torch.as_tensor(interp_matrix(tr["times"])) @ x_norm)
    # rebuild each stage input from the previous ones with an independent path evaluation
    path, h, f = LinearPath(x_norm), 1.0 / n, model.field
    for k in range(n):
        t = k * h
        s = tr["stages"][k]
        k1 = f(s[0], path(t))
        torch.testing.assert_close(s[1], s[0] + h / 2 * k1)
        k2 = f(s[1], path(t + h / 2))
        torch.testing.assert_close(s[2], s[0] + h / 2 * k2)
        k3 = f(s[2], path(t + h / 2))
        torch.testing.assert_close(s[3], s[0] + h * k3)
        k4 = f(s[3], path(t + h))
        nxt = tr["stages"][k + 1, 0] if k + 1 < n else tr["z1"]
        torch.testing.assert_close(nxt, s[0] + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
    torch.testing.assert_close(tr["stages"][0, 0], tr["z0"])
    torch.testing.assert_close(tr["logits"], model.head(tr["z1"]))
    model.solver = SolverSpec("dopri5")
    with pytest.raises(ValueError, match="fixed-step solver"):
        model.trace(x)


# ---------------------------------------------------------------------------------------------
# GRU against a hand-written recurrence
# ---------------------------------------------------------------------------------------------


def _manual_gru(model: GRUClassifier, x_norm: torch.Tensor, reset_after: bool = True) -> torch.Tensor:
    """Eq. (11) in PyTorch's gate order (r, z, n) and conventions; returns all hidden states.

    r = sigma(W_ir x + b_ir + W_hr h + b_hr)
    z = sigma(W_iz x + b_iz + W_hz h + b_hz)
    n = tanh(W_in x + b_in + r * (W_hn h + b_hn))      reset after the matmul (linear_before_reset=1)
    n = tanh(W_in x + b_in + W_hn (r * h) + b_hn)      reset before it, as Eq. (11) writes it
    h = (1 - z) * n + z * h
    """
    g = model.gru
    w_ir, w_iz, w_in = g.weight_ih_l0.chunk(3)
    w_hr, w_hz, w_hn = g.weight_hh_l0.chunk(3)
    b_ir, b_iz, b_in = g.bias_ih_l0.chunk(3)
    b_hr, b_hz, b_hn = g.bias_hh_l0.chunk(3)
    h = torch.zeros(x_norm.shape[0], model.hidden, dtype=x_norm.dtype)
    out = []
    for t in range(x_norm.shape[1]):
        x = x_norm[:, t]
        r = torch.sigmoid(x @ w_ir.T + b_ir + h @ w_hr.T + b_hr)
        z = torch.sigmoid(x @ w_iz.T + b_iz + h @ w_hz.T + b_hz)
        if reset_after:
            n = torch.tanh(x @ w_in.T + b_in + r * (h @ w_hn.T + b_hn))
        else:
            n = torch.tanh(x @ w_in.T + b_in + (r * h) @ w_hn.T + b_hn)
        h = (1 - z) * n + z * h
        out.append(h)
    return torch.stack(out, dim=1)


@torch.no_grad()
def test_gru_last_state_logits_equal_manual_recurrence():
    torch.manual_seed(0)
    model = GRUClassifier(C, hidden=16).double()
    x = _raw(3, dtype=torch.float64)
    _normalised(model, x)
    x_norm = (x - model.mean) / model.std
    h = _manual_gru(model, x_norm)
    logits = h[:, -1] @ model.head.weight.T + model.head.bias
    torch.testing.assert_close(model(x), logits, rtol=1e-12, atol=1e-12)
    tr = model.trace(x)
    torch.testing.assert_close(tr["h"], h, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(tr["logits"], logits)
    # the other reset convention is a different function: this test would catch a swap
    wrong = _manual_gru(model, x_norm, reset_after=False)[:, -1] @ model.head.weight.T + model.head.bias
    assert (wrong - logits).abs().max() > 1e-4


# ---------------------------------------------------------------------------------------------
# MACs, builders, signatures, checkpoints
# ---------------------------------------------------------------------------------------------


def test_macs_from_weight_counts(cnode):
    for method, n, evals in (("rk4", 8, 32), ("midpoint", 8, 16), ("euler", 5, 5)):
        cnode.solver = SolverSpec(method, n)
        expected = (
            cnode.encoder.weight.numel()
            + evals * (cnode.field.lin1.weight.numel() + cnode.field.lin2.weight.numel())
            + cnode.head.weight.numel()
        )
        assert cnode.macs_per_window() == expected
    cnode.solver = SolverSpec("rk4", 8)
    assert cnode.macs_per_window() == 212_024  # 23*40 + 32*(63*64 + 64*40) + 40*4
    assert cnode.macs_breakdown()["control_matmul"] == 17 * 80 * 23
    cnode.solver = SolverSpec("dopri5")
    with pytest.raises(ValueError, match="pass evals"):
        cnode.macs_per_window()
    assert cnode.macs_per_window(evals=554) == 23 * 40 + 554 * 6592 + 160
    gru = GRUClassifier(C)
    per_step = gru.gru.weight_ih_l0.numel() + gru.gru.weight_hh_l0.numel()
    assert gru.macs_per_window() == W * per_step + gru.head.weight.numel() == 1_977_920


def test_state_dict_names_are_the_export_contract():
    cnode = CNODE(C)
    assert set(cnode.state_dict()) == {
        "mean", "std", "encoder.weight", "encoder.bias", "field.lin1.weight", "field.lin1.bias",
        "field.lin2.weight", "field.lin2.bias", "head.weight", "head.bias",
    }
    assert cnode.field.lin1.weight.shape == (64, 40 + C) and cnode.field.lin2.weight.shape == (40, 64)
    gru = GRUClassifier(C)
    assert set(gru.state_dict()) == {
        "mean", "std", "gru.weight_ih_l0", "gru.weight_hh_l0", "gru.bias_ih_l0", "gru.bias_hh_l0",
        "head.weight", "head.bias",
    }


def test_build_model_follows_train_config():
    cfg = TrainConfig(latent=12, hidden=20, gru_hidden=30, solver="dopri5", steps=5, rtol=1e-5, atol=1e-6, jump_t=False)
    cnode = build_model("cnode", 7, cfg)
    assert (cnode.latent, cnode.hidden, cnode.n_channels, cnode.window) == (12, 20, 7, 80)
    assert cnode.solver == SolverSpec("dopri5", 5, 1e-5, 1e-6, False)
    gru = build_model("gru", 7, cfg)
    assert gru.hidden == 30 and gru.gru.input_size == 7
    with pytest.raises(ValueError, match="unknown model kind 'lstm'; valid: cnode, gru"):
        build_model("lstm", 7, cfg)


@pytest.mark.parametrize("kind", MODEL_KINDS)
def test_signature_rebuilds_the_model_and_checkpoint_loads_weights_only(kind):
    model, x = _seeded_model(kind, 2)
    sig = model_signature(model)
    assert sig["kind"] == kind and all(type(v) in (int, str) for v in sig.values())
    buf = io.BytesIO()
    torch.save({"signature": sig, "state_dict": model.state_dict()}, buf)
    buf.seek(0)
    ckpt = torch.load(buf, weights_only=True)
    rebuilt = model_from_signature(ckpt["signature"])
    rebuilt.load_state_dict(ckpt["state_dict"], strict=True)
    assert model_signature(rebuilt) == sig
    with torch.no_grad():
        torch.testing.assert_close(rebuilt(x), model(x), rtol=0, atol=0)
    with pytest.raises(ValueError, match="signature"):
        model_from_signature({**sig, "latent": "40"})
    with pytest.raises(TypeError):
        model_signature(torch.nn.Linear(2, 2))
