"""What a session with a rig (or the simulated testbed) is made of, above the link:
today the link keeper that reconnects with back-off for the CLI."""
