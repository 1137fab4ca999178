"""``quadfdi detect``: an exported model on a real flight -> probabilities, alarms, one figure (docs/detect.md)."""
