"""``quadfdi evaluate``: the evaluation protocol and the alarm policy
over every prediction set a run's index lists (docs/evaluation.md).

Modules: load (index -> per-flight batches), outcomes (per-flight counts under a policy), metrics
(ratios of summed counts, Garwood), bootstrap (flight resampling, paired), policy (the validation
sweep and rule), ceiling (label noise), protocol (pooling, sets, pairs), figures, report, run, cli.
"""
