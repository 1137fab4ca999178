"""Timing loops of ``quadfdi.bench.latency_worker``, one per runtime (pytorch, ort, cpp; common: statistics and
process memory). They time the adapters of ``quadfdi.runtimes``; they do not define their own."""
