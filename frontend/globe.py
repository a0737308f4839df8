"""The Earth of the twin view: a textured WGS84 ellipsoid in Earth radii, as a GLB for viser.

Scene units are WGS84 equatorial radii (near/far planes rule out metres, DESIGN.md). The mesh is in
ECEF axes (x toward longitude 0 on the equator, z toward the North Pole); the scene rotates it into
ECI with the ECEF → ECI quaternion of the displayed instant (seed 000 §6 "sticking on a texture of
the Earth map onto the Earth surface" of the rotating Earth).
"""

from __future__ import annotations

import io
from functools import lru_cache
from pathlib import Path

import numpy as np

from sim_core import frames

__all__ = ["ASSETS_DIR", "DAY_IMAGE", "NIGHT_IMAGE", "EARTH_CREDIT", "POLAR_RATIO", "earth_mesh_arrays", "earth_glb"]

ASSETS_DIR = Path(__file__).resolve().parent / "assets"
DAY_IMAGE = ASSETS_DIR / "earth_day_2048x1024.jpg"
NIGHT_IMAGE = ASSETS_DIR / "earth_night_2048x1024.jpg"
EARTH_CREDIT = "Earth imagery: NASA Visible Earth (http://visibleearth.nasa.gov/)"
POLAR_RATIO = 1.0 - frames.WGS84_F  # b / a
NIGHT_LIGHTS_GAIN = 0.55  # emissive city lights: visible on the dark side, faint beside daylight


def earth_mesh_arrays(n_lat: int = 64, n_lon: int = 128) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (Earth radii, ECEF axes), triangle faces, geodetic unit normals and equirectangular UVs.

    The seam meridian is duplicated so that u runs 0 → 1 from longitude −180° to +180° (the
    projection of the vendored images); v runs 0 → 1 from the South to the North Pole.
    """
    if n_lat < 4 or n_lon < 8:
        raise ValueError("n_lat, n_lon: need at least 4 latitude and 8 longitude divisions")
    lat = np.linspace(-np.pi / 2, np.pi / 2, n_lat + 1)
    lon = np.linspace(-np.pi, np.pi, n_lon + 1)
    lon_g, lat_g = np.meshgrid(lon, lat)
    normals = np.stack([np.cos(lat_g) * np.cos(lon_g), np.cos(lat_g) * np.sin(lon_g), np.sin(lat_g)], -1)
    axes = np.array([1.0, 1.0, POLAR_RATIO])
    scaled = axes**2 * normals  # ellipsoid point with geodetic normal n (see sim_core.camera)
    vertices = scaled / np.sqrt(np.sum(scaled * normals, axis=-1, keepdims=True))
    uv = np.stack([(lon_g + np.pi) / (2 * np.pi), (lat_g + np.pi / 2) / np.pi], -1)
    idx = np.arange((n_lat + 1) * (n_lon + 1)).reshape(n_lat + 1, n_lon + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return vertices.reshape(-1, 3), faces, normals.reshape(-1, 3), uv.reshape(-1, 2)


@lru_cache(maxsize=2)
def earth_glb(night_lights: bool = True) -> bytes:
    """GLB of the textured Earth (day image as base colour, city lights as a dim emissive map; JPEG kept)."""
    import trimesh
    from PIL import Image

    vertices, faces, normals, uv = earth_mesh_arrays()
    material = trimesh.visual.material.PBRMaterial(
        name="earth",
        baseColorTexture=Image.open(DAY_IMAGE),
        metallicFactor=0.0,
        roughnessFactor=0.9,
        emissiveTexture=Image.open(NIGHT_IMAGE) if night_lights else None,
        emissiveFactor=[NIGHT_LIGHTS_GAIN] * 3 if night_lights else None,
    )
    mesh = trimesh.Trimesh(
        vertices=vertices,
        faces=faces,
        vertex_normals=normals,
        process=False,
        visual=trimesh.visual.TextureVisuals(uv=uv, material=material),
    )
    buffer = io.BytesIO()
    buffer.write(trimesh.Scene(mesh).export(file_type="glb"))
    return buffer.getvalue()
