"""The configs quadfdi ships: each ``<name>.toml`` here is ``--config <name>`` on any command
(``paper``: the paper's Table 2, ``realistic``: the realistic scenario suite, ``realistic-mask``: its
dataset trained with the masked profile, ``fleet``: vehicles flown many times, docs/fleet.md). Read through
``quadfdi.core.resources``; a package only so that the wheel carries the files."""
