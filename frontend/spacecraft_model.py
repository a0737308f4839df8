"""The spacecraft of the twin view as GLB: bus, two solar-array wings and the telescope barrel along
body +x (the boresight of DESIGN.md), in body axes and metres.

Two looks: the *actual* spacecraft (opaque, telemetry) and the *simulated* ghost (translucent, one
colour, ``alphaMode="BLEND"`` baked into its materials) — seed 000 §7's two monitors, here also
overlaid in one scene.
"""

from __future__ import annotations

import io
from functools import lru_cache

import numpy as np

__all__ = ["BUS_SIZE_M", "ARRAY_SPAN_M", "TELESCOPE_LENGTH_M", "MODEL_EXTENT_M", "spacecraft_glb", "spacecraft_meshes"]

BUS_SIZE_M = (1.2, 1.0, 1.0)
ARRAY_SPAN_M = 2.4  # one wing, along body ±y
ARRAY_CHORD_M = 0.9
TELESCOPE_LENGTH_M = 1.1
TELESCOPE_RADIUS_M = 0.32
MODEL_EXTENT_M = BUS_SIZE_M[1] / 2 + ARRAY_SPAN_M + 0.1  # half-size of the model, for display scaling

_ACTUAL_COLOURS = {"bus": (212, 175, 55, 255), "array": (30, 50, 140, 255), "telescope": (200, 200, 205, 255)}
_GHOST_RGBA = (80, 255, 160, 110)


def spacecraft_meshes() -> dict[str, list]:
    """Trimesh parts by material group: bus box, two array wings on ±y, telescope barrel along +x."""
    import trimesh

    bx, by, bz = BUS_SIZE_M
    bus = trimesh.creation.box(extents=BUS_SIZE_M)
    wings = []
    for side in (-1.0, 1.0):
        wing = trimesh.creation.box(extents=(0.04, ARRAY_SPAN_M, ARRAY_CHORD_M))
        wing.apply_translation((0.0, side * (by / 2 + 0.1 + ARRAY_SPAN_M / 2), 0.0))
        boom = trimesh.creation.cylinder(
            radius=0.03, height=0.2, transform=trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0))
        )
        boom.apply_translation((0.0, side * (by / 2 + 0.05), 0.0))
        wings += [wing, boom]
    along_x = trimesh.transformations.rotation_matrix(np.pi / 2, (0, 1, 0))
    barrel = trimesh.creation.cylinder(
        radius=TELESCOPE_RADIUS_M, height=TELESCOPE_LENGTH_M, sections=32, transform=along_x
    )
    barrel.apply_translation((bx / 2 + TELESCOPE_LENGTH_M / 2, 0.0, 0.0))
    return {"bus": [bus], "array": wings, "telescope": [barrel]}


@lru_cache(maxsize=2)
def spacecraft_glb(ghost: bool = False) -> bytes:
    """GLB of the spacecraft, opaque (actual) or translucent green ghost (simulated, alphaMode BLEND)."""
    import trimesh

    scene = trimesh.Scene()
    for group, parts in spacecraft_meshes().items():
        mesh = trimesh.util.concatenate(parts)
        rgba = _GHOST_RGBA if ghost else _ACTUAL_COLOURS[group]
        material = trimesh.visual.material.PBRMaterial(
            name=f"{group}{'_ghost' if ghost else ''}",
            baseColorFactor=[c / 255.0 for c in rgba],
            metallicFactor=0.2 if group == "telescope" else 0.0,
            roughnessFactor=0.5,
            alphaMode="BLEND" if ghost else "OPAQUE",
            doubleSided=ghost,
        )
        mesh.visual = trimesh.visual.TextureVisuals(material=material)
        scene.add_geometry(mesh, node_name=group)
    buffer = io.BytesIO()
    buffer.write(scene.export(file_type="glb"))
    return buffer.getvalue()
