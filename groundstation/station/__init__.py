"""What a session with a rig (or the simulated testbed) is made of, above the link:

- station.py: `Station`, the Qt-free session every front end uses (CLI, scripts, the
  window's Session adapter): link, simulator, generator, recording, parameter table
  behind the validation gate, profiles, make_safe;
- recording.py: the session's one recording and its journal;
- tracker.py: the newest device state from HIGH_RATE;
- keeper.py: a link kept up with reconnects for the long-running CLI commands."""
