"""Ground station for hybrid-flexure-bearing precision-pointing testbeds."""

__version__ = "0.1.0"
