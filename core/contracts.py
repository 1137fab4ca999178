"""Contracts shared by Python and C++: classes (and which are rotor-side), split codes, the parity
tolerances, the RK4 constants, weights.bin's model and precision codes, and the alarm policy's keys
(their order, names and the C++ fwref::AlarmParams fields; the on-board record's columns).

Each is written here once (the channel table and the profiles: core/channels.py). The C++ side gets them from the generated header
``firmware_ref/include/fwref/contracts_gen.hpp`` (``python -m quadfdi.core.contracts --header``), and a test
checks that the committed header equals what this module generates.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable

from quadfdi.core.resources import firmware_sources
from quadfdi.core.rk4 import RK4_CONSTANT_NAMES, RK4_PROGRAM, RK4_C

# Every class quadfdi knows: (name, rotor-side). The paper's four first, in label order (label i =
# CLASS_NAMES[i]); the realistic suite adds PropellerFault. Rotor-side: the fault sits on one rotor
# (sim.realistic_faults: lost effectiveness, cooling or heat of rotor m's motor, rotor m's propeller),
# so an alarm of that class reports a motor (core.alarm rule 5) and the motor head learns on its
# windows (models.motor); a BatteryFault has none.
CLASS_TABLE: tuple[tuple[str, bool], ...] = (("Healthy", False), ("BatteryFault", False), ("MotorFault", True),
                                             ("OverheatFault", True), ("PropellerFault", True))
KNOWN_CLASSES: tuple[str, ...] = tuple(name for name, _ in CLASS_TABLE)
ROTOR_SIDE_CLASSES: tuple[str, ...] = tuple(name for name, rotor in CLASS_TABLE if rotor)
CLASS_NAMES: tuple[str, ...] = KNOWN_CLASSES[:4]  # the paper's
N_CLASSES = len(CLASS_NAMES)
CLASS_LABELS: tuple[int, ...] = tuple(range(N_CLASSES))
HEALTHY = 0

# Split codes stored in dataset.npz's ``split`` array.
SPLITS: dict[str, int] = {"train": 0, "validation": 1, "test": 2}
SPLIT_TRAIN, SPLIT_VALIDATION, SPLIT_TEST = SPLITS["train"], SPLITS["validation"], SPLITS["test"]

# Parity tolerances (docs/firmware.md, "Parity tolerances, and why"). Two fp32 tolerances, because
# they check different pairs:
# - the C++ reference against ONNX Runtime (`quadfdi parity`) and against PyTorch (reference.bin,
#   fwref_parity and the QEMU harness): max |diff| <= FP32_CPP_REL_TOL * max(1, max |reference|).
#   Eigen's blocked sums against MLAS sgemm and the rational tanh/sigmoid give ~1e-6 at |value| ~ 1;
#   the bound is two orders above that and far below a logit margin that could move an argmax.
# - ONNX Runtime against PyTorch when the export checks itself (export/verify.py): both evaluate the
#   same float32 program with library kernels, so the bound is ten times tighter; a failure stops
#   the export.
FP32_CPP_REL_TOL = 1e-4
FP32_ORT_VS_TORCH_REL_TOL = 1e-5
# int8, C++ against ONNX Runtime's int8 graph: argmax agreement at least INT8_ARGMAX_MIN, and every
# difference at most INT8_TOL_STEPS quantisation steps (for a logit: 127 * s_in * s_w[o], the largest
# change one step of one head input can make). Identical integer sums give 0 steps; the margin
# covers a runtime whose tanh/sigmoid round an ulp differently (GRU measured up to 5.4 steps).
INT8_ARGMAX_MIN = 0.999
INT8_TOL_STEPS = 8.0
# Where float32 rounding is amplified (a recurrence or ODE near a switch of its state), two correct float32
# programs part by more than an fp32 bound. The windows over it (or, in parity, with another argmax) are
# judged against the rounding itself (runtimes/pytorch.py `rounding_judgement`; docs/firmware.md): at most
# FP32_OVER_BOUND_SHARE of the windows (at least one), each within ROUNDING_FACTOR times the spread of
# ROUNDING_SAMPLES float64 evaluations with weights and inputs moved by up to one float32 ulp. On random
# GRUs driven to the edge of chaos (`PYTHONPATH=. python lab/export_rounding.py`, seeds 0-7: 239 windows
# over the bound, the spread drawn four times) a correct graph measured at most 2.8 times that spread, a
# graph with linear_before_reset=0 at least 10.4 (its first 64 windows of each of seeds 0-1); the factor
# lies between. Such a wrong graph puts every window over the bound and is stopped by the share first.
# A streaming network's export replays one flight step by step, its state carried: one ill-conditioned step
# takes the steps after it over the bound too, so there the share is of the flight's steps and wide
# (STREAM_OVER_BOUND_SHARE), each step still within ROUNDING_FACTOR spreads. On random streaming GRUs at the
# edge of chaos (`PYTHONPATH=. python lab/stream_rounding.py`: 48 flights of 1,500 steps) a correct graph
# put at most 0.455 of a flight's steps over the bound, 5,436 in all, at most 5.45 spreads from float64
# (99.9 % within 4.93); the graph with linear_before_reset=0 every step, each flight's largest at least
# 2.9e6 spreads.
FP32_OVER_BOUND_SHARE = 0.001
STREAM_OVER_BOUND_SHARE = 0.5
ROUNDING_SAMPLES = 16
ROUNDING_FACTOR = 6.0

TOLERANCES: dict[str, float] = {"fp32_cpp_rel_tol": FP32_CPP_REL_TOL,
                                "fp32_ort_vs_torch_rel_tol": FP32_ORT_VS_TORCH_REL_TOL,
                                "int8_argmax_min": INT8_ARGMAX_MIN, "int8_tol_steps": INT8_TOL_STEPS}

# Section codes of the tensor-record container (formats/binfmt.py: each section's ``model`` and
# ``precision`` fields). 16.. are the optional sections: the motor heads (formats/weights_layout.py)
# and the streaming GRU (its own file, formats/sgru_weights.py). A new code is a new entry here.
MODEL_CODES: dict[str, int] = {"none": 0, "cnode": 1, "gru": 2, "cnode_motor": 16, "gru_motor": 17, "sgru": 18}
PRECISION_CODES: dict[str, int] = {"none": 0, "fp32": 1, "int8": 2}
_PRECISION_CPP = {"none": "kPrecNone", "fp32": "kPrecF32", "int8": "kPrecI8"}

# One alarm policy (core/alarm.py): key, type, meaning. In this order: AlarmConfig's fields, the keys
# of the manifest's ``alarm`` dicts and of [alarm.<net>] tables, and fwref::AlarmParams' first fields.
POLICY_FIELDS: tuple[tuple[str, type, str], ...] = (
    ("threshold", float, "p_fault >= threshold votes (0 < threshold <= 1)"),
    ("k", int, "votes among ..."),
    ("n", int, "... the last n windows raise (1 <= k <= n)"),
    ("clear_m", int, "consecutive non-voting windows clear (>= 1)"),
    ("latch", bool, "never clear once raised"),
)
POLICY_KEYS: tuple[str, ...] = tuple(f[0] for f in POLICY_FIELDS)
POLICY_TYPES: dict[str, type] = {name: typ for name, typ, _ in POLICY_FIELDS}
# The networks that may have a policy of their own ([alarm.<net>], the manifest's ``alarm_per_model``,
# the on-board record's ``alarm.models`` rows, which name the network by its model code).
POLICY_NETWORKS: tuple[str, ...] = ("cnode", "gru", "sgru")
# The on-board record's int32 policy tensors (formats/onboard.py): the integer keys in POLICY_FIELDS
# order (a bool as 0/1), the float64 threshold as two words, low first, in its own tensor or columns.
_INT_KEYS = tuple(name for name, typ, _ in POLICY_FIELDS if typ is not float)
ALARM_POLICY_COLUMNS: tuple[str, ...] = _INT_KEYS + ("healthy",)  # alarm.policy (5,)
ALARM_MODELS_COLUMNS: tuple[str, ...] = ("model",) + _INT_KEYS + ("threshold_lo", "threshold_hi")  # alarm.models (M, 7)
# fwref::AlarmParams after the policy's keys: name, C++ type, meaning, default ("" none).
_ALARM_PARAMS_MORE = (("healthy", "int", "the Healthy class's column", ""), ("classes", "int", "K", ""),
                      ("rotor_mask", "std::uint32_t", "bit c: class c's alarm reports a motor (rule 5, alarm.rotor_side); "
                       "all bits: rule 4 alone", "0xFFFFFFFFu"))
_CPP_TYPE = {float: "double", int: "int", bool: "bool"}


def cpp_policy_values(policy: dict) -> str:
    """A policy's values as the first initializers of a fwref::AlarmParams, in POLICY_FIELDS order
    (what the Cortex-M stream generator compiles in): ``0.5, 2, 3, 3, false``."""
    text = {float: lambda v: repr(float(v)), int: lambda v: str(int(v)), bool: lambda v: "true" if v else "false"}
    return ", ".join(text[typ](policy[name]) for name, typ, _ in POLICY_FIELDS)


# In firmware_ref's sources, found as package data (a checkout: the tracked firmware_ref/include/fwref/).
HEADER_PATH = firmware_sources() / "include" / "fwref" / "contracts_gen.hpp"


def _camel(name: str) -> str:
    return "k" + "".join(p[:1].upper() + p[1:] for p in name.split("_"))


def _cpp_list(values) -> str:
    return "{" + ", ".join(values) + "}"


def _alarm_params() -> str:
    """fwref::AlarmParams: the policy's keys in POLICY_FIELDS order, then _ALARM_PARAMS_MORE."""
    rows = [(name, _CPP_TYPE[typ], doc, "") for name, typ, doc in POLICY_FIELDS] + list(_ALARM_PARAMS_MORE)
    out = []
    for name, typ, doc, default in rows:
        out.append(f"  {typ} {name}{' = ' + default if default else ''};  // {doc}")
    return "\n".join(out)


def _code_switch(codes: dict[str, int]) -> str:
    return " : ".join(f'code == {v}u ? "{k}"' for k, v in codes.items()) + " : nullptr"


def _codes_and_policy() -> str:
    """The part of the header in namespace fwref: section codes, their names, AlarmParams."""
    models = "\n".join(f"constexpr std::uint32_t kModel{_camel(k)[1:]} = {v};" for k, v in MODEL_CODES.items())
    precs = "\n".join(f"constexpr std::uint32_t {_PRECISION_CPP[k]} = {v};" for k, v in PRECISION_CODES.items())
    nets = " || ".join(f"code == {MODEL_CODES[n]}u" for n in POLICY_NETWORKS)
    return f"""// Section codes of weights.bin / reference.bin (formats/binfmt.py's ``model`` and ``precision``).
{models}
{precs}
// A section code's name (core/contracts.py MODEL_CODES), nullptr for a code this build does not know.
constexpr const char* model_code_name(std::uint32_t code) {{ return {_code_switch(MODEL_CODES)}; }}
constexpr const char* precision_code_name(std::uint32_t code) {{ return {_code_switch(PRECISION_CODES)}; }}
// Whether the model code names a network that may have its own alarm policy (alarm.models' first column).
constexpr bool policy_network(std::uint32_t code) {{ return {nets}; }}

// One alarm policy as fwref/alarm.hpp runs it: the policy's keys (core/contracts.py POLICY_FIELDS, in
// that order), then what the bound model adds.
struct AlarmParams {{
{_alarm_params()}
}};"""


def cpp_header() -> str:
    """The text of fwref/contracts_gen.hpp."""
    tol = "\n".join(f"constexpr double {_camel(k)} = {v!r};" for k, v in TOLERANCES.items())
    names = ", ".join(f'"{n}"' for n in CLASS_NAMES)
    splits = "\n".join(f"constexpr int kSplit{k.capitalize()} = {v};" for k, v in SPLITS.items())
    consts = "\n".join(f"constexpr int kRk4{_camel(n)[1:]} = {i};" for i, n in enumerate(RK4_CONSTANT_NAMES))
    rk4_names = ", ".join(f'"{n}"' for n in RK4_CONSTANT_NAMES)
    program = "\n".join(f"//   {line}" for line in RK4_PROGRAM)
    known = ", ".join(f'"{n}"' for n in KNOWN_CLASSES)
    rotor = ", ".join("true" if r else "false" for _, r in CLASS_TABLE)
    keys = ", ".join(f'"{k}"' for k in POLICY_KEYS)
    policy_cols = "\n".join(f"constexpr int kAlarmPolicy{_camel(c)[1:]} = {i};" for i, c in enumerate(ALARM_POLICY_COLUMNS))
    models_cols = "\n".join(f"constexpr int kAlarmModels{_camel(c)[1:]} = {i};" for i, c in enumerate(ALARM_MODELS_COLUMNS))
    return f"""// GENERATED by `python -m quadfdi.core.contracts --header` from core/contracts.py and core/rk4.py; do not edit.
// Classes, split codes, parity tolerances, the RK4 evaluation program, weights.bin's section codes and
// the alarm policy's keys, shared with Python.
#pragma once

#include <cstdint>

namespace fwref {{
namespace contracts {{

// Classes, in label order (the paper's).
constexpr int kNumClasses = {N_CLASSES};
constexpr const char* kClassNames[kNumClasses] = {{{names}}};
// Every class quadfdi knows and whether it is rotor-side (its alarm reports a motor: core.alarm rule 5).
constexpr int kNumKnownClasses = {len(KNOWN_CLASSES)};
constexpr const char* kKnownClassNames[kNumKnownClasses] = {{{known}}};
constexpr bool kRotorSide[kNumKnownClasses] = {{{rotor}}};

// One alarm policy's keys (AlarmParams' first fields), and the networks that may have their own.
constexpr int kPolicyKeyCount = {len(POLICY_KEYS)};
constexpr const char* kPolicyKeys[kPolicyKeyCount] = {{{keys}}};
constexpr int kPolicyNetworkCount = {len(POLICY_NETWORKS)};
constexpr const char* kPolicyNetworks[kPolicyNetworkCount] = {_cpp_list(f'"{n}"' for n in POLICY_NETWORKS)};
// The on-board record's alarm.policy int32 (kAlarmPolicyWidth,) and alarm.models int32 (M, kAlarmModelsWidth):
{policy_cols}
constexpr int kAlarmPolicyWidth = {len(ALARM_POLICY_COLUMNS)};
{models_cols}
constexpr int kAlarmModelsWidth = {len(ALARM_MODELS_COLUMNS)};

// Split codes of dataset.npz's ``split`` array.
{splits}

// Parity tolerances (core/contracts.py says which pair each one checks).
{tol}

// Classic RK4 as every implementation evaluates it (core/rk4.py RK4_PROGRAM), in this order:
{program}
// The float32 constants, in the order weights.bin's ``rk4.consts`` holds them.
constexpr int kRk4StagesPerStep = {len(RK4_C)};
constexpr int kRk4NumConsts = {len(RK4_CONSTANT_NAMES)};
{consts}
constexpr const char* kRk4ConstNames[kRk4NumConsts] = {{{rk4_names}}};

}}  // namespace contracts

{_codes_and_policy()}

}}  // namespace fwref
"""


def header_cli(argv: list[str], default: Path, text: Callable[[], str], module: str) -> int:
    """``python -m <module> --header [PATH]``: write a generated header (default: the committed one)."""
    if argv[:1] != ["--header"] or len(argv) > 2:
        print(f"usage: python -m {module} --header [PATH]   (default: {default.name}, the committed header)",
              file=sys.stderr)
        return 1
    path = Path(argv[1]) if len(argv) == 2 else default
    path.write_text(text())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(header_cli(sys.argv[1:], HEADER_PATH, cpp_header, "quadfdi.core.contracts"))
