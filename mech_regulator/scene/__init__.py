"""Scenes: the YAML format (schema), reading and validating scene files, bundled scenes."""

from mech_regulator.scene.loading import SceneError, bundled_scenes, config_dir, load_scene, validate_scene
from mech_regulator.scene.schema import Scene

__all__ = ["Scene", "SceneError", "bundled_scenes", "config_dir", "load_scene", "validate_scene"]
