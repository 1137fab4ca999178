"""Limits a config is checked against before any compute: memory, firmware, threads."""

from __future__ import annotations

from pathlib import Path

# Bytes of dataset.npz per (trajectory, sample): telemetry, states, severity and the actuator
# arrays, float32 (measured: 24 trajectories x 200 samples make 1.28 MB). Generation holds the
# arrays and their serialized copy, so it needs about twice that in memory.
DATASET_BYTES_PER_SAMPLE = 270
FIRMWARE_MAX_STEPS = 64  # FWREF_MAX_STEPS of firmware_ref: the unrolled CNODE graph may not exceed it
MAX_THREADS = 256  # beyond any machine this runs on: 100000 threads once hung torch


def available_memory() -> int | None:
    """MemAvailable of /proc/meminfo in bytes (None where there is no such file)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None
