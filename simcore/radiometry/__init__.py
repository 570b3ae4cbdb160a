"""The analytic radiometry: Bhanderi's Earth albedo (toolbox-exact and physical), diode angular
responses, the direct + albedo irradiance of every diode (the check of the renderer) and the
on-board albedo prediction."""
