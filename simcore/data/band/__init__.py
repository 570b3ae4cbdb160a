"""The band maps' data (README.md) and their offline builder, ``build_band_data.py``."""
