"""Satellite descriptions (TOML data) and the code that builds their geometry."""
from scenes.config import ConfigError, MountedDiode, SatelliteConfig, list_configs

__all__ = ["ConfigError", "MountedDiode", "SatelliteConfig", "list_configs"]
