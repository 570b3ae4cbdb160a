"""Satellite descriptions (TOML data) and the code that builds their geometry."""
from scenes.config import ConfigError, Diode, SatelliteConfig, list_configs

__all__ = ["ConfigError", "Diode", "SatelliteConfig", "list_configs"]
