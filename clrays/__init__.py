"""clrays: volumetric shadows (light shafts) with 1D min-max mipmaps, in OpenCL.

    import clrays
    scene = clrays.load_scene("scenes/demo.yaml")
    image = clrays.render(scene, method="raymarch")   # (H, W, 3) float32 linear radiance
"""
from .errors import ClraysError, DeviceError, OutputError, SceneError
from .session import Renderer, RenderResult, render
from .scene.load import load_scene, parse_scene

__version__ = "0.1.0"
__all__ = ["load_scene", "parse_scene", "render", "Renderer", "RenderResult",
           "ClraysError", "SceneError", "DeviceError", "OutputError"]
