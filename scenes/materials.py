"""Spacecraft surface materials by the names an engineer uses, each a Mitsuba 3 BSDF dictionary.

A configuration names a material per part (``[body] material``, ``[mount] material``,
scenes/FORMAT.md); the renderer (:mod:`simcore.render.reflected`) gives the part that BSDF and
path-traces the sunlight and Earth light it reflects onto the diodes (the ``reflected``
component). Values are solar-spectrum (broadband) figures: the renderer runs Mitsuba's
monochromatic variant, so one reflectance stands for the whole band a silicon photodiode sees.

Named materials (:data:`MATERIALS`; sources next to each value):

``black``
    Ideal absorber (reflectance 0): the renderer's behaviour before materials existed and the
    default everywhere. A part of this material stops light; nothing is traced from it.
``black_paint``
    Lambertian, reflectance 0.05: Aeroglaze (ex Chemglaze) Z306 flat black polyurethane, solar
    absorptance alpha_s ~ 0.95 (Henninger, "Solar absorptance and thermal emittance of some
    common spacecraft thermal-control coatings", NASA RP-1121, 1984), so an opaque reflectance of
    1 - alpha_s ~ 0.05.
``aluminium``
    Bare (machined) aluminium: Mitsuba ``roughconductor``, GGX, alpha 0.1 (an rms slope of ~0.1:
    a milled/turned finish; polished stock is ~0.02, bead-blasted ~0.3: give your own with an
    expert dict), with explicit optical constants of Al at 550 nm, eta = 0.958, k = 6.69
    (Rakic, Appl. Opt. 37, 5271 (1998), via refractiveindex.info), whose normal-incidence
    Fresnel reflectance ((n-1)^2 + k^2) / ((n+1)^2 + k^2) = 0.921 matches the solar absorptance
    ~0.08-0.10 of bare polished aluminium (Henninger 1984).
``anodised_aluminium``
    Clear (sulphuric-acid) anodised aluminium: a smooth-ish oxide film over a scattering
    substrate, Mitsuba ``roughplastic``: GGX alpha 0.2, film index 1.65 (anodic Al2O3, ~1.6-1.7),
    diffuse base reflectance 0.55, so that the total solar reflectance is ~0.6 (alpha_s ~ 0.35-0.45
    for clear anodise, Henninger 1984).
``mli``
    Multi-layer insulation with an aluminised-Kapton outer layer, Kapton side out: the light crosses
    the smooth Kapton film and reflects off the aluminium behind it, so the lobe is a metal's (a
    ``roughconductor``), widened by the blanket's crinkle (GGX alpha 0.35, an assumption: blankets
    vary) and scaled to the film's solar reflectance: Fresnel factor 1 (``material = "none"``)
    times ``specular_reflectance`` 0.6 (alpha_s ~ 0.40 for 1-mil aluminised Kapton, Henninger 1984).
``solar_cell``
    Cover glass over a dark cell: Mitsuba ``plastic`` (a smooth dielectric coating over a
    Lambertian base, the coating's specular reflection included), int_ior 1.5 (ceria-doped
    borosilicate cover glass, CMX/CMG: n ~ 1.5), diffuse base reflectance 0.06, so that the total
    is ~0.09-0.10 (alpha_s ~ 0.90-0.92 of triple-junction GaAs cells with cover glass). The
    specular lobe gives the glint: Fresnel 4 % near normal incidence, rising toward grazing.
``mirror``
    Perfect mirror: ``conductor`` with ``material = "none"`` (reflectance 1 at every angle), for
    checks.

Experts give any Mitsuba BSDF dictionary instead of a name (TOML:
``material = {type = "roughconductor", material = "Au", alpha = 0.05}``); the renderer loads it
with ``mi.load_dict`` and wraps single-sided reflective BSDFs in ``twosided`` (a part's faces
are lit from whichever side the light comes).
"""
from __future__ import annotations

import copy

from simcore import _llvm
from simcore.errors import InvalidInputError

DEFAULT = "black"

MATERIALS = {
    "black": {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.0}},
    "black_paint": {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.05}},
    "aluminium": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.1,
                  "eta": {"type": "uniform", "value": 0.958}, "k": {"type": "uniform", "value": 6.69}},
    "anodised_aluminium": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.2, "int_ior": 1.65,
                           "ext_ior": 1.0, "diffuse_reflectance": {"type": "uniform", "value": 0.55}},
    "mli": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.35, "material": "none",
            "specular_reflectance": {"type": "uniform", "value": 0.6}},
    "solar_cell": {"type": "plastic", "int_ior": 1.5, "ext_ior": 1.0,
                   "diffuse_reflectance": {"type": "uniform", "value": 0.06}},
    "mirror": {"type": "conductor", "material": "none"},
}

# Mitsuba 3's BSDF plugins (docs "Plugin reference: BSDFs"), for a clear error on a misspelt type.
BSDF_TYPES = ("diffuse", "dielectric", "thindielectric", "roughdielectric", "conductor", "roughconductor",
              "hair", "measured", "pplastic", "plastic", "roughplastic", "bumpmap", "normalmap", "blendbsdf",
              "mask", "twosided", "principled", "principledthin", "polarizer", "retarder", "circular",
              "measured_polarized", "null")


class MaterialError(InvalidInputError):
    """A material that is neither a known name nor a Mitsuba BSDF dictionary."""


def material_names():
    """Return the named materials (sorted)."""
    return sorted(MATERIALS)


def check_material(spec, where="material"):
    """Return ``spec`` unchanged (a name of :data:`MATERIALS` or a BSDF dict with a known ``type``),
    or raise :class:`MaterialError` saying which names exist."""
    if isinstance(spec, str):
        if spec not in MATERIALS:
            raise MaterialError(f"{where}: unknown material {spec!r}; use one of {', '.join(material_names())}, "
                                "or a Mitsuba BSDF table such as {type = \"roughconductor\", material = \"Al\", "
                                "alpha = 0.1}")
        return spec
    if isinstance(spec, dict):
        kind = spec.get("type")
        if kind not in BSDF_TYPES:
            raise MaterialError(f"{where}: a material table needs type = one of Mitsuba's BSDFs "
                                f"({', '.join(BSDF_TYPES)}), got {kind!r}; or use a name: "
                                f"{', '.join(material_names())}")
        _load_check(spec, where)
        return spec
    raise MaterialError(f"{where}: a material is a name ({', '.join(material_names())}) or a Mitsuba BSDF "
                        f"table, got {spec!r}")


def _load_check(spec, where):
    """Raise MaterialError when Mitsuba cannot build the BSDF dict ``spec`` (a wrong parameter name or
    value), so that a run fails on its configuration before it writes anything."""
    mi = _llvm.import_mitsuba()
    prev = mi.variant()
    mi.set_variant(prev or "scalar_rgb")     # any variant parses the dict; keep the caller's when set
    try:
        mi.load_dict(bsdf_dict(spec))
    except Exception as exc:                 # Mitsuba raises RuntimeError/TypeError/ValueError with its reason
        reason = " ".join(str(exc).split())
        raise MaterialError(f"{where}: Mitsuba cannot build the material {spec!r}: {reason[:300]}") from None


def is_black(spec):
    """Return True for the ideal absorber (the name 'black'): parts the renderer only ray-tests."""
    return isinstance(spec, str) and spec == DEFAULT


def bsdf_dict(spec):
    """Return the Mitsuba BSDF dictionary (a fresh copy) of a material name or dict, two-sided where
    Mitsuba's plugin is single-sided and reflective."""
    if not isinstance(spec, dict):
        check_material(spec)
    d = copy.deepcopy(MATERIALS[spec] if isinstance(spec, str) else spec)
    if d["type"] in ("twosided", "dielectric", "thindielectric", "roughdielectric", "null", "mask"):
        return d
    return {"type": "twosided", "bsdf": d}
