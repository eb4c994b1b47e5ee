"""The foundation every other package stands on, importing nothing of the project: the
error hierarchy, the protocol dictionary (protocol/*.toml as data), the device-facing
contracts, TOML reading with line-numbered errors, the closed vocabularies (kinds) and the
Ctrl-C/SIGTERM stop request of the long commands."""
