"""The `groundstation` command: main.py builds the parser and dispatches; one module per
command group (logs, params, profile, campaign, fg, analysis, station).  Argument parsing
imports only the standard library; each command imports what it uses when it runs."""
