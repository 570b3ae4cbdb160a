"""Studies built on runs: the thesis' chapter-4 reproduction, aperture-geometry studies, coverage maps
and the cross-map evaluation of the on-board albedo prediction."""
