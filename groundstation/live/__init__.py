"""What the window pulls from while telemetry flows, without Qt: the display store (the
decimated ring buffers of every channel) and the limit monitor.  The station and the
command line can use them as well; the widgets only read them."""
