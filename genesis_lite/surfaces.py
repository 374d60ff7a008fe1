"""Surfaces: how an entity looks to cameras."""
from dataclasses import dataclass

import numpy as np

from .options import named_keywords
from .solvers.core import InvalidInputError


@named_keywords("cutoff", "default_roughness", "diffuse_texture", "diffuse_trans", "double_sided", "emissive",
                "emissive_texture", "foam_options", "generate_foam", "ior", "metallic", "metallic_texture",
                "normal_diff_clamp", "normal_texture", "opacity", "opacity_texture", "recon_backend", "roughness",
                "roughness_texture", "smooth", "specular_trans")
@dataclass
class Default:
    """A plain surface. color: (r, g, b) or (r, g, b, a) in [0, 1], or None (Genesis's default):
    the asset's own colours (a URDF's materials), else grey. A colour given here paints the whole
    entity, URDF materials included, as in Genesis. Cameras draw opaque surfaces: alpha is kept
    but not drawn. vis_mode: None, or what the cameras draw of the entity ("visual" for a rigid
    entity, "particle" for particles), checked by scene.add_entity (its own vis_mode argument, when
    given, is the one taken, as Genesis)."""
    color: tuple = None
    vis_mode: str = None

    def __post_init__(self):
        if not (self.vis_mode is None or isinstance(self.vis_mode, str)):
            raise InvalidInputError(f"surfaces.Default: argument 'vis_mode' must be None or a str, got "
                                    f"{self.vis_mode!r}")
        if self.color is None:
            return
        try:
            color = np.asarray(self.color, dtype=np.float64)
        except (TypeError, ValueError):
            color = np.full(0, np.nan)
        if color.shape not in ((3,), (4,)) or not np.all((color >= 0) & (color <= 1)):
            raise InvalidInputError(f"surfaces.Default: argument 'color' must be (r, g, b) or (r, g, b, a) in [0, 1] "
                                    f"or None, got {self.color!r}")
        self.color = tuple(float(c) for c in color)
