"""Limits a config is checked against before any compute: memory, firmware, threads."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.errors import QuadfdiError

# Bytes of dataset.npz per (trajectory, sample): telemetry, states, severity and the actuator
# arrays, float32 (measured: 24 trajectories x 200 samples make 1.28 MB). Generation holds the
# arrays and their serialized copy, so it needs about twice that in memory.
DATASET_BYTES_PER_SAMPLE = 270
FIRMWARE_MAX_STEPS = 64  # FWREF_MAX_STEPS of firmware_ref: the unrolled CNODE graph may not exceed it
MAX_THREADS = 256  # beyond any machine this runs on: 100000 threads once hung torch
# The firmware's capacities (firmware_ref/include/fwref/config.hpp's FWREF_MAX_* defaults; a test
# reads them there): a model larger than these cannot be deployed, so a config asking for one is
# refused before any compute instead of ending in an allocation failure.
MAX_LATENT = 128  # FWREF_MAX_LATENT
MAX_CNODE_HIDDEN = 256  # FWREF_MAX_CNODE_HIDDEN
MAX_GRU_HIDDEN = 256  # FWREF_MAX_GRU_HIDDEN
MAX_WINDOW = 256  # FWREF_MAX_WINDOW
MAX_BATCH = 65536  # windows or flights per batch: far above what fits a training step on this machine
MAX_EPOCHS = 100_000


def available_memory() -> int | None:
    """MemAvailable of /proc/meminfo in bytes (None where there is no such file)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def dataset_bytes(n_traj: int, n_samples: int) -> int:
    return n_traj * n_samples * DATASET_BYTES_PER_SAMPLE


def check_dataset_memory(n_traj: int, n_samples: int) -> None:
    """Refuse a dataset that cannot fit in memory before simulating a single trajectory."""
    need = 2 * dataset_bytes(n_traj, n_samples)
    avail = available_memory()
    if avail is not None and need > avail:
        raise QuadfdiError(f"sim.n_traj={n_traj} x {n_samples} samples needs about {need / 1e9:.1f} GB of memory, "
                           f"{avail / 1e9:.1f} GB are available: lower sim.n_traj or sim.duration_s")
