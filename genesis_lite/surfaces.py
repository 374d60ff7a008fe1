"""Surfaces: how an entity looks to cameras.

Genesis's surface kinds (Plastic and its Rough, Smooth, Reflective and Collision; Metal and its
Iron, Aluminium, Copper, Gold; Glass and Water; Emission; BSDF) are taken with Default's
arguments and drawn as Default is: their colour with the cameras' Lambert shading (Genesis's
rasterizer and ray tracer give them their roughness, index of refraction or metal look; their
look's own arguments are refused by name, as Default's). Collision and Water keep Genesis's
default colours."""
from dataclasses import dataclass

import numpy as np

from .options import named_keywords
from .solvers.core import InvalidInputError

_LOOK_OPTIONS = ("cutoff", "default_roughness", "diffuse_texture", "diffuse_trans", "double_sided", "emissive",
                 "emissive_texture", "foam_options", "generate_foam", "ior", "metallic", "metallic_texture",
                 "normal_diff_clamp", "normal_texture", "opacity", "opacity_texture", "recon_backend", "roughness",
                 "roughness_texture", "smooth", "specular_trans", "specular_texture", "metal_type")


@named_keywords(*_LOOK_OPTIONS)
@dataclass
class Default:
    """A plain surface. color: (r, g, b) or (r, g, b, a) in [0, 1], or None (Genesis's default):
    the asset's own colours (a URDF's materials), else grey. A colour given here paints the whole
    entity, URDF materials included, as in Genesis. Cameras draw opaque surfaces: alpha is kept
    but not drawn. vis_mode: None, or what the cameras draw of the entity ("visual" or "collision"
    for a rigid entity, "particle" for particles), checked by scene.add_entity (its own vis_mode
    argument, when given, is the one taken, as Genesis)."""
    color: tuple = None
    vis_mode: str = None

    def __post_init__(self):
        if not (self.vis_mode is None or isinstance(self.vis_mode, str)):
            raise InvalidInputError(f"surfaces.{type(self).__name__}: argument 'vis_mode' must be None or a str, got "
                                    f"{self.vis_mode!r}")
        if self.color is None:
            return
        try:
            color = np.asarray(self.color, dtype=np.float64)
        except (TypeError, ValueError):
            color = np.full(0, np.nan)
        if color.shape not in ((3,), (4,)) or not np.all((color >= 0) & (color <= 1)):
            raise InvalidInputError(f"surfaces.{type(self).__name__}: argument 'color' must be (r, g, b) or (r, g, b, a) "
                                    f"in [0, 1] or None, got {self.color!r}")
        self.color = tuple(float(c) for c in color)


def _kind(name, base, doc, color=None):
    """A Genesis surface kind: ``base`` with Genesis's default ``color`` (None: the asset's)."""
    namespace = {"__doc__": doc, "__module__": __name__, "__qualname__": name,
                 "__annotations__": {"color": tuple}, "color": color}
    return named_keywords(*_LOOK_OPTIONS)(dataclass(type(name, (base,), namespace)))


BSDF = _kind("BSDF", Default, "Genesis's BSDF surface, drawn as Default (Genesis's Default is a BSDF; here BSDF is a "
                            "Default).")
Plastic = _kind("Plastic", Default, "Genesis's plastic surface, drawn as Default.")
Rough = _kind("Rough", Plastic, "Genesis's rough plastic, drawn as Default.")
Smooth = _kind("Smooth", Plastic, "Genesis's smooth plastic, drawn as Default.")
Reflective = _kind("Reflective", Plastic, "Genesis's reflective plastic, drawn as Default.")
Collision = _kind("Collision", Plastic, "Genesis's surface of collision geometry: grey by default.", (0.5, 0.5, 0.5))
Metal = _kind("Metal", Default, "Genesis's metal surface, drawn as Default.")
Iron = _kind("Iron", Metal, "Genesis's iron, drawn as Default.")
Aluminium = _kind("Aluminium", Metal, "Genesis's aluminium, drawn as Default.")
Copper = _kind("Copper", Metal, "Genesis's copper, drawn as Default.")
Gold = _kind("Gold", Metal, "Genesis's gold, drawn as Default.")
Glass = _kind("Glass", Default, "Genesis's glass, drawn as Default (opaque).")
Water = _kind("Water", Glass, "Genesis's water surface: its colour by default, drawn as Default.", (0.61, 0.98, 0.93))
Emission = _kind("Emission", Default, "Genesis's emissive surface, drawn as Default (no light of its own).")
