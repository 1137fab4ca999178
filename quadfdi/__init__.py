"""quadfdi: physics-based fault diagnosis of quadrotors, from simulation to a Cortex-M build.

This package is the app layer: the ``quadfdi`` command-line dispatcher, ``quadfdi run`` (every
stage in order) and the run report. No stage imports it. What the stages share (config, atomic
I/O, contracts) is the ground floor, ``core``.
"""

__version__ = "0.1.0"
