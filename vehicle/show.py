"""``quadfdi vehicle show VEHICLE_JSON``: what a reference holds, as text a reader checks before trusting it
(docs/formats.md, "Vehicle reference"): the flights it rests on, each motor's share with its spreads, the
share model and the range it was fitted on (what a flight is covered by: coverage.py), the hover
collective, the pack, vibration, ESC and motor temperature quantities, and the warnings ``learn`` gave.
"""

from __future__ import annotations

from quadfdi.vehicle.coverage import WHAT, flown_text


def _num(x, fmt: str = ".3f", none: str = "-") -> str:
    return none if x is None else format(x, fmt)


def _spread(stat: dict) -> str:
    """'between flights B, within a flight W, a flight's mean to +- se' of a combined statistic."""
    parts = [f"between flights {_num(stat.get('between_std'))}" if stat.get("between_std") is not None
             else "one flight: no between-flight spread"]
    if stat.get("within_std") is not None:
        parts.append(f"within a flight {_num(stat['within_std'])}")
    if stat.get("se") is not None:
        parts.append(f"a flight's mean to +-{_num(stat['se'])}")
    return ", ".join(parts)


def _header(ref: dict, name: str) -> list[str]:
    veh = ref["vehicle"]
    flights = ref["flights"]
    total = sum(f["airborne_s"] for f in flights)
    return [f"{name}: vehicle reference, format {ref['format_version']}; {veh['autopilot']}, frame "
            f"{veh.get('frame')}, {veh.get('cells') or 'unknown'} cell(s), motor map {veh['motor_map']}",
            f"learned from {len(flights)} healthy flight(s), {total:.1f} s airborne: "
            + ", ".join(f"{f['file']} ({f['airborne_s']:.1f} s)" for f in flights)]


def _shares(ref: dict) -> list[str]:
    out = ["motor command shares (airborne, all four commands; 1 = the mean of the four):"]
    out += [f"  rotor {m['rotor']} ({m['log_motor']}): {_num(m['mean'])}; {_spread(m)}" for m in ref["motor_share"]]
    model = ref["share_model"]
    if not model.get("motors"):
        return out + [f"share model: none ({model.get('why', 'no steady samples')})"]
    names = model["regressors"]
    flown = flown_text(model) if names else "no regressor logged"
    out.append(f"share model over {model['motors'][0]['seconds']:.1f} s of steady samples; 5-95 % {flown}"
               + (f"; yaw rate from {', '.join(model['yaw_rate_source'])}" if "yaw_rate" in names else ""))
    for m in model["motors"]:
        terms = "".join(f" {m[f'per_{n}']:+.3f} per {WHAT[n][1]}" for n in names)
        out.append(f"  rotor {m['rotor']} ({m['log_motor']}): {m['intercept']:.3f}{terms}, scatter "
                   f"{m['residual_std']:.3f}")
    return out


def _hover(ref: dict) -> list[str]:
    cmd = ref["hover"]["cmd"]
    held = sum(x is not None for x in cmd["flights"])
    out = [f"hover collective {_num(cmd['mean'])} (between flights {_num(cmd['between_std'])}; {held} of "
           f"{len(cmd['flights'])} flights hold a steady hover)"]
    cur = ref["hover"]["cur_a"]
    if cur["mean"] is not None:
        out.append(f"hover current {cur['mean']:.2f} A (between flights {_num(cur['between_std'], '.2f')})")
    return out


def _battery(ref: dict) -> list[str]:
    bat = ref.get("battery")
    if not bat:
        return ["pack: no model (a flight logs no pack voltage or cell count)"]
    line = (f"pack, {bat['cells']} cell(s), per cell: v0 {_num(bat['v0']['mean'])} V, drift "
            f"{_num(bat['drift_v_per_min']['mean'])} V/min")
    if bat["mode"] == "sag":
        line += (f", sag {_num(bat['sag_v_per_a']['mean'], '.4f')} V/A (between flights "
                 f"{_num(bat['sag_v_per_a']['between_std'], '.4f')})")
    else:
        line += "; no sag per ampere (no current that moves)"
    return [line]


def _others(ref: dict) -> list[str]:
    out = []
    for name, v in ref["vibration"].items():
        out.append(f"vibration {name}: floor {_num(v['floor']['mean'], '.2f')} + "
                   f"{_num(v['per_collective']['mean'], '.2f')} x collective {v['unit']} (level "
                   f"{_num(v['level']['mean'], '.2f')}; {_spread(v['level'])})")
    for key, v in ref["esc"].items():
        out.append(f"ESC {key} ({v['unit']}): " + ", ".join(f"{m['log_motor']} {_num(m['mean'])}" for m in v["motors"]))
    if ref.get("motor_temp"):
        out.append("motor temperature offsets (K): " + ", ".join(f"{m['log_motor']} {_num(m['mean'], '+.2f')}"
                                                                 for m in ref["motor_temp"]))
    return out


def show(ref: dict, name: str) -> str:
    """The reference as text (the module docstring)."""
    lines = _header(ref, name) + _shares(ref) + _hover(ref) + _battery(ref) + _others(ref)
    lines.append(f"warnings ({len(ref['warnings'])}):" if ref["warnings"] else "warnings: none")
    lines += [f"  {w}" for w in ref["warnings"]]
    return "\n".join(lines)
