"""The analysis tab: runs from logs, campaign reports or live telemetry, the metric tables
and plots, the background jobs that compute them (numerics live in groundstation.analysis),
and export."""
