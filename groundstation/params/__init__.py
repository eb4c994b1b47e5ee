"""Parameter tables: schema from protocol/parameters.toml, packing, validation."""
