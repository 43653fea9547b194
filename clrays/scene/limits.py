"""How much a scene file may ask for, written once. Each limit keeps one hostile or
mistaken input (an alias bomb, /dev/zero, a 50 MB scene) from taking a shared render node
down, and each is named in the error that enforces it. docs/limits.md says why each has
the value it has, with the measurements behind it.
"""
from __future__ import annotations

#: A scene file's size. Reading YAML costs 1 to 3 s and about 60 MB per MiB (measured on
#: a scene of inline triangles, docs/limits.md), so a 4 MiB scene loads in seconds;
#: geometry that needs more belongs in a mesh file, which is read as arrays.
MAX_SCENE_BYTES = 4 << 20
#: A mesh file's size: room for `MAX_TRIANGLES` in any of the three formats (binary STL,
#: the largest, takes 50 bytes a triangle: 100 MiB), so trimesh never reads much more
#: than the loader can keep.
MAX_MESH_BYTES = 128 << 20

#: How deep mappings and lists may nest, in the file or behind aliases. A scene needs
#: about 6 levels; the cap, checked on the parser's events before anything is composed,
#: keeps composing and converting (which recurse) far from the stack's limits.
MAX_NESTING = 64
#: How many values aliases (`*name`, `<<: *name`) may copy in all. A few anchored colours
#: or lights copy tens; the cap stops an alias bomb (each level repeating the one before)
#: long before it fills memory.
MAX_ALIAS_NODES = 100_000
#: The most digits (and letters, for 0x and 0b) a number may be written with. Python
#: refuses to turn an integer of more than 4300 digits into text; no scene value needs 20.
MAX_NUMBER_DIGITS = 100

#: Lights in one scene. A frame of several lights runs them in turn through one light's
#: shadow map, trees and bound maps (clrays.light_turns), so its memory barely grows with
#: the count; each light still costs its own raster, volume and visibility every frame, and
#: a float per camera sample for its visibility: 64 point lights at 1280×720 peak under 1 GB,
#: 256 at 3.5 MiB each of visibility (docs/limits.md).
MAX_LIGHTS = 256
#: Triangles in one scene, counted as each object is built (a sphere's or a plane's
#: before it is tessellated): a 60-byte sphere with `segments: 1024` is a million of them,
#: so without a cap a small file could ask for terabytes. Loading costs about 110 bytes
#: per triangle (measured: 4 spheres of a million triangles peak at 570 MB), so 2 Mi
#: triangles stay near 250 MB; the renderer's own copies come on top.
MAX_TRIANGLES = 1 << 21
#: Skinned or morphed vertices in one glTF scene (each instance's counted), posed again on
#: the host every frame where they move: a skinned grid of 1 Mi vertices and 2 Mi triangles
#: took 4.3 s a frame on the 2-core machine (docs/limits.md), a few times the frame's render.
MAX_DEFORMED_VERTICES = 1 << 20
#: Morph target vertices (targets × vertices, summed over the primitives): each target keeps
#: its float64 displacements, 24 bytes a vertex (twice that with NORMAL displacements), so
#: 4 Mi of them take about 100 to 200 MB.
MAX_MORPH_VERTICES = 1 << 22
#: Objects in one scene: each is read and transformed on its own in Python; meshes carry
#: any number of triangles in one object.
MAX_OBJECTS = 4096

#: A glTF file (.glb, .gltf) and, in all, the buffers it reads (.bin files, data URIs, the
#: GLB's BIN chunk): as a mesh file's, room for `MAX_TRIANGLES` (float32 positions and
#: normals, 32-bit indices: 60 bytes a triangle at worst, 120 MiB) read as arrays.
MAX_GLTF_BYTES = MAX_MESH_BYTES
#: Everything a glTF import materializes, counted against one budget before each allocation:
#: the buffers it reads (.bin files, data URIs, the GLB's BIN chunk), each accessor it reads
#: (once, however many primitives or channels use it) as float64 including its sparse
#: indices and values, the image files it reads and their decoded pixels (4 bytes each, the
#: most a PNG or JPEG decodes to). Buffers that fill their 128 MiB with float32 vertices need
#: 384 MiB (the buffers, and their values again as float64), which leaves room for a dozen
#: 4096² base colour textures (docs/limits.md). Without it, accessors without a view (all zeros),
#: re-read per primitive, and one small PNG named by 200 images cost minutes and gigabytes.
MAX_GLTF_IMPORT_BYTES = 1 << 30
#: Chunks in a GLB file: the JSON chunk, the BIN chunk and chunks of unknown types, which the
#: spec says to skip (extensions may add some; exporters write none). 19 million empty chunks after the
#: JSON (a 150 MB file) took 52 s and 2.1 GB to walk.
MAX_GLB_CHUNKS = 16
#: Values in a glTF file's JSON (counted from its commas, colons and brackets before it is
#: parsed: strings that hold them only overcount): each becomes a Python object of 24 to 100
#: bytes. 21 MB of `[],` took 540 MB to parse, and a file at the size limit would have taken
#: 4 GB; exported files hold hundreds of thousands at most (their data is in buffers).
MAX_GLTF_JSON_VALUES = 1 << 23
#: Nodes in a glTF file: each is a Python dict and a 4×4 matrix per pose, and the checks
#: of the hierarchy walk them all; exported scenes hold hundreds to a few thousand.
MAX_GLTF_NODES = 65_536
#: The width of a frame pattern's field (`{:04d}`): a frame number has at most 6 digits,
#: and `{:0999999999d}` made Python build a 1 GB string (4.8 GB, 25 s) before the file
#: system refused the name.
MAX_FRAME_FIELD_WIDTH = 32
#: Points in one sweep, the product of its axes' lengths, counted before anything is
#: built: each point is a scene to load and a frame to render, and results.csv is
#: rewritten as they finish; three axes of 100 values (a million points) rendered nothing
#: in 2 minutes while memory grew.
MAX_SWEEP_POINTS = 10_000
#: A sequence's frame manifest and a sweep's results.csv, read back to resume: a few
#: hundred bytes a frame or a point, so room for every frame and point many times over;
#: a link to /dev/zero took 7.5 GB.
MAX_RUN_RECORD_BYTES = 64 << 20
#: The largest coordinate, in scene units, of any point the device sees: vertices after
#: their transforms (every frame of an animation), the camera, the lights. float64 on the
#: host, the scene reaches the kernels as float32 (largest 3.4e38), where a ray–triangle
#: test multiplies three coordinates (an edge, the cross of another with the ray, the ray
#: origin): 1e12 cubed is 1e36, so sums of such products stay finite. A vertex at 1e39
#: became infinite, and `scale: 1e300` rendered broken geometry with exit 0.
MAX_COORDINATE = 1e12
