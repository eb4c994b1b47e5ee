"""The strip charts: the panel (plot stack, settings, timebase), its plots and columns,
autoscaling, the channel tree and the live spectrum view."""
