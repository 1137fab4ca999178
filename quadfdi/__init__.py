"""quadfdi: physics-based fault diagnosis of quadrotors, from simulation to a Cortex-M build.

The stages live in their own top-level packages (``sim``, ``train``, ``export``, ``bench``);
this package holds what they share: the config, atomic file output, errors and the CLI.
"""

__version__ = "0.1.0"
