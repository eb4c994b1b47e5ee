"""The design workbench: the PQ method interactively - design editor, the model of what
is shown, plots, and the worker processes that compute the slow views."""
