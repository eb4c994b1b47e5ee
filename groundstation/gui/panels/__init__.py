"""The panels around the charts: connection bar, status, commands, recording, parameters,
profiles, campaigns and logs."""
