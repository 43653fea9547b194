"""The scene: the frozen model (`model`), the format's keys with their types, defaults
and ranges (`fields`), the YAML loader (`load`) over YAML that keeps positions
(`yaml_tree`), how much a scene may ask for (`limits`) and how its files are read
(`files`), keyframes (`animation`), primitive and mesh triangles and their shading
normals (`geometry`), affine transforms (`transforms`) and the camera's rays (`camera`)."""
from .load import load_scene, parse_scene
from .model import (Camera, DirectionalLight, Geometry, Image, Light, Medium, Phase, PointLight, Render, Scene,
                    SpotLight)

__all__ = ["load_scene", "parse_scene", "Scene", "Image", "Camera", "PointLight", "SpotLight", "DirectionalLight",
           "Light", "Phase", "Medium", "Render", "Geometry"]
