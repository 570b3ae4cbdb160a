"""The Monte-Carlo renderer (Mitsuba 3 / Dr.Jit): diode irradiance along an orbit with standard errors
(:class:`Renderer`), one module per estimator over a shared launch base (docs/renderer.md), reflections on the
spacecraft (aperture walls included) path traced. Dr.Jit's libLLVM is configured when a renderer is first built."""
from simcore.render.launch import SUN_ANGULAR_RADIUS_RAD, choose_variant, occluder_scene, rays_blocked
from simcore.render.probes import widen_cells
from simcore.render.renderer import Renderer, render
from simcore.render.results import RenderResult
from scenes.satellite import DiodeSurfaces  # the renderer's input, at home in the data layer

__all__ = ["SUN_ANGULAR_RADIUS_RAD", "DiodeSurfaces", "RenderResult", "Renderer", "choose_variant", "occluder_scene",
           "rays_blocked", "render", "widen_cells"]
