"""firmware_ref's C++ sources (CMake project, headers, sources, Cortex-M files) as package data:
``quadfdi.runtimes.build`` copies them into the per-user cache and builds them there. A package only
so that the wheel carries the files; no Python code lives here."""
