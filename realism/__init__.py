"""``quadfdi realism``: hold the simulator's telemetry against real flights on steady segments."""
