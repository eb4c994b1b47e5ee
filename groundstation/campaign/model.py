"""The campaign as typed records: the campaign itself, its steps, and the error that
lists what is wrong with a campaign file.  No I/O and no knowledge of the actions."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.errors import GroundStationError


class CampaignError(GroundStationError):
    """A campaign file is malformed or asks for values the rig must not be given; every
    problem found names the file, the step and the field (`problems`, one per line of
    the message)."""

    def __init__(self, message: str, problems: list[str] | None = None):
        super().__init__(message)
        self.problems = list(problems) if problems else [message]


@dataclass
class Step:
    index: int                       # position in the whole campaign, 0-based
    phase: str                       # "setup", "run", "teardown"
    run: int                         # 1-based run number (0 in setup/teardown)
    action: str
    args: dict[str, Any]
    variables: dict[str, Any]
    position: int = 0                # 1-based position within its phase (within a run)

    def label(self) -> str:
        where = f"run {self.run}" if self.run else self.phase
        return f"step {self.index + 1} ({where}): {self.action}"

    def where(self) -> str:
        """'run 2 step 4 (dwell)', 'setup step 1 (connect)': how problems name a step."""
        head = f"run {self.run}" if self.run else self.phase
        return f"{head} step {self.position} ({self.action})"


#: the campaign's reference metrics an [analysis] table may ask for (`metrics = [...]`),
#: named as `groundstation analyze --metrics` names them (campaign/reference_metrics.py)
REFERENCE_METRICS = ("step", "frf", "hysteresis", "friction_velocity")


@dataclass(frozen=True)
class AnalysisSpec:
    """A campaign's optional `[analysis]` table: how its logs are scored after the runs
    (campaign/metrics.py).  Without the table every log is scored over its whole length
    with the defaults and nothing is compared.  `metrics` names the campaign's reference
    metrics (REFERENCE_METRICS), computed per log beside jitter and energy."""

    start_after_mark: str = ""           # the scored window starts at this mark ('' : the log's start)
    duration_s: float | None = None      # window length (None: to the log's end)
    sensor: str = "autocollimator"
    integration_period_s: float = 1.0
    group_by: str = ""                   # a matrix key: one comparison per value
    compare: str = ""                    # a matrix key: the values compared in each group
    baseline: Any = None                 # the value of `compare` (as in [matrix]) others are relative to
    metrics: tuple[str, ...] = ()        # reference metrics per log (REFERENCE_METRICS)
    #: a window with more than this fraction excluded is not valid (None: the analysis
    #: default, analysis/validity.py MAX_EXCLUDED_FRACTION)
    max_excluded_fraction: float | None = None
    given: bool = False                  # the file has an [analysis] table

    def as_dict(self) -> dict[str, Any]:
        return {"start_after_mark": self.start_after_mark, "duration_s": self.duration_s,
                "sensor": self.sensor, "integration_period_s": self.integration_period_s,
                "group_by": self.group_by, "compare": self.compare, "baseline": self.baseline,
                "metrics": list(self.metrics), "max_excluded_fraction": self.excluded_limit()}

    def excluded_limit(self) -> float:
        """The excluded fraction above which a window is not valid."""
        if self.max_excluded_fraction is not None:
            return self.max_excluded_fraction
        from ..analysis.validity import MAX_EXCLUDED_FRACTION   # plain Python, no numpy
        return MAX_EXCLUDED_FRACTION


@dataclass
class Campaign:
    path: Path
    name: str
    description: str
    testbed: Path
    matrix: dict[str, list[Any]]
    steps: list[Step]
    runs: int
    on_run_failure: str = "stop"
    analysis: AnalysisSpec = field(default_factory=AnalysisSpec)
