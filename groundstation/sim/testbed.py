"""Moved to groundstation/plant/testbed.py (the testbed is the domain model, not the
simulator's).  This name stays only until the generator modules import it from there."""

from ..plant.testbed import *  # noqa: F401,F403
from ..plant.testbed import DEFAULT_TESTBED, PROFILES_DIR, TESTBEDS_DIR, Testbed, load_testbed  # noqa: F401
