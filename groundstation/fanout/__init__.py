"""Many consoles on one rig: the commanding station publishes, read-only consoles watch.

    wire.py       the multipart message layout (topic, header, payload) - no zmq
    endpoints.py  which endpoints may be bound or watched, and why not - no zmq
    keys.py       CURVE key pairs for a publisher bound beyond loopback
    publisher.py  the PUB socket the device link feeds with the raw frames it receives
    viewer.py     WatchClient: a TelemetrySource over a SUB socket, read-only, ABORT direct
    commands.py   `monitor --watch`, `record --watch`, `fanout keys` (the CLI's side)

Nothing here is imported when the ground station starts: zmq is loaded only by a
command or a window that publishes or watches (tests/test_architecture.py).
"""
