"""The testbed as a domain model: its description (testbed files), its linear plant
model and transfer functions, and its friction slope table.

The simulator (sim/), the controller design (params/) and the analysis all read it;
it reads none of them.
"""
