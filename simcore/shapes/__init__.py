"""The shapes that block light, in closed form: a diode's well aperture (its exact overlap response)
and the body box's shadow (convex polygons). Shared by the scenes, the analytic model and the renderer."""
