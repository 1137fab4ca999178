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
    ("simulator.n_traj=3", "unknown section 'simulator'; valid sections: sim, train, sgru, scnode, export"),
    ("sim.duration_s=-1", "sim.duration_s must be positive, found -1.0"),
    ("sim.fault_ratio=1.5", "sim.fault_ratio must be in [0, 1], found 1.5"),
    ("sim.n_traj=ten", "sim.n_traj must be an integer, found 'ten'"),
    ("sim.onset_frac=[0.1]", "sim.onset_frac must be a list of 2 values"),
    ("train.solver=rk45", "train.solver must be one of dopri5, bosh3, rk4, euler, midpoint; found 'rk45'"),
    ("sim.severity_threshold=0.45", "may become detectable at"),
    ("n_traj", "--set expects section.key=value"),
    ("sgru.hiden=3", "unknown key sgru.hiden; valid keys of [sgru]: hidden, epochs, batch"),
    ("sgru.hidden=0", "sgru.hidden must be positive, found 0"),
    ("sgru.zero_start=1.5", "sgru.zero_start is a probability in [0, 1], found 1.5"),
    ("sgru.class_mix=windows", "sgru.class_mix must be one of steps, sampled; found 'windows'"),
    ("sgru.segment=1.5", "sgru.segment must be an integer, found 1.5"),
    ("evaluate.kn=['2-3']", "evaluate.kn entries must be 'k/n'"),
    ("run.study_sim_seeds=[1, 1]", "run.study_sim_seeds must be distinct non-negative seeds"),
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


def test_sections_are_the_installed_entry_points_in_file_order():
    """Each section is declared once, in pyproject.toml, by the package that owns it; the installed
    metadata must say the same (a stale install would miss a section), and Config has one field per
    section in config-file order."""
    import dataclasses
    import tomllib
    from importlib.metadata import entry_points

    from quadfdi.core.sections import FILE_ORDER, GROUP, section_classes

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"][GROUP]
    assert {ep.name: ep.value for ep in entry_points(group=GROUP)} == declared
    assert set(declared) == set(FILE_ORDER)
    assert [f.name for f in dataclasses.fields(Config)] == list(section_classes()) == list(FILE_ORDER)
    assert list(Config().to_dict()) == list(FILE_ORDER)
    for name, cls in section_classes().items():
        assert isinstance(getattr(Config(), name), cls)
        # beside the stage that reads it (<stage>/config.py); [alarm] is core's contract, [run] the app's
        assert declared[name].endswith(".config:" + cls.__name__) or name in ("alarm", "run")


def test_core_config_loads_no_stage_until_config_is_asked_for():
    """core is the ground floor: importing core.config imports no stage; the sections are loaded when
    Config is first used (and the composed class pickles by reference, as Dask jobs carry it)."""
    import subprocess
    import sys

    probe = ("import sys, pickle; import quadfdi.core.config as c; "
             "early = sorted(m for m in sys.modules if m.startswith('quadfdi.') and not m.startswith('quadfdi.core')); "
             "cfg = c.load_config(None, ['sgru.hidden=7']); "
             "assert pickle.loads(pickle.dumps(cfg)) == cfg and type(cfg) is c.Config; "
             "print(early, cfg.sgru.hidden, 'quadfdi.sim.config' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd=ROOT / "tests")
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["[]", "7", "True"]


def test_a_check_across_sections_is_the_sections_validate_with():
    """Config.validate runs every section's own validate, then validate_with(cfg) of the sections that
    define one: the place for a check that reads another section."""
    from dataclasses import dataclass

    from quadfdi.core.config import compose

    @dataclass(frozen=True)
    class Window:
        samples: int = 80

        def validate(self) -> None:
            if self.samples < 2:
                raise QuadfdiError("win.samples must be 2 or more")

    @dataclass(frozen=True)
    class Steps:
        n: int = 8

        def validate(self) -> None:
            pass

        def validate_with(self, cfg) -> None:
            if self.n > cfg.win.samples - 1:
                raise QuadfdiError(f"steps.n must be below win.samples ({cfg.win.samples}), found {self.n}")

    cls = compose({"win": Window, "steps": Steps})
    assert [f for f in cls().to_dict()] == ["win", "steps"] and cls().steps.n == 8
    cls().validate()
    with pytest.raises(QuadfdiError, match="win.samples must be 2"):  # own checks first
        cls(win=Window(1), steps=Steps(200)).validate()
    with pytest.raises(QuadfdiError, match=r"steps.n must be below win.samples \(10\), found 12"):
        cls(win=Window(10), steps=Steps(12)).validate()


def test_sgru_section_defaults_and_round_trip():
    cfg = load_config(ROOT / "configs/paper.toml", ["sgru.hidden=40", "sgru.class_mix=sampled"])
    assert (Config().sgru.hidden, Config().sgru.segment, Config().sgru.motor_aux) == (60, 250, 0.5)
    assert (cfg.sgru.hidden, cfg.sgru.class_mix) == (40, "sampled")
    assert build_config(__import__("tomllib").loads(dumps_toml(cfg))) == cfg


def test_dataset_arrays_takes_the_sim_section():
    from quadfdi.formats.dataset import dataset_arrays

    with pytest.raises(TypeError, match=r"takes the \[sim\] section"):
        dataset_arrays({}, Config())
