"""``sweep_bench.json`` and ``sweep_bench.md``: the scaling measured by ``quadfdi sweep bench``."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.atomic import write_text
from quadfdi.core.jsonio import write_json
from quadfdi.core.tables import md_table


def bench_markdown(r: dict) -> str:
    rows = []
    for name, w in r["workloads"].items():
        rows.append([name, w["jobs"], f"{w['serial_s']:.1f}", f"{w['hand_2proc_s']:.1f}", f"{w['dask_2workers_s']:.1f}",
                     f"{w['speedup_hand']:.2f}x", f"{w['speedup_dask']:.2f}x", f"{100 * w['efficiency_vs_hand']:.0f} %",
                     "yes" if w["bytes_identical"] else "NO"])
    s = r["scheduler"]
    lines = [f"`{r['command']}` on {r['cores']} cores (load average {r['load_avg_before']:.1f} before, "
             f"{r['load_avg_after']:.1f} after; the machine was shared); Dask intervals: "
             f"{'Dask defaults' if r.get('dask_config') == 'defaults' else 'quadfdi coarse-job settings'}.", "",
             *md_table(["workload", "jobs", "1 worker (s)", "2 processes by hand (s)", "Dask, 2 workers (s)",
                        "speed-up by hand", "speed-up Dask", "Dask / by hand (throughput)", "same bytes"], rows),
             f"Scheduler cost: {s['dask_ms_per_job']:.1f} ms of worker time per job on the 2-worker cluster "
             f"({s['dask_wall_ms_per_job']:.1f} ms wall), against {s['in_process_ms_per_job']:.2f} ms in-process "
             f"({s['jobs']} empty jobs). Cluster start-up (not in the times above): {r['cluster_start_s']:.1f} s.", "",
             *[f"CPU of the Dask way beyond the jobs' own ({name}): {w['dask_overhead_cpu_s']:.1f} CPU-s "
               f"({w['cpu_dask_s']:.1f} for the scheduler, client, nannies and workers against {w['cpu_serial_s']:.1f} "
               f"serially), {100 * w['dask_overhead_cpu_s'] / (2 * w['dask_2workers_s']):.1f} % of the 2 cores."
               for name, w in r["workloads"].items() if "dask_overhead_cpu_s" in w], ""]
    return "\n".join(lines)


def write_bench(out: Path, result: dict) -> list[Path]:
    js, md = out / "sweep_bench.json", out / "sweep_bench.md"
    write_json(js, result)
    write_text(md, bench_markdown(result))
    print(bench_markdown(result))
    return [js, md]
