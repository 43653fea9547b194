"""The scene: the frozen model (`model`), the YAML loader (`load`), keyframes
(`animation`), primitive and mesh triangles (`geometry`), affine transforms
(`transforms`) and the camera's rays (`camera`)."""
from .load import load_scene, parse_scene
from .model import (Camera, DirectionalLight, Geometry, Image, Light, Medium, Phase, PointLight, Render, Scene,
                    SpotLight)

__all__ = ["load_scene", "parse_scene", "Scene", "Image", "Camera", "PointLight", "SpotLight", "DirectionalLight",
           "Light", "Phase", "Medium", "Render", "Geometry"]
