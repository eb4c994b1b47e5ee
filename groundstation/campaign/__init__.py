"""Campaigns: a test procedure as data, run step by step on a `Testbed`, with a report.

A campaign file (`profiles/campaigns/*.toml`):

    [campaign]
    name = "relative_steps"
    testbed = "../testbeds/relative_2dof.toml"      # relative to this file

    [matrix]                                        # one run per combination, first key outermost
    design = ["../controllers/relative_design1.toml", "../controllers/relative_design2.toml"]

    [[setup]]                                       # once, before the runs
    action = "set_mode"
    mode = "RELATIVE"

    [[run]]                                         # for every combination of the matrix
    action = "upload_design"
    design = "{design}"
    ...

    [[teardown]]                                    # once, after the runs

`[campaign] on_run_failure = "next_run"` makes a failed run (a fault, a refused upload)
a result instead of the end: the rig is made safe, the fault acknowledged, that run's
recording closed, and the next run starts.  The default, "stop", ends the campaign.

Text values may use {campaign}, {run} (1, 2, ...), every matrix key, and {KEY_stem}
(the file name of a path without its extension).  Values naming files (`design`,
`profile`, `psd`) are relative to the campaign file.

`load_campaign` checks every step of every run before anything runs - the structure,
then every value against the protocol dictionary, the testbed's limits and the 4053B
generator's, and that every referenced file loads - and raises CampaignError listing
every problem ("FILE: run 2 step 4 (dwell): seconds = -5 - must be a finite number > 0").

On any failure or an abort the session is made safe (ABORT, generator off, recording
closed) and the report says which step stopped and why.  `resume` re-runs the setup
steps (they build the state a run needs), skips the runs that completed, and starts the
failed run again from its first step - a run's mode, table and recording are made by
its own steps, so half a run cannot be continued.

The package, one job per module:

- `model`: the records (Campaign, Step, CampaignError);
- `actions`: the registry of actions - each action's keys, its value check and what it
  does on the Testbed, one class per action (`ACTIONS`, `register`);
- `checks`: the helpers the value checks are written with (StepCheck);
- `reading`: the file read, the matrix expanded, every step checked (load_campaign);
- `runner`: the steps run on a Testbed, failures and Ctrl-C made safe (CampaignRunner);
- `report`: what a run leaves (CampaignReport, StepResult);
- `metrics`: every run's log scored with groundstation.analysis, grouped and compared
  with a baseline as the campaign's optional `[analysis]` table says (CSV, JSON, text);
- `report_figures`: the comparison's bar charts (matplotlib, PNG) and the
  self-contained HTML report.

`groundstation.campaign` names the package's public API (below).
"""

from __future__ import annotations

from .actions import ACTIONS, DURATION_KEYS, PATH_KEYS, Action, StepRun, known_actions, register
from .checks import CampaignChecker, StepCheck
from .model import Campaign, CampaignError, Step
from .reading import check_campaign, load_campaign, read_campaign
from .report import CampaignReport, StepResult
from .runner import CampaignRunner

__all__ = [
    "ACTIONS", "DURATION_KEYS", "PATH_KEYS", "Action", "Campaign", "CampaignChecker",
    "CampaignError", "CampaignReport", "CampaignRunner", "Step", "StepCheck", "StepResult",
    "StepRun", "check_campaign", "known_actions", "load_campaign", "read_campaign", "register",
]
