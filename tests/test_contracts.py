"""Contracts written once: the channel table (stable ids) and the profiles derived from it, the class
table and its rotor-side flags, weights.bin's model codes, the alarm policy's keys and the ONE rule
that picks a network's policy (config, manifest, on-board record), and the one reader of an export
folder (formats/export_folder.py), including exports written before a key. The generated headers
and what the C++ compiles in: tests/test_parity.py ("contracts written once")."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.errors import QuadfdiError

# Pinned: an id never changes (a profile, a mask, weights.bin and the C++ name a channel by it).
CHANNEL_IDS = ["x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r", "V_b", "I_b", "SoC",
               "T1", "T2", "T3", "T4", "thr1", "thr2", "thr3", "thr4", "vib_px4", "rpm1", "rpm2", "rpm3", "rpm4",
               "esc_temp1", "esc_temp2", "esc_temp3", "esc_temp4", "esc_cur1", "esc_cur2", "esc_cur3", "esc_cur4",
               "vib_ap", "airborne"]
MIN_MODEL = ["roll", "pitch", "p", "q", "r", "vx_h", "vy_h", "vz", "v_cell", "i_rel", "m1_rel", "m2_rel", "m3_rel",
             "m4_rel", "vib"]
ESC_MODEL = [*MIN_MODEL, "rpm1_rel", "rpm2_rel", "rpm3_rel", "rpm4_rel", "esc1_i_rel", "esc2_i_rel", "esc3_i_rel",
             "esc4_i_rel", "esc1_t_rel", "esc2_t_rel", "esc3_t_rel", "esc4_t_rel"]


def test_channel_ids_are_stable_and_flight_columns_unchanged():
    from quadfdi.core import channels

    assert [c.name for c in channels.CHANNELS] == CHANNEL_IDS
    assert [c.id for c in channels.CHANNELS] == list(range(len(CHANNEL_IDS)))  # kChannelNames[id] in the C++
    assert channels.CHANNEL_NAMES == tuple(CHANNEL_IDS[:37])  # flight.npz's columns
    assert channels.SIM_CHANNEL_NAMES == tuple(CHANNEL_IDS[:23])
    assert {c.kind for c in channels.CHANNELS[37:]} == {"stream"} and channels.AIRBORNE == "airborne"
    header = channels.cpp_header()
    assert header.count("constexpr int kChannel") == len(CHANNEL_IDS) + 1  # one per channel and the count
    assert len(set(line.split("=")[0] for line in header.splitlines() if line.startswith("constexpr int kChannel"))) \
        == len(CHANNEL_IDS) + 1  # distinct C++ names


def test_profiles_are_channel_lists_over_the_table_and_their_model_channels_derived():
    from quadfdi.core.channels import CHANNEL_IDS as IDS, MODEL_CHANNELS, PROFILE_TABLE, profile_enum, stream_raw
    from quadfdi.core.profiles import PROFILES, channel_names, required_raw
    from quadfdi.formats.onboard import stream_channels

    assert [(p.id, p.name) for p in PROFILE_TABLE] == [(0, "paper"), (1, "flightlog-min"), (2, "flightlog-nocur"),
                                                        (3, "flightlog-esc"), (4, "flightlog-mask"),
                                                        (5, "flightlog-ref"), (6, "flightlog-phys")]
    assert [profile_enum(p.name) for p in PROFILE_TABLE] == ["kPaper", "kFlightlogMin", "kFlightlogNocur",
                                                             "kFlightlogEsc", "kFlightlogMask", "kFlightlogRef",
                                                             "kFlightlogPhys"]
    assert channel_names("flightlog-min", []) == MIN_MODEL and channel_names("flightlog-esc", []) == ESC_MODEL
    assert channel_names("flightlog-nocur", []) == [c for c in MIN_MODEL if c != "i_rel"]
    assert PROFILES["paper"] is None and channel_names("paper", ["a", "b"]) == ["a", "b"]
    for p in PROFILE_TABLE[1:]:
        assert all(r in IDS for r in p.raw)  # every raw channel is one of the table's
        assert required_raw(p.name) == list(p.raw)  # the declared list is complete (hover inputs included)
        assert stream_channels(p.name, []) == list(stream_raw(p))  # what the on-board record and the C++ name
        used = [r for c in p.model for r in c.raw]
        assert sorted(set(used)) == sorted(p.raw)  # every raw channel feeds a model channel
    # a model channel is in a profile exactly when the profile has its raw channels (the masked profile
    # then adds one availability channel per group: tests/test_masks.py)
    assert channel_names("flightlog-mask", [])[:len(ESC_MODEL) + 1] == ESC_MODEL[:15] + ["vib_ap"] + ESC_MODEL[15:]
    mask = set(PROFILE_TABLE[1].raw) - {"I_b"}
    assert [c.name for c in MODEL_CHANNELS if set(c.raw) <= mask and not c.reference] == \
        channel_names("flightlog-nocur", [])


def test_classes_and_rotor_side_are_one_table():
    from quadfdi.core import alarm, contracts
    from quadfdi.models.motor import rotor_side

    names = list(contracts.KNOWN_CLASSES)
    assert contracts.CLASS_NAMES == ("Healthy", "BatteryFault", "MotorFault", "OverheatFault")
    assert contracts.ROTOR_SIDE_CLASSES == ("MotorFault", "OverheatFault", "PropellerFault")
    assert rotor_side(names).tolist() == alarm.rotor_columns(names).tolist() == [False, False, True, True, True]
    assert alarm.ROTOR_SIDE_CLASSES is contracts.ROTOR_SIDE_CLASSES


def test_model_codes_and_policy_keys_are_one_table():
    from quadfdi.core import contracts
    from quadfdi.core.alarm import AlarmConfig
    from quadfdi.formats import binfmt, onboard

    assert binfmt.MODELS is contracts.MODEL_CODES and binfmt.PRECISIONS is contracts.PRECISION_CODES
    assert contracts.MODEL_CODES == {"none": 0, "cnode": 1, "gru": 2, "cnode_motor": 16, "gru_motor": 17, "sgru": 18}
    assert onboard.POLICY_MODELS == {"cnode": 1, "gru": 2, "sgru": 18}
    fields = [(f.name, f.type) for f in dataclasses.fields(AlarmConfig)][:len(contracts.POLICY_KEYS)]
    assert fields == [(n, t.__name__) for n, t, _ in contracts.POLICY_FIELDS]  # AlarmConfig's order and types
    assert list(AlarmConfig().policy()) == list(contracts.POLICY_KEYS)
    assert contracts.ALARM_POLICY_COLUMNS == ("k", "n", "clear_m", "latch", "healthy")
    assert contracts.ALARM_MODELS_COLUMNS == ("model", "k", "n", "clear_m", "latch", "threshold_lo", "threshold_hi")
    assert contracts.cpp_policy_values({"threshold": 0.1 + 0.2, "k": 2, "n": 3, "clear_m": 4, "latch": True}) == \
        "0.30000000000000004, 2, 3, 4, true"
    header = contracts.cpp_header()
    assert "struct AlarmParams {\n  double threshold;" in header and "constexpr std::uint32_t kModelSgru = 18;" in header


DEFAULT = {"threshold": 0.5, "k": 2, "n": 3, "clear_m": 3, "latch": False}
SINGLE = {"threshold": 0.8, "k": 1, "n": 2, "clear_m": 4, "latch": True}
GRU = {"threshold": 0.3, "k": 3, "n": 5, "clear_m": 2, "latch": False}


def test_one_rule_picks_a_networks_policy_for_config_manifest_and_record():
    """The network's own entry, else the single policy, else the defaults: the same answer from the
    config, from a manifest (and one written before each key) and from the on-board record."""
    from quadfdi.core.alarm import AlarmConfig, resolve_policy
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.onboard import policy_of

    cfg = AlarmConfig(**SINGLE, gru={"threshold": 0.3, "k": 3, "n": 5, "clear_m": 2, "latch": False})
    manifest = Export(Path("x"), {"alarm": SINGLE, "alarm_per_model": {"gru": {"policy": GRU, "source": "config"}}})
    record = {"alarm": SINGLE, "alarm_models": {"gru": GRU}}
    assert cfg.policy_for("gru") == manifest.policy("gru")[0] == policy_of(record, "gru")[0] == GRU
    assert cfg.policy_for("cnode") == manifest.policy("cnode")[0] == policy_of(record, "cnode")[0] == SINGLE
    assert manifest.policy("gru")[1] == "config" and manifest.policy("cnode")[1] == "manifest alarm"
    assert policy_of(record, "gru")[1] == "alarm.models" and policy_of(record, "cnode")[1] == "alarm.policy"
    assert AlarmConfig(threshold=0.9, gru={"k": 1}).policy_for("gru") == {**DEFAULT, "threshold": 0.9, "k": 1}
    # exports written before the per-network policies, and before the policy itself
    assert Export(Path("x"), {"alarm": SINGLE}).policy("gru") == (SINGLE, "manifest alarm")
    assert Export(Path("x"), {}).policy("cnode") == (DEFAULT, "manifest alarm")
    assert policy_of({"alarm": SINGLE, "alarm_models": None}, "gru") == (SINGLE, "alarm.policy")
    assert list(resolve_policy("gru", {"gru": {"latch": True, "threshold": 0.7}}, None)[0]) == list(DEFAULT)
    with pytest.raises(QuadfdiError, match=r"manifest alarm \(gru\)\.k and .* must satisfy 1 <= k <= n"):
        Export(Path("x"), {"alarm_per_model": {"gru": {"policy": {**GRU, "k": 9}, "source": "config"}}}).policy("gru")


def test_an_export_without_a_profile_is_paper_and_artifacts_are_inside_the_folder():
    from quadfdi.formats.export_folder import Export

    ex = Export(Path("/e"), {"artifacts": {"cnode_fp32": "cnode.onnx"}, "class_names": ["Healthy", "MotorFault"]})
    assert ex.profile() == "paper" and ex.artifact("cnode", "fp32") == Path("/e/cnode.onnx")
    assert not ex.has_motor("cnode") and ex.rotor_side().tolist() == [False, False]
    with pytest.raises(QuadfdiError, match="lists no artifact gru_int8"):
        ex.artifact("gru", "int8")


# ----------------------------------------------------------------------- the reader on a real export


@pytest.fixture()
def export_copy(fault_exported, tmp_path) -> Path:
    dst = tmp_path / "export"
    shutil.copytree(fault_exported / "export", dst)
    return dst


def test_export_reader_on_a_real_export(export_copy):
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.export_folder import read_record

    ex = Export.open(export_copy)
    m = ex.manifest
    assert ex.profile() == "paper" and ex.window == m["window"] and ex.steps == m["solver"]["steps"] == 2
    assert ex.artifact("gru", "int8").is_file() and ex.weights().has("cnode", "fp32")
    rec = ex.onboard()
    assert rec == read_record(export_copy / "weights.bin") and rec["profile"] == "paper"
    assert rec["channels"] == ex.channel_names and rec["alarm"] == m["alarm"]
    for net in ("cnode", "gru"):
        assert ex.policy(net) == (m["alarm_per_model"][net]["policy"], "config")


def _rewrite(export: Path, name: str, data: bytes, *, relist: bool) -> None:
    """Replace a file of the export; ``relist``: also its manifest entry (an export written that way)."""
    (export / name).write_bytes(data)
    if relist:
        m = json.loads((export / "manifest.json").read_text())
        m["files"][name] = {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}
        (export / "manifest.json").write_text(json.dumps(m, indent=2))


def test_export_reader_refusals_are_one_line(export_copy, tmp_path):
    from quadfdi.formats.binfmt import pack, read_file
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.weights_layout import MAGIC, VERSION

    with pytest.raises(QuadfdiError, match="does not exist"):
        Export.open(tmp_path / "nowhere")
    _, sections = read_file(export_copy / "weights.bin", MAGIC, VERSION, "weights file")
    old = pack(MAGIC, VERSION, sections[:-1])  # a weights.bin written before the on-board record
    _rewrite(export_copy, "weights.bin", old, relist=False)
    with pytest.raises(QuadfdiError, match="weights.bin does not match its sha256") as exc:
        Export.open(export_copy)
    assert "\n" not in str(exc.value)
    _rewrite(export_copy, "weights.bin", old, relist=True)
    ex = Export.open(export_copy)  # an old export still opens; its models are read as before
    assert ex.weights().has("gru", "int8") and ex.policy("gru")[0] == ex.manifest["alarm_per_model"]["gru"]["policy"]
    with pytest.raises(QuadfdiError, match=r"weights.bin has no on-board record \(exported before it") as exc:
        ex.onboard()
    assert "\n" not in str(exc.value)


def test_stream_file_cli_refuses_an_export_without_the_record(export_copy, fault_exported, tmp_path):
    from quadfdi.cli import main
    from quadfdi.formats.binfmt import pack, read_file
    from quadfdi.formats.weights_layout import MAGIC, VERSION

    _, sections = read_file(export_copy / "weights.bin", MAGIC, VERSION, "weights file")
    _rewrite(export_copy, "weights.bin", pack(MAGIC, VERSION, sections[:-1]), relist=True)
    out = tmp_path / "s.bin"
    assert main(["stream-file", "--model", str(export_copy), "--dataset", str(fault_exported / "dataset.npz"),
                 "--flight", "0", "--out", str(out)]) == 2
    assert not out.exists()


def test_rotor_side_of_a_manifest_with_a_head():
    from quadfdi.formats.export_folder import Export

    names = ["Healthy", "BatteryFault", "MotorFault", "OverheatFault", "PropellerFault"]
    ex = Export(Path("x"), {"class_names": names, "motor_head": {"models": ["gru"],
                                                                "rotor_side_classes": ["MotorFault", "PropellerFault"]}})
    assert ex.has_motor("gru") and not ex.has_motor("cnode")
    assert np.array_equal(ex.rotor_side(), [False, False, True, False, True])  # the manifest's list, as written
