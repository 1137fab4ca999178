"""bench.json's ``memory`` list: what each model costs to store and to run (SPEC section 6).

One record per number: ``{model, runtime, precision, solver, item, value, unit, source}``
(``model`` / ``runtime`` / ``precision`` / ``solver`` are null where a number is not specific to
one). Items:

- ``parameters`` (count): trainable parameters of the checkpoint (normalisation buffers excluded);
- ``file_bytes``: the checkpoint (torch), each ONNX file (ort), weights.bin (cpp; it holds all four
  model sections);
- ``baseline_rss_bytes``, ``peak_rss_above_baseline_batch1_bytes``,
  ``peak_rss_above_baseline_batch96_bytes``: the runtime's own process (bench.latency_worker):
  the baseline is the resident set after the runtime library is imported and the windows loaded,
  the peak is VmHWM after the batch-1 (then batch-96) loop, the mark reset at the baseline; for
  the C++ program, GNU time's peak of a one-window run minus that of ``fwref_infer --help``. From
  the 1-thread, spinning-off worker of each setting;
- ``static_ram_bytes`` (and ``data_bytes``, ``bss_bytes``): the host C++ program's statically
  allocated RAM, ``size -A`` of fwref_infer (.data + .bss; on the host the weights and the
  workspace are on the heap, counted in its peak RSS);
- ``flash_bytes``, ``static_ram_bytes``, ``stack_peak_bytes``, ``weights_bytes`` of the Cortex-M
  images (runtime ``cortex-m4`` / ``cortex-m7``), copied from ``runs/<name>/parity/mcu.json``
  when the parity stage wrote it.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from quadfdi.core.reportmd import optional_json

MCU_ITEMS = ("flash_bytes", "weights_bytes", "static_ram_bytes", "stack_peak_bytes")


def rec(model, runtime, precision, item: str, value, unit: str, source: str, solver: str | None = None) -> dict:
    return {"model": model, "runtime": runtime, "precision": precision, "solver": solver, "item": item,
            "value": value, "unit": unit, "source": source}


def parameter_counts(run_root: Path) -> dict[str, int]:
    """Trainable parameters per model kind, from the checkpoints (normalisation buffers excluded)."""
    from quadfdi.models.checkpoint import load_checkpoint

    out = {}
    for kind in ("cnode", "gru"):
        path = run_root / f"{kind}.pt"
        if path.is_file():
            model, _ = load_checkpoint(path, kind)
            out[kind] = int(sum(p.numel() for p in model.parameters()))
    return out


def file_records(run_root: Path, manifest: dict) -> list[dict]:
    out = []
    for kind in ("cnode", "gru"):
        p = run_root / f"{kind}.pt"
        if p.is_file():
            out.append(rec(kind, "torch", "fp32", "file_bytes", p.stat().st_size, "bytes", str(p.name)))
        for precision in ("fp32", "int8"):
            name = manifest["artifacts"][f"{kind}_{precision}"]
            out.append(rec(kind, "ort", precision, "file_bytes", manifest["files"][name]["bytes"], "bytes",
                           f"export/{name}"))
    if "weights.bin" in manifest["files"]:
        out.append(rec(None, "cpp", None, "file_bytes", manifest["files"]["weights.bin"]["bytes"], "bytes",
                       "export/weights.bin (all four sections)"))
    return out


def rss_records(runtime_memory: list[dict]) -> list[dict]:
    """Peak-RSS records from the latency workers (1 thread, spinning off or n/a only)."""
    out = []
    for m in runtime_memory:
        if m["threads"] != 1 or m.get("spinning") is True:
            continue
        src = f"bench.latency_worker ({m.get('method', '')})"
        if m.get("baseline_kib") is not None:
            out.append(rec(m["model"], m["runtime"], m["precision"], "baseline_rss_bytes", m["baseline_kib"] * 1024,
                           "bytes", src, m["solver"]))
        for key, item in (("peak_batch1_above_baseline_kib", "peak_rss_above_baseline_batch1_bytes"),
                          ("peak_batch_above_baseline_kib", "peak_rss_above_baseline_batch96_bytes")):
            if m.get(key) is not None:
                out.append(rec(m["model"], m["runtime"], m["precision"], item, m[key] * 1024, "bytes", src,
                               m["solver"]))
    return out


def static_ram_records(fwref: str | None) -> list[dict]:
    if not fwref:
        return []
    exe = shutil.which("size")
    if exe is None:
        return []  # no binutils: the host program's static RAM is not reported
    from quadfdi.runtimes.mcu import section_sizes

    s = section_sizes(fwref, exe)
    data = s.get(".data", 0) + s.get(".tdata", 0)
    bss = s.get(".bss", 0) + s.get(".tbss", 0)
    src = "size -A fwref_infer"
    return [rec(None, "cpp", None, "static_ram_bytes", data + bss, "bytes", src + " (.data + .bss)"),
            rec(None, "cpp", None, "data_bytes", data, "bytes", src),
            rec(None, "cpp", None, "bss_bytes", bss, "bytes", src),
            rec(None, "cpp", None, "text_bytes", s.get(".text", 0), "bytes", src)]


def mcu_records(run_root: Path) -> tuple[list[dict], dict | None]:
    """Cortex-M flash / RAM / stack records from parity/mcu.json, and the file's content (None if absent)."""
    mcu = optional_json(run_root / "parity" / "mcu.json", "Cortex-M results")
    if mcu is None:
        return [], None
    out = []
    for cpu, r in (mcu.get("cpus") or {}).items():
        for key, m in (r.get("models") or {}).items():
            model, _, precision = key.partition("_")
            for item in MCU_ITEMS:
                if m.get(item) is not None:
                    out.append(rec(model, cpu, precision, item, m[item], "bytes", "parity/mcu.json"))
    return out, mcu


def memory_records(run_root: Path, manifest: dict, runtime_memory: list[dict], fwref: str | None) -> list[dict]:
    """The whole ``memory`` list (see the module doc)."""
    out = [rec(kind, None, None, "parameters", n, "count", f"{kind}.pt")
           for kind, n in parameter_counts(run_root).items()]
    out += file_records(run_root, manifest)
    out += rss_records(runtime_memory)
    out += static_ram_records(fwref)
    out += mcu_records(run_root)[0]
    return out
