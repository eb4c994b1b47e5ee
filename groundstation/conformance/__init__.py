"""Protocol conformance suite: checks derived from protocol/SPEC.md, run against any
device over the raw wire (`groundstation conformance`, docs/firmware.md)."""
