"""The ground floor: what every stage shares and nothing else.

Config (one TOML; core composes the sections the stages declare, core/sections.py), errors, atomic
file output, deterministic npz and strict JSON, the run folder's file names, markdown tables, headless
plotting, and the cross-language contracts (classes, split codes, the RK4 program, parity
tolerances). This package imports no stage and no app module; stages import it, and the app layer
(``quadfdi``) sits on top of both.
"""
