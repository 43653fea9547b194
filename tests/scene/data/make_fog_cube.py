"""Writes fog_cube.glb, which tests/scene/test_gltf_fog_volume.py reads: a scene as a Blender
user makes fog, exported by Blender's own glTF exporter (Blender 4.5, its default settings,
lights and camera included) so that clrays's import is tested on what the exporter writes.
Not run by the tests; to regenerate (the `bpy` wheel, Python 3.11):

    /tmp/bpyenv/bin/python tests/scene/data/make_fog_cube.py

The scene (Blender's Z up; glTF's Y up): a 4 × 4 m floor (top at z = 0), a node `fog` placing
a 2 m cube at (1, −0.5, 1.5) scaled to 4 × 3 × 2 m (so x ∈ [−1, 3], y ∈ [−2, 1], z ∈ [0.5, 2.5];
in glTF x ∈ [−1, 3], y ∈ [0.5, 2.5], z ∈ [−1, 2]) whose material is a Principled Volume
alone (no Surface), a 100 W point light at z = 4 and a camera. The exporter writes the cube
as an ordinary mesh and its material as `{"doubleSided": true, "name": "fog_volume"}`: no
pbrMetallicRoughness and no extension for the volume.
"""
import math
from pathlib import Path

import bpy

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0, 0, 0))
bpy.context.active_object.name = "floor"
bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.0, -0.5, 1.5))
cube = bpy.context.active_object
cube.name = "fog"
cube.scale = (2.0, 1.5, 1.0)  # kept on the node, as a user leaves it: the bounds are the world box
fog = bpy.data.materials.new("fog_volume")
fog.use_nodes = True
nodes = fog.node_tree.nodes
nodes.remove(nodes["Principled BSDF"])
volume = nodes.new("ShaderNodeVolumePrincipled")
volume.inputs["Density"].default_value = 0.2
fog.node_tree.links.new(volume.outputs[0], nodes["Material Output"].inputs["Volume"])
cube.data.materials.append(fog)
lamp = bpy.data.objects.new("lamp", bpy.data.lights.new("lamp", "POINT"))
lamp.data.energy = 100.0
lamp.location = (0.0, 0.0, 4.0)
bpy.context.scene.collection.objects.link(lamp)
eye = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
eye.location = (6.0, -6.0, 4.0)
eye.rotation_euler = (math.radians(65), 0.0, math.radians(45))
bpy.context.scene.collection.objects.link(eye)
bpy.context.scene.camera = eye
bpy.ops.export_scene.gltf(filepath=str(Path(__file__).with_name("fog_cube.glb")), export_format="GLB",
                          export_lights=True, export_cameras=True)
