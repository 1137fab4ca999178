"""The int8 targets ("int8 that pays"), read from one bench's latency records so that every
ratio compares runtimes measured in the same run (bench.json ``targets``, next to the latency targets from
bench.floors.targets):

- C++ int8 no slower than C++ fp32 at batch 1, both models; the GRU's int8 at least 1.5x faster. The
  ratio is the median of bench.cpp_pairs' per-round ratios (both precisions in one fwref_pair process);
  without ``cpp_pairs`` (a build without fwref_pair) the latency records' pooled p50s;
- C++ int8 within 3x of its floor at batch 1 (fp32's 2x is the latency targets' row), no runtime below its floor;
- ONNX Runtime at one thread without spinning (the like-for-like single-core setting): at batch 96
  int8 faster than fp32, at batch 1 int8 within 2x of fp32, both models. The ratio is the median of
  the per-round ratios of bench.ort_pairs (both graphs in one process, calls interleaved: its doc says
  why); a bench.json without ``ort_pairs`` falls back to the latency records' separate p50s.

Each row is {target, model, precision, measured, threshold, met, detail} like bench.floors.targets';
``measured`` is the ratio the threshold applies to (a speed-up, or a slowdown where the target bounds
one). A pair of records the bench did not measure gives no row.
"""

from __future__ import annotations

from quadfdi.bench.floors import below_floor, floor_for

INT8_FLOOR_X = 3.0  # int8 within 3x of its floor (fp32: 2x, the latency targets' row)
GRU_INT8_SPEEDUP = 1.5  # the C++ GRU int8 at least 1.5x faster than its fp32
ORT_BATCH1_SLOWDOWN = 2.0  # ORT int8 at batch 1 within 2x of fp32


def _p50(records: list[dict], runtime: str, model: str, precision: str, batch: int) -> float | None:
    for r in records:
        if (r.get("runtime"), r.get("model"), r.get("precision"), r.get("batch")) != (runtime, model, precision, batch):
            continue
        if runtime == "ort" and (r.get("threads") != 1 or r.get("spinning") is not False):
            continue  # like-for-like: one thread, no spinning
        if r.get("p50_us"):
            return float(r["p50_us"])
    return None


def _row(target: str, model: str, precision: str, measured: float, threshold: float, met: bool, detail: str) -> dict:
    return {"target": target, "model": model, "precision": precision, "measured": measured, "threshold": threshold,
            "met": bool(met), "detail": detail}


def _pair(pairs: dict | None, model: str, batch: int) -> dict | None:
    """``model``'s summary at ``batch`` in bench.json's ``ort_pairs`` or ``cpp_pairs`` (None: not measured)."""
    got = (pairs or {}).get(model)
    return next((p for p in got if p.get("batch") == batch and p.get("rounds")), None) if isinstance(got, list) else None


def _ort_ratio(records: list[dict], pairs: dict | None, model: str, batch: int) -> tuple[float, str] | None:
    """(int8 / fp32 time, how it was measured) at ``batch``: the paired rounds if there, else the p50s."""
    p = _pair(pairs, model, batch)
    if p is not None:
        return p["int8_over_fp32_median"], (
                f"ORT 1 thread, spinning off, batch {batch}, fp32 and int8 interleaved in one process, {p['rounds']} "
                f"rounds: int8 / fp32 time median {p['int8_over_fp32_median']:.2f} (rounds' p10-p90 "
                f"{p['int8_over_fp32_p10']:.2f}-{p['int8_over_fp32_p90']:.2f}); p50 fp32 {p['fp32_p50_us']:.1f} us, "
                f"int8 {p['int8_p50_us']:.1f} us")
    o32, o8 = _p50(records, "ort", model, "fp32", batch), _p50(records, "ort", model, "int8", batch)
    if not (o32 and o8):
        return None
    return o8 / o32, (f"ORT 1 thread, spinning off, batch {batch}, separate processes: p50 fp32 {o32:.1f} us, "
                      f"int8 {o8:.1f} us")


def _cpp_speedup(records: list[dict], pairs: dict | None, model: str) -> tuple[float, str] | None:
    """(int8 speed-up over fp32, how it was measured) at batch 1: the paired rounds if there, else the p50s."""
    p = _pair(pairs, model, 1)
    if p is not None:
        return 1 / p["int8_over_fp32_median"], (
                f"C++ fp32 and int8 in one process (fwref_pair), {p['rounds']} rounds: int8 / fp32 time median "
                f"{p['int8_over_fp32_median']:.3f} (rounds' p10-p90 {p['int8_over_fp32_p10']:.2f}-"
                f"{p['int8_over_fp32_p90']:.2f}); p50 fp32 {p['fp32_p50_us']:.1f} us, int8 {p['int8_p50_us']:.1f} us")
    f32, i8 = _p50(records, "cpp", model, "fp32", 1), _p50(records, "cpp", model, "int8", 1)
    if not (f32 and i8):
        return None
    return f32 / i8, f"C++ p50 fp32 {f32:.1f} us, int8 {i8:.1f} us (separate processes, pooled)"


def int8_targets(records: list[dict], floor_list: list[dict], pairs: dict | None = None,
                 cpp_pairs: dict | None = None) -> list[dict]:
    """The rows above; ``pairs``: bench.json's ``ort_pairs`` (bench.ort_pairs.measure_ort_pairs),
    ``cpp_pairs``: its ``cpp_pairs`` (bench.cpp_pairs.measure_cpp_pairs)."""
    out = []
    broken = below_floor(records)
    for model in ("cnode", "gru"):
        i8 = _p50(records, "cpp", model, "int8", 1)
        got = _cpp_speedup(records, cpp_pairs, model)
        if got is not None:
            need = GRU_INT8_SPEEDUP if model == "gru" else 1.0
            out.append(_row(f"C++ int8 >= {need:g}x as fast as fp32 at batch 1", model, "int8", got[0], need,
                            got[0] >= need, got[1]))
        f = floor_for(floor_list, model, "int8")
        if i8 and f is not None:
            bad = [r for r in broken if r["model"] == model and r["precision"] == "int8"]
            x = i8 / f["floor_us"]
            out.append(_row(f"C++ int8 batch-1 p50 within {INT8_FLOOR_X:g}x of the floor", model, "int8", x,
                            INT8_FLOOR_X, x <= INT8_FLOOR_X and not bad,
                            f"p50 {i8:.1f} us, floor {f['floor_us']:.2f} us ({f['bound']})"
                            + ("; FLOOR INVALID: a runtime beat it" if bad else "")))
        for batch in (96, 1):
            got = _ort_ratio(records, pairs, model, batch)
            if got is None:
                continue
            slow, detail = got
            if batch == 96:
                out.append(_row("ORT int8 faster than fp32 at batch 96", model, "int8", 1 / slow, 1.0, slow < 1,
                                detail))
            else:
                out.append(_row(f"ORT int8 within {ORT_BATCH1_SLOWDOWN:g}x of fp32 at batch 1", model, "int8", slow,
                                ORT_BATCH1_SLOWDOWN, slow <= ORT_BATCH1_SLOWDOWN, detail))
    return out
