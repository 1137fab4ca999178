"""One adapter per timed runtime of ``bench.latency_worker``: torch_rt, ort_rt, cpp_rt (+ common)."""
