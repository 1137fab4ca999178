"""The solver study (solverstudy/), its model variants (models/variants.py) and ``quadfdi solvers``.

Numbers are checked against independent computations: evaluation counts against the schemes'
stage counts, the step-average control against the closed-form mean of a linear path and a fine
quadrature of a piecewise-linear one, the average-control CNODE against a hand-written Euler loop.
The commands run through the real dispatcher (``quadfdi.cli.main``) on tiny configurations
(``--set solvers.key=value``); no timing is asserted.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import random_weight_run
import torch

from quadfdi.solverstudy.config import SolversConfig
from quadfdi.core.config import load_config
from quadfdi.cli import main as quadfdi_main
from quadfdi.solverstudy.matching import matched_table
from quadfdi.solverstudy.matrix import TrainSpec, control_findings, ott_findings
from quadfdi.solverstudy.settings import Setting, default_settings, reference_setting
from quadfdi.solverstudy.study import run_study, sample_indices, solve_each, with_setting
from quadfdi.models.networks import CNODE
from quadfdi.models.variants import AverageControlCNODE, average_matrix

C, W = 5, 80
RECORD_FIELDS = {
    "label", "method", "steps", "rtol", "atol", "jump_t", "control", "dtype", "reference", "macro_f1",
    "argmax_agreement", "max_logit_err", "mean_logit_err", "nfe_per_window", "nfe_min", "nfe_max", "latency_us",
    "n_windows", "sample", "split_macro_f1", "split_n_windows", "macs_per_window",
}


def _model(seed: int = 0, cls=CNODE) -> CNODE:
    torch.manual_seed(seed)
    m = cls(C, window=W, latent=8, hidden=16)
    m.eval()
    return m


def _windows(n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    # smooth-ish random telemetry: a random walk per channel, (n, W, C) float32
    return np.cumsum(rng.normal(scale=0.3, size=(n, W, C)), axis=1).astype(np.float32)


# ------------------------------------------------------------------------------- settings


def test_setting_parse_and_labels():
    assert Setting.parse("rk4:8") == Setting("rk4", steps=8)
    assert Setting.parse("rk4:8:avg").control == "average"
    d = Setting.parse("dopri5:1e-3")
    assert (d.rtol, d.atol, d.jump_t) == (1e-3, pytest.approx(1e-4), True)
    assert Setting.parse("bosh3:1e-4:nojump").jump_t is False
    assert Setting.parse("ref") == reference_setting()
    assert Setting.parse("dopri5:1e-3:restart").label == "dopri5 rtol=1e-3 restart"
    labels = [s.label for s in default_settings(SolversConfig(controls=("point",)))]
    assert len(labels) == len(set(labels)) == 3 * 7 + 2 * 5 * 2
    for bad in ("rk4", "rk4:0", "dopri5:x", "heun:4", "dopri5:1e-3:avg", "rk4:8:mean"):
        with pytest.raises(ValueError):
            Setting.parse(bad)


def test_sample_indices_fixed_and_sorted():
    a, b = sample_indices(1188, 128, 0), sample_indices(1188, 128, 0)
    assert np.array_equal(a, b) and len(a) == 128 and np.all(np.diff(a) > 0)
    assert not np.array_equal(a, sample_indices(1188, 128, 1))
    assert np.array_equal(sample_indices(10, 0), np.arange(10))
    assert np.array_equal(sample_indices(10, 50), np.arange(10))


# ----------------------------------------------------------------------- evaluation counts


@pytest.mark.parametrize("method,per_step", [("euler", 1), ("midpoint", 2), ("rk4", 4)])
@pytest.mark.parametrize("n", [1, 3, 8])
def test_fixed_nfe_per_window(method, per_step, n):
    s = Setting(method, steps=n)
    out = solve_each(_model(), s, _windows(3))
    assert np.all(out.nfe == per_step * n) and s.evals_per_window() == per_step * n
    avg = solve_each(_model(), Setting(method, steps=n, control="average"), _windows(3))
    assert np.all(avg.nfe == per_step * n)


def test_adaptive_nfe_counted_per_window():
    x = _windows(2)
    out = solve_each(_model(), Setting("dopri5", rtol=1e-3, atol=1e-4, jump_t=True), x)
    # with the 78 knots as jump_t dopri5 cannot step over a segment: >= 6 evaluations per segment
    assert np.all(out.nfe >= 6 * (W - 1))
    free = solve_each(_model(), Setting("dopri5", rtol=1e-3, atol=1e-4, jump_t=False), x)
    assert np.all(free.nfe < out.nfe)


# --------------------------------------------------------------------- the average control


@pytest.mark.parametrize("n", [1, 2, 3, 7, 8, 79, 100])
def test_average_matrix_rows_and_linear_path(n):
    a = average_matrix(n, W)
    assert a.shape == (n, W)
    np.testing.assert_allclose(a.sum(axis=1), 1.0, atol=1e-13)
    assert np.all(a >= -1e-15)
    t = np.arange(W) / (W - 1)
    x = 0.7 - 2.5 * t  # a linear path: its mean over [k/n, (k+1)/n] is its value at the midpoint
    mid = (np.arange(n) + 0.5) / n
    np.testing.assert_allclose(a @ x, 0.7 - 2.5 * mid, rtol=0, atol=1e-13)


def test_average_matrix_equals_fine_quadrature_of_piecewise_linear_path():
    rng = np.random.default_rng(3)
    x = rng.normal(size=W)
    for n in (1, 2, 5, 8, 32):
        expect = []
        for k in range(n):  # the trapezoid rule on a fine grid of step k (knots need not be on it)
            fine = np.linspace(k / n, (k + 1) / n, 20_001)
            expect.append(np.trapezoid(np.interp(fine, np.arange(W) / (W - 1), x), fine) * n)
        np.testing.assert_allclose(average_matrix(n, W) @ x, expect, atol=1e-6)
    # a coarse grid still sees every sample: every column has weight at N = 2
    assert np.all(average_matrix(2, W).sum(axis=0) > 0)


def test_average_control_cnode_is_a_hand_written_euler_loop():
    point = _model(4)
    avg = with_setting(point, Setting("euler", steps=4, control="average"))
    assert isinstance(avg, AverageControlCNODE)
    x = torch.from_numpy(_windows(2))
    with torch.no_grad():
        xn = avg.normalise(x)
        z = torch.tanh(avg.encoder(xn[:, 0]))
        ubar = torch.einsum("nw,bwc->bnc", torch.as_tensor(average_matrix(4, W), dtype=torch.float32), xn)
        for k in range(4):
            z = z + 0.25 * avg.field(z, ubar[:, k])
        np.testing.assert_allclose(avg(x).numpy(), avg.head(z).numpy(), rtol=1e-5, atol=1e-6)
        # and the trace has integrate_fixed's layout: z0, N*S stage states, z1
        avg.solver = Setting("rk4", steps=3, control="average").spec()
        tr = avg.trace(x)
        assert tr["stages"].shape == (3, 4, 2, 8) and tr["u"].shape == (2, 3, C)
        torch.testing.assert_close(tr["logits"], avg(x))
    # weights move between the two classes unchanged
    assert all(torch.equal(a, b) for a, b in zip(point.state_dict().values(), avg.state_dict().values()))


def test_a_cnode_with_a_motor_head_rebuilds_under_every_setting():
    """The realistic suite's CNODE carries a motor head (models.motor): the solver study rebuilds it
    (quadfdi run on configs/realistic.toml failed here on n_motors) and keeps the head's weights."""
    from quadfdi.models.motor import attach_motor_head

    m = attach_motor_head(_model(5))
    for setting in (Setting("rk4", steps=8), Setting("euler", steps=4, control="average"),
                    Setting("dopri5", rtol=1e-3, atol=1e-5, jump_t=True, restart=True)):
        r = with_setting(m, setting)
        assert r.motor_head is not None
        assert all(torch.equal(a, b) for a, b in zip(m.state_dict().values(), r.state_dict().values()))


def test_signature_records_the_control_and_a_checkpoint_loads_either(tmp_path):
    from quadfdi.models.checkpoint import load_checkpoint, save_checkpoint
    from quadfdi.models.networks import model_from_signature, model_signature

    avg = with_setting(_model(5), Setting("rk4", steps=2, control="average"))
    sig = model_signature(avg)
    assert sig["control"] == "average" and model_signature(_model())["control"] == "point"
    save_checkpoint(tmp_path / "avg.pt", avg, {}, [f"c{i}" for i in range(C)])
    back, blob = load_checkpoint(tmp_path / "avg.pt", "cnode")
    assert type(back) is AverageControlCNODE and back.solver == avg.solver
    x = torch.from_numpy(_windows(2))
    with torch.no_grad():
        torch.testing.assert_close(back(x), avg(x), rtol=0, atol=0)
    with pytest.raises(ValueError, match="control"):  # models.networks alone knows the point control only
        model_from_signature(sig)
    old = {k: v for k, v in sig.items() if k != "control"}  # checkpoints written before the control was recorded
    assert type(model_from_signature(old)) is CNODE


# ---------------------------------------------------------------------------- the study


def test_reference_equals_fine_float64_rk4_on_the_knot_grid():
    # rk4 with 8 steps per segment never straddles a knot: 4th order on each linear piece, an
    # independent solver (no torchdiffeq, no step control)
    x = _windows(2)
    ref = solve_each(_model(2), reference_setting(), x)
    fine = solve_each(_model(2), Setting("rk4", steps=8 * (W - 1), dtype="float64"), x)
    np.testing.assert_allclose(ref.logits, fine.logits, rtol=0, atol=1e-6)
    # restarting at each knot costs a few evaluations per segment, not thousands (torchdiffeq's
    # jump_t can lose track of the knots at rtol 1e-9, see KnotRestartCNODE)
    assert np.all(ref.nfe < 40 * (W - 1))


def test_knot_restart_matches_jump_t_where_jump_t_works():
    x = _windows(2)
    a = solve_each(_model(3), Setting.parse("dopri5:1e-5:restart"), x)
    b = solve_each(_model(3), Setting.parse("dopri5:1e-5"), x)
    np.testing.assert_allclose(a.logits, b.logits, rtol=0, atol=1e-4)


def test_study_reference_agrees_with_itself_and_records_hold_every_field():
    x, y = _windows(6), np.array([0, 1, 2, 3, 0, 1])
    settings = [Setting.parse(s) for s in ("euler:2", "rk4:1", "rk4:79", "dopri5:1e-2", "dopri5:1e-2:nojump")]
    out = run_study(_model(), x, y, SolversConfig(sample=4, sample_seed=0), settings, log=lambda s: None)
    ref = out["solvers"][0]
    assert ref["reference"] and ref is out["reference"]
    assert ref["max_logit_err"] == 0 and ref["mean_logit_err"] == 0 and ref["argmax_agreement"] == 1
    assert ref["dtype"] == "float64" and ref["rtol"] == 1e-9 and ref["restart"] is True
    assert out["meta"]["reference_check"]["max_abs_logit_diff"] < 1e-6
    for r in out["solvers"]:
        assert RECORD_FIELDS <= set(r), RECORD_FIELDS - set(r)
        assert r["n_windows"] == 4 and "4 of 6 test windows" in r["sample"]
    by = {r["label"]: r for r in out["solvers"]}
    assert by["rk4 N=1"]["nfe_per_window"] == 4 and by["euler N=2"]["nfe_per_window"] == 2
    assert by["rk4 N=1"]["split_n_windows"] == 6 and by["dopri5 rtol=1e-2 jump"]["split_macro_f1"] is None
    # rk4 on the knot grid is 4th order on each linear piece: far closer than rk4 N=1
    assert by["rk4 N=79"]["max_logit_err"] < 1e-3 * by["rk4 N=1"]["max_logit_err"] + 1e-6
    assert [m["adaptive"] for m in out["matched"]] == ["dopri5 rtol=1e-2 jump", "dopri5 rtol=1e-2 nojump"]


def _rec(label, method, nfe, err, f1, control="point", **kw):
    return {"label": label, "method": method, "nfe_per_window": nfe, "max_logit_err": err, "macro_f1": f1,
            "control": control, "reference": False, **kw}


def test_matched_table_picks_cheapest_matching_fixed():
    recs = [
        _rec("ref", "dopri5", 900, 0.0, 0.90, reference=True),
        _rec("dopri5 a", "dopri5", 554, 1e-3, 0.900),
        _rec("rk4 N=79", "rk4", 316, 1e-6, 0.900),  # matches
        _rec("rk4 N=16", "rk4", 64, 5e-4, 0.9015),  # matches, cheaper: chosen
        _rec("euler N=8", "euler", 8, 2e-3, 0.900),  # cheaper still, but error too large
        _rec("midpoint N=8", "midpoint", 16, 1e-4, 0.895),  # error fine, F1 off by 0.5 point
        _rec("rk4 N=2 avg", "rk4", 8, 1e-5, 0.900, control="average"),  # another model: not a candidate
        _rec("dopri5 b", "dopri5", 30, 1e-9, 0.900),  # nothing is that accurate
    ]
    table = {m["adaptive"]: m for m in matched_table(recs)}
    assert set(table) == {"dopri5 a", "dopri5 b"}  # the reference is not an adaptive setting to match
    assert table["dopri5 a"]["fixed"] == "rk4 N=16"
    assert table["dopri5 a"]["ratio"] == pytest.approx(554 / 64)
    assert table["dopri5 b"]["fixed"] is None and table["dopri5 b"]["ratio"] is None


def test_matched_table_equal_cost_prefers_smaller_error_and_f1_tolerance_is_inclusive():
    recs = [_rec("dopri5", "dopri5", 100, 1e-2, 0.8), _rec("midpoint N=2", "midpoint", 4, 9e-3, 0.802),
            _rec("rk4 N=1", "rk4", 4, 1e-3, 0.798)]
    assert matched_table(recs)[0]["fixed"] == "rk4 N=1"
    assert matched_table(recs, f1_tol=0.001)[0]["fixed"] == "midpoint N=2"  # F1 above: at least as accurate
    assert matched_table(recs, f1_tol=0.001, two_sided=True)[0]["fixed"] is None
    better = [_rec("dopri5", "dopri5", 100, 1e-2, 0.80), _rec("rk4 N=4", "rk4", 16, 1e-3, 0.85)]
    assert matched_table(better)[0]["fixed"] == "rk4 N=4"
    assert matched_table(better, two_sided=True)[0]["fixed"] is None


# ------------------------------------------------------------------------- matrix findings


def test_ott_and_control_findings_on_hand_made_matrix():
    def info(label, method, steps=None, control="point", rtol=None, jump=None):
        return {"label": label, "method": method, "steps": steps, "control": control, "rtol": rtol, "jump_t": jump}

    ref = reference_setting().to_dict()
    deploys = [Setting.parse(s).to_dict() for s in ("dopri5:1e-3", "rk4:2", "rk4:8", "rk4:2:avg")] + [ref]
    train = [info("dopri5 jump", "dopri5", rtol=1e-3, jump=True), info("rk4 N=2", "rk4", 2),
             info("rk4 N=8", "rk4", 8), info("rk4 N=2 avg", "rk4", 2, "average")]
    f1 = {  # train -> deploy -> F1
        "dopri5 jump": [0.90, 0.85, 0.90, 0.70, 0.90], "rk4 N=2": [0.60, 0.85, 0.70, 0.5, 0.60],
        "rk4 N=8": [0.90, 0.80, 0.90, 0.6, 0.895], "rk4 N=2 avg": [0.7, 0.6, 0.7, 0.905, 0.7],
    }
    cells = [{"train": t, "deploy": d["label"], "macro_f1": v, "max_logit_err": 0.1, "nfe_per_window": n}
             for t, vals in f1.items() for d, v, n in zip(deploys, vals, (554, 8, 32, 8, 900))]
    m = {"train": train, "deploy": deploys, "cells": cells, "meta": {"break_tol": 0.02}}
    ott = {o["train"]: o for o in ott_findings(m)}
    assert ott["rk4 N=2"]["breaks"] and not ott["rk4 N=8"]["breaks"] and not ott["dopri5 jump"]["breaks"]
    assert ott["rk4 N=2"]["own_deploy"] == "rk4 N=2" and ott["dopri5 jump"]["own_deploy"] == "dopri5 rtol=1e-3 jump"
    assert ott["rk4 N=2"]["f1_drop_to_ref"] == pytest.approx(0.25)
    ctl = control_findings(m)
    assert ctl == [{"method": "rk4", "steps": 2, "nfe_per_window": 8, "average": "rk4 N=2 avg", "point": "rk4 N=2",
                    "average_macro_f1": 0.905, "average_max_logit_err": 0.1, "point_macro_f1": 0.85,
                    "point_max_logit_err": 0.1}]
    from quadfdi.solverstudy.report import f1_match_sentence, ott_sentence

    assert "between h = 1/8 and h = 1/2" in ott_sentence({**m, "ott": list(ott.values())})
    assert "rk4 N=2 avg" in f1_match_sentence({**m, "ott": list(ott.values())})


# ----------------------------------------------------------------------------- the commands


@pytest.fixture(scope="module")
def tiny_run(small_run, tmp_path_factory) -> Path:
    """A copy of the session's small run with a random-weight (untrained) CNODE checkpoint."""
    return random_weight_run(small_run, tmp_path_factory.mktemp("solvers") / "run", ("cnode",),
                             load_config(small_run / "config.toml").to_dict())


def _set(**kw) -> list[str]:
    """``--set solvers.key=value`` arguments (TOML values)."""
    out = []
    for k, v in kw.items():
        out += ["--set", f"solvers.{k}={json.dumps(list(v) if isinstance(v, tuple) else v)}"]
    return out


def test_solvers_command_writes_every_field(tiny_run):
    argv = ["solvers", "study", "--run", str(tiny_run), "--workers", "1",  # jobs in this process, cached
            *_set(sample=3, steps=(1, 2), fixed_methods=("euler", "rk4"), adaptive_methods=("dopri5", "bosh3"),
                  rtols=(1e-2,), jump="both")]
    assert quadfdi_main(argv) == 0
    out = json.loads((tiny_run / "solvers" / "solvers.json").read_text())
    assert "this process, one setting per job" in out["meta"]["latency_note"]
    assert quadfdi_main(argv) == 0  # every setting from the cache: the same records, timings included
    assert json.loads((tiny_run / "solvers" / "solvers.json").read_text())["solvers"] == out["solvers"]
    assert set(out) == {"solvers", "matched", "matched_any_control", "reference", "meta"}
    assert len(out["solvers"]) == 1 + 2 * 4 + 4  # reference, fixed x (point, average), adaptive
    assert "rk4 N=2 avg" in {r["label"] for r in out["solvers"]}
    assert len(out["matched_any_control"]) == len(out["matched"]) == 4
    for r in out["solvers"]:
        assert RECORD_FIELDS <= set(r)
    for m in out["matched"]:
        assert {"adaptive", "adaptive_nfe", "fixed", "fixed_nfe", "ratio"} <= set(m)
    assert {"sample", "n_windows", "n_test_windows", "sample_indices", "threads", "latency_note", "checkpoint",
            "command", "seconds"} <= set(out["meta"])
    assert out["meta"]["command"].startswith("quadfdi solvers study --run ")
    assert "solvers.sample=3" in out["meta"]["command"]
    md = (tiny_run / "solvers" / "solvers.md").read_text()
    assert "### Matched accuracy" in md and "rk4 N=2" in md
    for f in ("solver_error_vs_nfe.png", "solver_f1_vs_latency.png"):
        assert (tiny_run / "figures" / f).read_bytes()[:4] == b"\x89PNG"
    # what bench and the run report read, from the files alone
    from quadfdi.formats.solver_files import load_records
    from quadfdi.solverstudy.report import headline, report_section

    assert load_records(tiny_run) == out["solvers"]
    section = report_section(tiny_run)
    assert section[0] == "## Solvers: fixed against adaptive steps"
    assert "![logit error vs evaluations](figures/solver_error_vs_nfe.png)" in section
    assert headline(tiny_run)[0].startswith("- Solvers (solvers/solvers.json): ")


def test_render_recomputes_the_matched_table_from_the_json(tiny_run, capsys):
    study = tiny_run / "solvers" / "solvers.json"
    if not study.is_file():  # the study test writes it; alone, make a tiny one
        assert quadfdi_main(["solvers", "study", "--run", str(tiny_run),
                             *_set(sample=2, steps=(1,), fixed_methods=("rk4",), adaptive_methods=("dopri5",),
                                   rtols=(1e-2,), jump="on", controls=("point",))]) == 0
    before = json.loads(study.read_text())
    assert quadfdi_main(["solvers", "render", "--run", str(tiny_run), *_set(f1_two_sided=True)]) == 0
    after = json.loads(study.read_text())
    assert after["meta"]["f1_two_sided"] is True and after["solvers"] == before["solvers"]
    assert after["matched"] == matched_table(before["solvers"], before["meta"]["f1_tol"], two_sided=True)
    assert "solvers.md" in capsys.readouterr().out


def test_matrix_command_writes_every_field_and_reuses_models(tiny_run, capsys):
    args = ["solvers", "matrix", "--run", str(tiny_run),
            *_set(matrix_epochs=1, matrix_max_train_windows=96, matrix_train=("dopri5", "rk4:1", "rk4:1:avg"),
                  matrix_deploy=("dopri5:1e-2:nojump", "rk4:1", "rk4:2", "rk4:1:avg", "ref")),
            "--set", "train.rtol=1e-2", "--set", "train.atol=1e-3", "--set", "train.jump_t=false"]
    assert quadfdi_main(args) == 0
    out = json.loads((tiny_run / "solvers" / "solver_matrix.json").read_text())
    assert set(out) == {"train", "deploy", "cells", "ott", "controls", "meta"}
    assert [i["label"] for i in out["train"]] == ["dopri5 nojump", "rk4 N=1", "rk4 N=1 avg"]
    for i in out["train"]:
        assert {"epochs", "train_seconds", "nfe_per_forward_train", "best_val_macro_f1", "control"} <= set(i)
        assert i["n_train_windows"] == 96
    assert len(out["cells"]) == 3 * 5
    for c in out["cells"]:
        assert {"train", "deploy", "macro_f1", "argmax_agreement", "max_logit_err", "mean_logit_err",
                "nfe_per_window", "n_windows"} <= set(c)
        if c["deploy"].startswith("reference"):
            assert c["max_logit_err"] == 0
    assert {o["train"] for o in out["ott"]} == {"dopri5 nojump", "rk4 N=1", "rk4 N=1 avg"}
    assert out["controls"][0]["steps"] == 1 and out["controls"][0]["nfe_per_window"] == 4
    assert {"seconds", "train_seconds", "epochs", "n_test_windows"} <= set(out["meta"])
    assert (tiny_run / "figures" / "solver_matrix_f1.png").is_file()
    assert (tiny_run / "figures" / "solver_controls.png").is_file()
    assert "Ott et al." in (tiny_run / "solvers" / "solver_matrix.md").read_text()
    # a step-average model loads back in its own class, no special case
    from quadfdi.models.checkpoint import load_checkpoint

    avg, _ = load_checkpoint(tiny_run / "solvers" / "matrix_models" / "rk4_N_1_avg.pt")
    assert isinstance(avg, AverageControlCNODE)
    first = {c["train"] + c["deploy"]: c["macro_f1"] for c in out["cells"]}
    capsys.readouterr()
    i = args.index('solvers.matrix_train=["dopri5", "rk4:1", "rk4:1:avg"]')
    assert quadfdi_main([*args[:i], 'solvers.matrix_train=["rk4:1:avg"]', *args[i + 1:], "--reuse"]) == 0
    assert "reuse rk4 N=1 avg" in capsys.readouterr().out
    again = json.loads((tiny_run / "solvers" / "solver_matrix.json").read_text())
    assert {c["train"] + c["deploy"]: c["macro_f1"] for c in again["cells"]} == \
        {k: v for k, v in first.items() if k.startswith("rk4 N=1 avg")}
    assert again["meta"]["reused"] == ["rk4 N=1 avg"]


def test_commands_fail_with_one_line_errors(tiny_run, tmp_path, capsys):
    assert quadfdi_main(["solvers", "study", "--run", str(tiny_run), "--checkpoint", str(tmp_path / "none.pt")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "does not exist" in err
    assert quadfdi_main(["solvers", "matrix", "--run", str(tiny_run), *_set(matrix_train=("rk4:0",))]) == 2
    assert "bad solver setting 'rk4:0'" in capsys.readouterr().err
    assert quadfdi_main(["solvers", "study", "--run", str(tiny_run), *_set(fixed_methods=("heun",))]) == 2
    assert "unknown or repeated value 'heun'" in capsys.readouterr().err
    assert quadfdi_main(["solvers", "study", "--run", str(tiny_run), "--set", "solvers.nope=1"]) == 2
    assert "valid keys of [solvers]" in capsys.readouterr().err
    assert quadfdi_main(["solvers", "matrix", "--run", str(tmp_path / "nothing")]) == 2
    assert quadfdi_main(["solvers", "render", "--run", str(tmp_path / "nothing")]) == 2
    assert TrainSpec.parse("dopri5", load_config(tiny_run / "config.toml")).setting.rtol == 1e-3


def test_config_section_is_the_studys_grid():
    cfg = SolversConfig()
    assert len(default_settings(cfg)) == 3 * 7 * 2 + 2 * 5 * 2  # fixed x N x control, adaptive x jump x rtol
    quick = dataclasses.replace(cfg, steps=(1, 4), fixed_methods=("rk4",), adaptive_methods=("dopri5",),
                                rtols=(1e-2,), jump="off", controls=("point",))
    assert [s.label for s in default_settings(quick)] == ["rk4 N=1", "rk4 N=4", "dopri5 rtol=1e-2 nojump"]
    from quadfdi.solverstudy.settings import QUICK, quick_config

    small = quick_config(load_config(None))
    assert all(getattr(small.solvers, k) == v for k, v in QUICK.items())
    assert load_config(None).solvers.sample == 64  # what `make run` measures (configs/paper.toml)
