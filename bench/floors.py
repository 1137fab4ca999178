"""Each model's latency floor on this machine, and how far each runtime is from it.

floor = max(compute, memory) for one window at batch 1, where

- compute = 2 * MACs / peak: the deployed graph's multiply-accumulates (manifest ``models.<m>.
  macs_per_window``) at the measured single-core peak (``limits.peak_gflops`` for fp32,
  ``limits.peak_int8_gops`` for int8);
- memory = bytes / ``limits.l2_gbps``: the weight bytes that must stream in from L2 for one
  window. A set of weights that is reused across iterations (the CNODE's field weights, 4N
  evaluations; the GRU's recurrent weights, W steps) is read once if it fits L1d, else once per
  iteration ("the GRU's fp32 recurrent weights do not fit a 32 KiB L1"). Weights used once per
  window (the CNODE's interpolation matrix, encoder, the u-part of lin1, head; the GRU's input
  weights, which one (W, C) x (C, 3H) product can apply to the whole window, and head) are read
  once. Biases, scales and normalisation vectors are float32 and counted once with them.

The floor is a lower bound over implementations, not a model of any one of them: the C++
reference computes the GRU's input product step by step (same bytes in total, as the input
weights of one step fit L1), ONNX Runtime's graphs do their own thing. All sizes come from the
architecture in the export manifest (``models.<m>``: n_channels, window, latent, hidden,
n_classes) and the solver's N.
"""

from __future__ import annotations

from typing import Iterable

FP32_BYTES = 4


def cnode_macs(arch: dict, evals: int) -> int:
    """MACs of a CNODE forward with ``evals`` field evaluations (models.networks.CNODE.macs_breakdown:
    encoder C*L, field ((L + C) * H + H * L) per evaluation, head L * K)."""
    c, l, h, k = arch["n_channels"], arch["latent"], arch["hidden"], arch["n_classes"]
    return c * l + int(evals) * ((l + c) * h + h * l) + l * k


def weight_traffic(arch: dict, precision: str, steps: int, l1_bytes: int) -> dict:
    """Bytes of weights one window must stream from L2 (see the module doc), with the parts.

    Returns {once_bytes, reused_bytes, reuse_count, reused_fits_l1, bytes_per_window}.
    """
    w = 1 if precision == "int8" else FP32_BYTES
    f = FP32_BYTES
    c, k, win = arch["n_channels"], arch["n_classes"], arch["window"]
    if arch["kind"] == "cnode":
        l, h = arch["latent"], arch["hidden"]
        s = 2 * steps + 1  # distinct stage times of classic RK4
        once = (s * win + l * c + h * c + k * l) * w + (2 * c + l + h + k) * f
        reused = (h * l + l * h) * w + (h + l) * f  # lin1_z, lin2 and their biases
        count = 4 * steps
    elif arch["kind"] == "gru":
        h = arch["hidden"]
        once = (3 * h * c + k * h) * w + (2 * c + 3 * h + k) * f  # W_ih, head; mean, std, b_ih, head bias
        reused = 3 * h * h * w + 3 * h * f  # W_hh and b_hh
        count = win
    else:
        raise ValueError(f"unknown model kind {arch.get('kind')!r}")
    fits = reused <= l1_bytes
    return {"once_bytes": once, "reused_bytes": reused, "reuse_count": count, "reused_fits_l1": fits,
            "bytes_per_window": once + reused * (1 if fits else count)}


def floor_of(macs: int, traffic_bytes: int, peak_gops: float, l2_gbps: float) -> dict:
    """compute_us, memory_us, floor_us (the larger) and which one bounds."""
    if not (peak_gops > 0 and l2_gbps > 0):
        raise ValueError(f"peak and bandwidth must be positive, found {peak_gops} and {l2_gbps}")
    compute = 2.0 * macs / (peak_gops * 1e3)  # GOP/s = 1e3 OP/us
    memory = traffic_bytes / (l2_gbps * 1e3)  # GB/s = 1e3 B/us
    return {"compute_us": compute, "memory_us": memory, "floor_us": max(compute, memory),
            "bound": "compute" if compute >= memory else "L2 bandwidth"}


def floors(models: dict, steps: int, limits: dict) -> list[dict]:
    """One floor per (model, precision) from the manifest's ``models`` and bench.json's ``limits``."""
    l1 = int(limits.get("caches", {}).get("L1d", 32 * 1024))
    out = []
    for kind in ("cnode", "gru"):
        arch = {"kind": kind, **models[kind]}
        macs = int(models[kind]["macs_per_window"])
        for precision in ("fp32", "int8"):
            peak = limits["peak_int8_gops"] if precision == "int8" else limits["peak_gflops"]
            traffic = weight_traffic(arch, precision, steps, l1)
            out.append({"model": kind, "precision": precision, "macs_per_window": macs,
                        "weight_bytes_per_window": traffic["bytes_per_window"], "traffic": traffic,
                        "peak_gops": peak, "l2_gbps": limits["l2_gbps"], "l1_bytes": l1,
                        **floor_of(macs, traffic["bytes_per_window"], peak, limits["l2_gbps"])})
    return out


def floor_for(floor_list: Iterable[dict], model: str, precision: str) -> dict | None:
    return next((f for f in floor_list if f["model"] == model and f["precision"] == precision), None)


def attach_distance(records: list[dict], floor_list: list[dict]) -> None:
    """Add ``floor_us`` and ``x_floor`` (p50 / floor) to every batch-1 latency record, in place."""
    for r in records:
        f = floor_for(floor_list, r["model"], r["precision"])
        if r["batch"] == 1 and f is not None and r.get("p50_us"):
            r["floor_us"] = f["floor_us"]
            r["x_floor"] = r["p50_us"] / f["floor_us"]


def below_floor(records: list[dict]) -> list[dict]:
    """Batch-1 records measured faster than their floor: the floor is then not a lower bound (a
    probe read the machine low, or the traffic model is wrong), and no target may lean on it."""
    return [r for r in records if r.get("batch") == 1 and r.get("x_floor") is not None and r["x_floor"] < 1.0]


def violation_text(records: list[dict]) -> str:
    """One line naming each runtime below its floor."""
    return "; ".join(f"{r['runtime']} {r['model']} {r['precision']} p50 {r['p50_us']:.1f} us < floor "
                     f"{r['floor_us']:.1f} us ({r['x_floor']:.2f}x)" for r in records)


def _pick(records: list[dict], **match) -> list[dict]:
    return [r for r in records if all(r.get(k) == v for k, v in match.items()) and r.get("p50_us")]


def targets(records: list[dict], floor_list: list[dict]) -> list[dict]:
    """The latency targets, each {target, model, precision, measured, threshold, met, detail,
    cpp_p50_us, and floor_us or ort_p50_us}.

    - C++ CNODE and GRU batch-1 p50 within 2x of their floor (fp32 and int8 each against its own);
    - C++ CNODE at least 10x faster than ONNX Runtime at batch 1, against ORT at one thread
      without spinning (the like-for-like single-core setting) and against ORT's best setting.
    """
    out = []
    broken = below_floor(records)
    for model in ("cnode", "gru"):
        for precision in ("fp32", "int8"):
            cpp = _pick(records, runtime="cpp", model=model, precision=precision, batch=1)
            f = floor_for(floor_list, model, precision)
            if not cpp or f is None:
                continue
            x = cpp[0]["p50_us"] / f["floor_us"]
            bad = [r for r in broken if r["model"] == model and r["precision"] == precision]
            detail = f"p50 {cpp[0]['p50_us']:.1f} us, floor {f['floor_us']:.2f} us ({f['bound']})"
            if bad:  # a floor some runtime beats is no floor: the target cannot be met against it
                detail += f"; FLOOR INVALID: {violation_text(bad)}"
            out.append({"target": "C++ batch-1 p50 within 2x of the floor", "model": model, "precision": precision,
                        "measured": x, "threshold": 2.0, "met": x <= 2.0 and not bad, "cpp_p50_us": cpp[0]["p50_us"],
                        "floor_us": f["floor_us"], "floor_valid": not bad, "detail": detail})
    for precision in ("fp32", "int8"):
        cpp = _pick(records, runtime="cpp", model="cnode", precision=precision, batch=1)
        ort = _pick(records, runtime="ort", model="cnode", precision=precision, batch=1)
        if not cpp or not ort:
            continue
        c = cpp[0]["p50_us"]
        like = [r for r in ort if r["threads"] == 1 and r.get("spinning") is False] or ort
        best = min(ort, key=lambda r: r["p50_us"])
        pairs = [("ORT 1 thread, no spinning", like[0])] + ([("ORT best setting", best)] if best is not like[0] else [])
        for label, o in pairs:
            ratio = o["p50_us"] / c
            out.append({"target": f"C++ CNODE >= 10x faster than {label} at batch 1", "model": "cnode",
                        "precision": precision, "measured": ratio, "threshold": 10.0, "met": ratio >= 10.0,
                        "cpp_p50_us": c, "ort_p50_us": o["p50_us"],
                        "detail": f"ORT p50 {o['p50_us']:.1f} us ({o['threads']} thread(s), spinning "
                                  f"{'on' if o.get('spinning') else 'off'}), C++ p50 {c:.1f} us"})
    return out
