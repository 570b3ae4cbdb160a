"""Sun-vector estimators: pure functions of diode irradiances and normals."""
