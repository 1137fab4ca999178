"""Config: defaults are Table 2, overrides are typed, unknown keys are rejected with the valid list."""

from __future__ import annotations

import pytest

from quadfdi.core.config import Config, build_config, dumps_toml, load_config
from quadfdi.core.errors import QuadfdiError
from tests.conftest import ROOT


def test_paper_toml_is_table_2():
    cfg = load_config(ROOT / "configs/paper.toml")
    s = cfg.sim
    assert (s.duration_s, s.sample_dt_s, s.n_traj, s.fault_ratio) == (16.0, 0.04, 240, 0.75)
    assert (s.onset_frac, s.ramp_frac, s.window, s.stride, s.split) == ((0.14, 0.43), (0.30, 0.62), 80, 10, (0.7, 0.15, 0.15))
    assert (cfg.train.epochs, cfg.train.batch_size, cfg.train.latent, cfg.train.gru_hidden) == (14, 96, 40, 80)
    assert s.n_samples == 400 and s.substeps == 8


def test_toml_round_trip():
    cfg = load_config(ROOT / "configs/paper.toml", ["sim.n_traj=12", "train.model=gru"])
    assert build_config(__import__("tomllib").loads(dumps_toml(cfg))) == cfg


def test_override_types():
    cfg = load_config(None, ["sim.duration_s=8", "sim.onset_frac=[0.1, 0.2]", "train.model=cnode", "train.jump_t=false"])
    assert cfg.sim.duration_s == 8.0 and isinstance(cfg.sim.duration_s, float)
    assert cfg.sim.onset_frac == (0.1, 0.2) and cfg.train.model == "cnode" and cfg.train.jump_t is False


@pytest.mark.parametrize("override, message", [
    ("sim.n_trajs=3", "unknown key sim.n_trajs; valid keys of [sim]: seed, vehicle, n_traj"),
    ("simulator.n_traj=3", "unknown section 'simulator'; valid sections: sim, train, export"),
    ("sim.duration_s=-1", "sim.duration_s must be positive, found -1.0"),
    ("sim.fault_ratio=1.5", "sim.fault_ratio must be in [0, 1], found 1.5"),
    ("sim.n_traj=ten", "sim.n_traj must be an integer, found 'ten'"),
    ("sim.onset_frac=[0.1]", "sim.onset_frac must be a list of 2 values"),
    ("train.solver=rk45", "train.solver must be one of dopri5, bosh3, rk4, euler, midpoint; found 'rk45'"),
    ("sim.severity_threshold=0.45", "may become detectable at"),
    ("n_traj", "--set expects section.key=value"),
])
def test_bad_overrides(override, message):
    with pytest.raises(QuadfdiError) as exc:
        load_config(ROOT / "configs/paper.toml", [override])
    assert message in str(exc.value)
    assert "\n" not in str(exc.value)


def test_unknown_key_in_file(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text("[sim]\nbogus = 1\n")
    with pytest.raises(QuadfdiError, match="unknown key sim.bogus"):
        load_config(p)


def test_missing_and_invalid_file(tmp_path):
    with pytest.raises(QuadfdiError, match="does not exist"):
        load_config(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[sim\n")
    with pytest.raises(QuadfdiError, match="not valid TOML"):
        load_config(bad)


def test_defaults_equal_paper_file():
    """Every stage's defaults are the paper file's; only [run] (what `quadfdi run` adds: the realism
    check against the shared real logs) differs, because a default cannot name files of this machine."""
    import dataclasses

    paper = load_config(ROOT / "configs/paper.toml")
    assert dataclasses.replace(paper, run=Config().run) == Config()
    assert paper.run.realism_logs and not Config().run.realism_logs
