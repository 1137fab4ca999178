"""The paper configuration's dataset, byte for byte: the realistic suite must leave it untouched.

The hash is of one numpy build on one CPU instruction set: numpy's transcendental functions
(sin, exp, sqrt is exact) take SIMD paths picked at run time, so another ISA or numpy version may
change last bits legitimately. There the test skips, naming what differs, instead of failing.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from quadfdi.core.machine import cpu_facts
from tests.conftest import ROOT, quadfdi

# `quadfdi sim --config configs/paper.toml --set sim.n_traj=24 --set sim.duration_s=8.0`, dataset.npz,
# recorded before the realistic suite was added (commit 2e70ecd) and after it.
GOLDEN_SHA256 = "907128522623692b9819d0500a7d8d05db5f6cc1fb81623aeec109f89a9a68a6"
GOLDEN_NUMPY = "2.4.6"
# core.machine.cpu_facts()['isa'] of the machines where numpy GOLDEN_NUMPY gave exactly these bytes: an AMD EPYC
# with AVX2 (where they were recorded) and an AMD EPYC with AVX-512 and VNNI.
GOLDEN_ISAS = (["sse4_2", "avx", "avx2", "fma", "f16c"],
               ["sse4_2", "avx", "avx2", "fma", "f16c", "avx512f", "avx512bw", "avx512vl", "avx512_vnni"])
# The full paper run (`--out /tmp/p0`, 240 x 16 s) hashed
# 1e53c0adb7e07fd4760bbb16b3426cc5db32b5572f4900f38f344f80cc99cd33 on both (too slow for a unit test; docs/realistic.md
# records the check).


def test_paper_dataset_golden_hash(tmp_path):
    isa = cpu_facts()["isa"]
    if np.__version__ != GOLDEN_NUMPY or isa not in GOLDEN_ISAS:
        pytest.skip(f"golden hash checked with numpy {GOLDEN_NUMPY} on ISAs {GOLDEN_ISAS}; "
                    f"this is numpy {np.__version__} on ISA {isa}")
    out = tmp_path / "p"
    res = quadfdi("sim", "--config", str(ROOT / "configs/paper.toml"), "--out", str(out),
                  "--set", "sim.n_traj=24", "--set", "sim.duration_s=8.0")
    assert res.returncode == 0, res.stderr
    digest = hashlib.sha256((out / "dataset.npz").read_bytes()).hexdigest()
    assert digest == GOLDEN_SHA256


def test_paper_dataset_has_no_realistic_keys(tmp_path):
    """The new [sim] keys stay out of a paper dataset's embedded config, and so do class/split names
    (readers fall back to the paper's); that is what keeps the golden bytes."""
    import dataclasses
    import json

    from quadfdi.core.config import Config
    from quadfdi.sim.config import SimConfig
    from quadfdi.formats.dataset import LATER_SIM_KEYS, class_names, dataset_arrays, split_names
    from quadfdi.sim.simulate import generate

    cfg = Config(sim=dataclasses.replace(SimConfig(), n_traj=4, duration_s=4.0, window=40, stride=5,
                                         onset_frac=(0.1, 0.3), ramp_frac=(0.2, 0.4)))
    arrays = dataset_arrays(generate(cfg.sim), cfg.sim)
    embedded = json.loads(str(arrays["config"]))["sim"]
    assert not set(LATER_SIM_KEYS) & set(embedded)
    assert "class_names" not in arrays and "split_names" not in arrays
    assert class_names(arrays) == ("Healthy", "BatteryFault", "MotorFault", "OverheatFault")
    assert split_names(arrays) == ("train", "validation", "test")
