"""The numerics of a campaign's design uploads done before its first run.

Uploading a design discretises it and samples the plant to check the closed loop
(params/loop.py).  Those results are kept on disk (core/numerics_cache.py), but a design
not seen before needs scipy.signal and scipy.linalg imported to compute them: about 0.4 s
of CPU.  `campaign run` calls this after its check, while the simulator's child starts
on the other core (sim/launch_ahead.py) and the command would otherwise only wait, so a
new design costs its imports there instead of inside the first run, and a known one
costs a few milliseconds.

Only time moves: nothing here decides anything.  A design that cannot be discretised or
checked raises nothing here; its upload step says so in its place, as it always did.
"""

from __future__ import annotations

from .model import Campaign


def discretise_designs_ahead(campaign: Campaign, dictionary) -> int:
    """Discretise every design the campaign uploads and sample its loop's plant, each
    file once; how many were done."""
    from ..params.design_file import load_design
    from ..params.loop_response import loop_model

    paths = dict.fromkeys(str(s.args["design"]) for s in campaign.steps
                          if s.action == "upload_design" and "design" in s.args)
    done = 0
    for path in paths:
        try:
            loop_model(load_design(path), dictionary=dictionary)
        except Exception:       # whatever fails here fails again, reported, at its upload step
            continue
        done += 1
    return done
