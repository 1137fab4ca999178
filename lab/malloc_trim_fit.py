"""One gradient-boosted fit as the baselines make them (HistGradientBoostingClassifier, 100 iterations of 15
leaves, one thread) on 24,000 random windows of 150 features; prints its wall and CPU seconds. Run it as is and
under Dask's nanny setting to see what glibc's memory trimming costs a job:

    python lab/malloc_trim_fit.py
    MALLOC_TRIM_THRESHOLD_=65536 python lab/malloc_trim_fit.py
"""

from __future__ import annotations

import time

import numpy as np
from sklearn.ensemble import HistGradientBoostingClassifier
from threadpoolctl import threadpool_limits


def main() -> None:
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(24000, 150)).astype(np.float32), rng.integers(0, 5, 24000)
    with threadpool_limits(1):
        t, c = time.perf_counter(), time.process_time()
        HistGradientBoostingClassifier(max_iter=100, max_leaf_nodes=15, early_stopping=False, random_state=0).fit(x, y)
        print(f"wall {time.perf_counter() - t:.1f} s, CPU {time.process_time() - c:.1f} s")


if __name__ == "__main__":
    main()
