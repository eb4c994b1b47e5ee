"""The analysis's vocabulary - the sensors it scores and the metrics it computes - in a
module without numerics, so a campaign file or a command line is checked against it
without importing scipy (about half a second at every start: docs/campaigns.md)."""

from __future__ import annotations

#: the sensors a log's pointing can be scored on
SENSORS = ("autocollimator", "los_estimate", "encoder_inner")
DEFAULT_SENSOR = "autocollimator"           # the reference's scoring sensor
#: the sensor chosen per log by its testbed: the relative set-up has no autocollimator
#: (nor IMU), its pointing is the inner encoder's; the inertial one scores the mirror
AUTO_SENSOR = "auto"
#: the metrics computed by default
METRICS = ("jitter", "energy", "psd")

__all__ = ["AUTO_SENSOR", "DEFAULT_SENSOR", "METRICS", "SENSORS"]
