"""bench.json's ``stream`` section: the streaming runtime's cost per sample.

``stream_section(run_root, export, fwref_infer, cpus, flights, log)`` replays ``flights`` test flights
of the run's dataset (round-robin over the classes, written as stream files by formats.stream)
through ``fwref_stream`` (the host build beside fwref_infer) for every windowed model (cnode, gru)
and precision (fp32, int8), pinned like the rest of the bench:

- ``latency`` (bench.stream_latency): per push without a decision and per decided push, p50 / p99
  / max microseconds, from fwref_stream's own ``--timings``;
- ``memory`` (bench.stream_memory): sizeof(fwref::Stream) with the model's limits on the host and
  the Cortex-M cores, and the stream image when one was built.

``{"skipped": reason}`` when the export has no on-board record (exported before it), no
fwref_stream can be found or built, or ``flights`` is 0. The CPU flags are bench.json's ``machine``.
"""

from __future__ import annotations

import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path


from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import flights_by_class
from quadfdi.formats.export_folder import Export




def find_stream_exe(fwref_infer: str | None) -> tuple[Path | None, str]:
    """fwref_stream beside fwref_infer (the same host build), built there if missing."""
    import shutil

    from quadfdi.runtimes.build import host_build_dir

    build = Path(fwref_infer).parent if fwref_infer else host_build_dir()
    exe = build / "fwref_stream"
    if exe.is_file():
        return exe, f"{exe} (existing build)"
    cmake = shutil.which("cmake")
    if cmake is None or not (build / "CMakeCache.txt").is_file():
        return None, f"no {exe} and no configured build to make it in"
    res = subprocess.run([cmake, "--build", str(build), "-j2", "--target", "fwref_stream"], capture_output=True,
                         text=True, timeout=900, check=False)
    return (exe, f"built {exe}") if res.returncode == 0 and exe.is_file() else (None, f"building {exe} failed")


def stream_section(run_root: Path, export: Export, fwref_infer: str | None, cpus: str, flights: int,
                   log: Callable[[str], None] = print, cores: tuple[str, ...] = ("cortex-m4", "cortex-m7")) -> dict:
    """The section (module docstring) of the opened export folder ``export`` (formats.export_folder);
    ``cores``: the Cortex-M cores whose sizeof is compiled."""
    from quadfdi.bench.limits import cpu_prefix
    from quadfdi.bench.stream_latency import latency_records
    from quadfdi.bench.stream_memory import stream_memory
    from quadfdi.parity.stream import vehicle_records
    from quadfdi.formats.stream import from_dataset, write_stream
    from quadfdi.formats import dataset as sim_dataset

    t0 = time.perf_counter()
    if flights <= 0:
        return {"skipped": "bench.stream_flights = 0"}
    try:
        record = export.onboard()
    except QuadfdiError as exc:  # an export written before the record
        return {"skipped": str(exc)}
    exe, how = find_stream_exe(fwref_infer)
    if exe is None:
        return {"skipped": f"no fwref_stream: {how}"}
    dataset_path = run_root / "dataset.npz"
    ds = sim_dataset.load_dataset(dataset_path)  # one load for every flight
    rows = flights_by_class(ds, flights)
    vehicles = vehicle_records(ds, record["profile"], rows)  # a reference profile's: each flight's vehicle record
    with tempfile.TemporaryDirectory(prefix="quadfdi-stream-bench-") as d:
        tmp = Path(d)
        paths = []
        for f in rows:
            paths.append(tmp / f"f{f}.bin")
            write_stream(paths[-1], from_dataset(dataset_path, f, record, ds, vehicles[f]))
        try:
            latency = latency_records(exe, export.weights_path, paths, tmp, cpu_prefix(cpus))
            memory = stream_memory(record, export, exe, cores)
        except subprocess.CalledProcessError as exc:  # a failed replay or compile skips the section, not the bench
            err = (exc.stderr or "").strip().splitlines()
            prog = next((Path(str(c)).name for c in exc.cmd if "taskset" not in str(c) and not str(c).startswith("-")
                         and not str(c)[:1].isdigit()), "?")
            return {"skipped": f"{prog} failed: {err[-1] if err else exc.returncode}"}
    seconds = time.perf_counter() - t0
    log(f"bench stream: {len(rows)} test flights x 4 models through {exe.name} in {seconds:.1f} s")
    return {"exe": how, "profile": record["profile"], "window": int(record["window"]), "stride": int(record["stride"]),
            "sample_dt_s": float(record["sample_dt_s"]), "flights": rows, "latency": latency, "memory": memory,
            "seconds": seconds}
