"""The TOML scene format (``docs/scene-format.md``): loading, the in-memory model, triangulation and emitter arrays
for the core, and stress variants (transformed copies of a scene, :mod:`harness.scene.variants`)."""

from harness.scene.emitter_arrays import emitter_arrays
from harness.scene.load import find_scene, load_scene, scene_argument
from harness.scene.material_arrays import material_arrays
from harness.scene.media_arrays import media_arrays
from harness.scene.model import Material, Scene, Shape
from harness.scene.triangulate import triangulate

__all__ = ["Material", "Scene", "Shape", "emitter_arrays", "find_scene", "load_scene", "material_arrays",
           "media_arrays", "scene_argument", "triangulate"]
