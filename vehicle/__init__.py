"""``quadfdi vehicle``: a reference of one airframe, learned from its own healthy flights, and the
simple reference rules that score other flights against it (docs/vehicle.md).

What a caller may use: ``learn.learn`` (flights -> the reference, formats/vehicle.py),
``flights.read_flight`` / ``find_flights`` (a log or flight.npz -> a Flight), ``rules.thresholds``,
``rules.score_flight`` and ``rules.score_paths`` (the four share rules), ``compare.compare`` (one
flight's quantities against a reference, for ``quadfdi detect --vehicle``), ``crazypad.label`` and
``crazypad.table`` (the CrazyPAD protocol's groups and table).
One job per module: ``flights`` (reading), ``quantities`` (per-sample quantities), ``stats`` (spreads,
disagreement), ``fits`` (least-squares models), ``learn``, ``compare`` (a flight against a reference), ``rules``,
``crazypad``, ``rules_report`` (markdown), ``cli``.
"""
