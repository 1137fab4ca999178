"""``quadfdi ingest``: real PX4 ULog, ArduPilot DataFlash and Crazyflie uSD-card flight logs -> ``flight.npz`` (docs/flight_format.md).

One job per module: ``model`` (channel table, the read result), ``frames`` (NED/FRD -> the
simulator's z-up frames), ``motors`` (geometry, motor order, command normalisation), ``battery``
(cell count), ``segments`` (armed / airborne intervals, refusals), ``px4`` and ``ardupilot``
(the two readers), ``resample`` (anti-aliased 25 Hz grid with masks), ``flight`` (assemble and
write the file), ``bench`` (throughput), ``cli``.
"""
