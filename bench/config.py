"""The [bench] section: how ``quadfdi bench`` measures latency (docs/bench.md)."""

from __future__ import annotations

from dataclasses import dataclass

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.limits import MAX_BATCH, MAX_THREADS
from quadfdi.core.sections import at_most, positive


@dataclass(frozen=True)
class BenchConfig:
    """Latency measurement settings of ``quadfdi bench`` (docs/bench.md); ``--quick`` replaces the
    counts with tiny ones and the thread counts with (1,)."""

    cpus: str = "0,1"  # CPUs every benchmark process is pinned to (taskset); --cpus overrides
    threads: tuple[int, ...] = (1, 2)  # intra-op thread counts timed (torch, ort)
    windows: int = 300  # batch-1 windows per setting, each timed once
    warmup: int = 30  # warm-up calls before each timed loop ...
    warmup_s: float = 1.0  # ... or this many seconds, whichever ends first
    batch: int = 96  # the batched setting's batch size
    batches: int = 10  # batched calls timed per setting
    budget_s: float = 8.0  # time budget of each timed loop (dopri5 is the one that hits it)
    min_samples: int = 5  # the budget never cuts a loop below this many calls
    profile_windows: int = 100  # windows run under the ORT per-node profiler
    callgrind_windows: int = 5  # windows run under valgrind callgrind (C++)
    worker_timeout_s: float = 900.0  # one worker process may take this long
    stream_flights: int = 10  # test flights replayed through fwref_stream (bench/stream.py); 0 skips; --quick: 1
    # A runtime below its floor after re-measuring: the floors are not lower bounds here, so the bench
    # exits non-zero (after writing bench.json); false only reports it (plumbing checks, not timings).
    fail_below_floor: bool = True

    def validate(self) -> None:
        positive(self, "windows", "warmup_s", "batch", "batches", "budget_s", "min_samples", "profile_windows",
                  "callgrind_windows", "worker_timeout_s")
        at_most(self, MAX_BATCH, "batch")
        if self.warmup < 0:
            raise QuadfdiError(f"bench.warmup must be 0 or more, found {self.warmup}")
        if self.stream_flights < 0:
            raise QuadfdiError(f"bench.stream_flights must be 0 or more, found {self.stream_flights}")
        if not self.threads or min(self.threads) < 1 or max(self.threads) > MAX_THREADS:
            raise QuadfdiError(f"bench.threads must be a non-empty list of counts in 1..{MAX_THREADS}, found {list(self.threads)}")
        parts = [c.strip() for c in self.cpus.split(",")]
        if not all(c.isdigit() for c in parts):
            raise QuadfdiError(f"bench.cpus must be a comma-separated list of CPU numbers, found {self.cpus!r}")
