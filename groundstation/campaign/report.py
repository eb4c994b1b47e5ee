"""What a campaign run leaves: each step's result and the campaign's report, saved as
JSON (read back by `--resume`) and as text for the operator."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from .model import CampaignError
from .run_setup import resume_command


@dataclass
class StepResult:
    index: int
    label: str
    status: str                       # "done", "failed", "skipped", "aborted"
    seconds: float = 0.0
    error: str = ""


@dataclass
class CampaignReport:
    campaign: str
    file: str
    started: float
    finished: float = 0.0
    status: str = "running"           # "completed", "completed_with_failures", "failed", "aborted",
    #                                   "interrupted" (Ctrl-C)
    failed_step: int | None = None    # 0-based index
    failed_run: int | None = None
    reason: str = ""
    steps: list[StepResult] = field(default_factory=list)
    recordings: list[dict[str, Any]] = field(default_factory=list)
    completed_runs: list[int] = field(default_factory=list)
    failed_runs: dict[str, str] = field(default_factory=dict)     # run number -> reason
    report_file: str = ""             # where save() wrote it (named in the resume hint)
    #: how it was run (device, fast, fast_sim, seed, testbed, log_folder): a resume takes
    #: these (run_setup.py); {} in reports written before they were kept
    setup: dict[str, Any] = field(default_factory=dict)

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        self.report_file = str(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(asdict(self), indent=2) + "\n")
        path.with_suffix(".txt").write_text(self.summary() + "\n")
        return path

    @classmethod
    def load(cls, path: str | Path) -> "CampaignReport":
        try:
            doc = json.loads(Path(path).read_text())
            doc["steps"] = [StepResult(**s) for s in doc.get("steps", [])]
            return cls(**doc)
        except (OSError, ValueError, TypeError) as exc:
            raise CampaignError(f"{path}: not a campaign report ({exc})") from None

    def summary(self) -> str:
        done = sum(1 for s in self.steps if s.status == "done")
        lines = [f"campaign {self.campaign}: {self.status.upper()} - {done} step(s) done, "
                 f"{len(self.completed_runs)} run(s) complete, {self.finished - self.started:.1f} s"]
        for run, why in sorted(self.failed_runs.items(), key=lambda kv: int(kv[0])):
            lines.append(f"run {run} failed: {why}")
        if self.failed_step is not None:
            lines.append(f"stopped at step {self.failed_step + 1}"
                         + (f" (run {self.failed_run})" if self.failed_run else "") + f": {self.reason}")
            if self.status == "interrupted":
                lines.append("interrupted by the operator (Ctrl-C): the rig was made safe (ABORT, "
                             "generator off) and the run's log closed with that reason")
            lines.append(f"resume with: {resume_command(self.file, self.report_file, self.setup)}")
        for rec in self.recordings:
            lines.append(f"  log {', '.join(Path(f).name for f in rec.get('files', []))}: "
                         f"{rec.get('frames', 0)} frames, {rec.get('discarded_blocks', 0)} blocks discarded"
                         + (f", {rec['dropped']} frames dropped on the link" if rec.get("dropped") else ""))
        return "\n".join(lines)
