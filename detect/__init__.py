"""``quadfdi detect``: an exported model on real flights -> probabilities, alarms, the evidence for each
alarm, a page per flight and a fleet index (docs/detect.md)."""
