"""The function-generator tab: the panel (instrument side and base-motion side), the
controller that talks to the instrument on a worker thread, its job queue and records."""
