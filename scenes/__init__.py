"""Satellite descriptions (TOML data) and the code that builds their geometry."""
