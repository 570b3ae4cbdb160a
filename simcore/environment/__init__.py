"""The environment along the orbit: time (epochs), TLE orbits (SGP4), frames, the Sun, eclipses,
attitude, the Earth's reflectivity maps, and the per-epoch study geometry that joins them.

The lowest stage of the pipeline: it imports nothing from the rest of sunsim but the constants.
"""
