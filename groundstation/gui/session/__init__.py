"""The window's model of one session, with no widgets: the connection (device, simulator,
replay), the recorder, command history, profile playback, the read-only consoles and the
campaign runner, as QObjects whose signals the panels connect to."""
