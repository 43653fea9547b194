"""The facts host and device share: the enumerations and constants of the kernels,
and numpy dtypes mirroring the structs of `cl/common.h` (same fields, same order).

The constants are defined here and nowhere else: every kernel build gets each one as a
`-D NAME=literal` option (`kernel_defines`, passed by `clrays.device.Device.program`),
and cl/common.h refuses to compile without them. tests/layout/test_layout.py asks the
device for every constant's value and for sizeof/offsetof of every struct field, and
compares them with this module.
"""
import numpy as np

PROJECTION_PERSPECTIVE = 0  # view_t.projection
PROJECTION_ORTHOGRAPHIC = 1

LIGHT_POINT = 0  # light_t.type, integrand_t.light_type
LIGHT_SPOT = 1
LIGHT_DIRECTIONAL = 2

PHASE_ISOTROPIC = 0  # frame_t.phase_type
PHASE_HG = 1

INTEGRAND_TABLE = 0  # integrand_t.mode
INTEGRAND_SVD = 1
INTEGRAND_ANALYTIC = 2

SURFACE_SHADOWS_EXACT = 0  # frame_t.surface_shadows
SURFACE_SHADOWS_MAP = 1
SURFACE_SHADOWS_PCF = 2
SURFACE_SHADOWS_FILTERED = 3  # the shadow_filter stage's answer, read like the visibility stage's

SHADOW_FILTER_HARD = 0  # cl/shadow_filter.cl's SHADOW_FILTER option (render.shadow_filter.type)
SHADOW_FILTER_PCF = 1
SHADOW_FILTER_VSM = 2
SHADOW_FILTER_MSM_HAMBURGER = 3
SHADOW_FILTER_MSM_HAUSDORFF = 4

TRAVERSAL_TREE = 0  # cl/traverse.cl's TRAVERSAL option
TRAVERSAL_SCAN = 1

STEP_SPACING_EQUIANGULAR = 0  # cl/raymarch.cl's STEP_SPACING option (render.step_spacing)
STEP_SPACING_UNIFORM = 1

TEXTURE_WRAP_REPEAT = 0  # light_texture_t.wrap
TEXTURE_WRAP_CLAMP = 1

DEPTH_EMPTY = np.uint32(0x7F800000)  # as_uint(+inf): a depth buffer's texel where nothing was rasterized

WRITER_NONE = -1  # the visibility stage's writer map: no triangle touches this texel
WRITER_MANY = -2  # two or more do (else the one triangle's index)
# Geometry.convex_part's flag of a solid's part (a box, a sphere): its triangles cannot shadow
# a point of its outside only, which (b - a) x (c - a) faces (cl/visibility.h).
CONVEX_OUTSIDE_ONLY = 1 << 30

# A point or spot light is a lamp: a ball of radius LAMP_RADIUS_REL × the scene's size around
# it holds no medium (clrays.physics.radiometry says why and what it changes); the radius
# reaches the device per frame, in frame_t.lamp_radius.
LAMP_RADIUS_REL = 1e-6

# Rays that hit nothing end at camera.far, but no further than this optical depth of the
# least attenuating channel (e^-40 ≈ 4e-18: nothing a float32 radiance keeps) nor than
# FAR_DEVICE_MAX scene units, where squared distances still fit a float32
# (clrays.physics.radiometry.effective_far).
FAR_OPTICAL_DEPTH = 40.0
FAR_DEVICE_MAX = 1e18

# sinβ is clamped to this in every 1/sinβ, so that β = 0 (a ray through a point light)
# stays finite; only rays within 1e-9 rad of the eye–light axis see the clamp.
SIN_BETA_MIN = 1e-9

# A point or spot light's γ texels are even in u ∈ [0, N], γ = γ_max·t·(1 − W + W·t), t = u/N
# (epipolar_t.gamma_warp, cl/gamma_texels.h, texel_gamma below): W = 0.7 makes the texels
# next to the eye's light ray (γ = 0) 0.3× the even width and those at γ_max 1.7×. Along a
# camera ray at angle β from the light, ds/dγ = d²/(d_el·sin β): rays close to the light's
# direction cover long stretches with the first texels (orbit.yaml frame 10, 0.80 → 0.49 %
# at 640×360; bench/RESULTS.md history, "γ texels finer near the eye's light ray, kept"). A
# quadratic, not γ0·(e^{K·u/N} − 1): the walks evaluate it and its inverse (a square root)
# at every run, and log1p and expm1 there cost traverse about a third more on PoCL. A
# directional light's γ is a length with ds/dγ = 1/sin β, the same all along: its texels
# stay even (W = 0).
GAMMA_TEXEL_WARP = 0.7


def texel_gamma(gamma_step: float, n: int, u, warp: float) -> np.ndarray:
    """γ at texel coordinate u of a row of n texels (float64; the start of texel u for an
    integer u, 0 at u = 0): u·gamma_step·(1 − W + W·u/n), W = warp; as cl/gamma_texels.h
    gamma_at_texel."""
    u = np.asarray(u, dtype=np.float64)
    return u * float(gamma_step) * (1.0 - warp + warp * u / n)


def texel_coordinate(gamma_step: float, n: int, gamma, warp: float) -> np.ndarray:
    """The texel coordinate u of γ, `texel_gamma`'s inverse (cl/gamma_texels.h gamma_texel_coord)."""
    x = np.asarray(gamma, dtype=np.float64) / float(gamma_step)
    even = 1.0 - warp
    return 2.0 * x / (even + np.sqrt(even * even + 4.0 * warp * x / n))


# raster: a triangle spanning more than RASTER_BIG_ROWS rows of a view (a floor plane)
# is listed by the first pass instead of looping over its rows alone; up to
# RASTER_BIG_TRIANGLES of them per launch, the rest draw their own rows.
RASTER_BIG_ROWS = 32
RASTER_BIG_TRIANGLES = 1 << 16
# The second pass gives each work-item this many consecutive rows of the view (whole on a
# CPU device, 32 columns of them elsewhere), of every listed triangle: it owns them (no
# atomics), and the clipping and projection it repeats per triangle are paid once per block.
RASTER_ROWS_PER_ITEM = 4
# raster_any (is a map empty?) reads this many texels per work-item.
RASTER_ANY_TEXELS = 256

# The depth tolerance, in texels of a shadow map, of every surface point's test against it
# (shade, visibility, transparency and translucency: one test, one tolerance).
SURFACE_BIAS_TEXELS = 1.5
# Shadow rays leave the surface by this much × (|p| + distance to the light): a few hundred
# float32 ulps of the sample's coordinates (visibility's rays, translucency's transmittance).
SHADOW_RAY_OFFSET_REL = 2e-6

# visibility: the value of a sample and light that visibility_prepare leaves to the maps
# or a ray; and visibility_bound's rect_mode: none, record each triangle's texel rectangle,
# or skip the triangles whose recorded rectangle holds no texel read (cl/visibility_bound.cl).
VISIBILITY_PENDING = -1.0
RECTS_NONE, RECTS_RECORD, RECTS_FILTER = 0, 1, 2
# Words of the read mask (32 texels each) one visibility_clear work-item takes.
VISIBILITY_CLEAR_WORDS = 32
# visibility's route: how the entries the maps leave get their shadow rays, decided on the
# device (cl/visibility.cl, visibility_route), so that the host enqueues the listed paths
# without waiting to learn the rays' count: none left; the frame's own lists (a thumbnail);
# lists of the rays' texels to be made, then those lists; the BVH. A launch of one path
# returns at once under another; ROUTE_ANY: a launch that runs whatever the route.
VISIBILITY_ROUTE_ANY = -1
VISIBILITY_ROUTE_NONE, VISIBILITY_ROUTE_LISTED, VISIBILITY_ROUTE_RAY_LISTS = 0, 1, 2
VISIBILITY_ROUTE_RAY_LISTED, VISIBILITY_ROUTE_BVH = 3, 4

#: Every constant above by its C name: the `-D` options of every kernel build.
KERNEL_CONSTANTS = {
    name: value for name, value in dict(globals()).items()
    if name.startswith(("PROJECTION_", "LIGHT_", "PHASE_", "INTEGRAND_", "TRAVERSAL_", "RASTER_", "SURFACE_SHADOWS_",
                         "TEXTURE_WRAP_", "SHADOW_FILTER_", "WRITER_", "STEP_SPACING_", "RECTS_", "CONVEX_",
                         "VISIBILITY_ROUTE_"))
    or name in ("DEPTH_EMPTY", "SIN_BETA_MIN", "VISIBILITY_PENDING", "VISIBILITY_CLEAR_WORDS", "SURFACE_BIAS_TEXELS",
                "SHADOW_RAY_OFFSET_REL")
}


def c_literal(value) -> str:
    """`value` as a C literal: an int, a `u`-suffixed hex uint, or a float as the exact
    decimal of its float32 value with an `f` suffix, so that the kernels get the bits of
    `np.float32(value)` and no expression with it is promoted to double."""
    if isinstance(value, np.uint32):
        return f"{int(value):#x}u"
    if isinstance(value, float):
        return repr(float(np.float32(value))) + "f"
    return str(int(value))


def kernel_defines() -> dict[str, str]:
    """NAME → C literal of every shared constant, for `-D NAME=literal`."""
    return {name: c_literal(value) for name, value in KERNEL_CONSTANTS.items()}


_f4 = (np.float32, 4)

view_dtype = np.dtype([
    ("origin", _f4), ("right", _f4), ("up", _f4), ("forward", _f4),
    ("scale_x", np.float32), ("scale_y", np.float32),
    ("width", np.int32), ("height", np.int32),
    ("projection", np.int32), ("depth_offset", np.int32),
    ("cull_back_faces", np.int32), ("_pad1", np.int32),
])

light_dtype = np.dtype([
    ("position", _f4), ("direction", _f4), ("power", _f4),
    ("type", np.int32), ("cos_cone", np.float32),
    ("first_view", np.int32), ("view_count", np.int32),
    ("texel_angle", np.float32),
    ("_pad0", np.int32), ("_pad1", np.int32), ("_pad2", np.int32),
])

frame_dtype = np.dtype([
    ("sigma_s", _f4), ("sigma_t", _f4), ("background", _f4), ("near_plane", _f4),
    ("phase_g", np.float32), ("phase_type", np.int32),
    ("far", np.float32), ("light_count", np.int32),
    ("width", np.int32), ("height", np.int32), ("spp", np.int32), ("steps", np.int32),
    ("jitter", np.int32), ("pcf", np.int32),
    ("lamp_radius", np.float32), ("surface_shadows", np.int32),
])

epipolar_dtype = np.dtype([
    ("axis", _f4), ("u", _f4), ("w", _f4),
    ("d_el", np.float32), ("alpha_min", np.float32), ("alpha_step", np.float32), ("slices", np.int32),
    ("gamma_step", np.float32), ("gamma_samples", np.int32), ("levels", np.int32), ("light_index", np.int32),
    ("full_circle", np.int32), ("gamma_warp", np.float32), ("_pad1", np.int32), ("_pad2", np.int32),
])

integrand_dtype = np.dtype([
    ("amplitude", _f4), ("sigma_t", _f4), ("s_end", _f4),
    ("beta_min", np.float32), ("beta_max", np.float32), ("d_el", np.float32), ("g", np.float32),
    ("mode", np.int32), ("n_beta", np.int32), ("n_gamma", np.int32), ("rank", np.int32),
    ("light_type", np.int32), ("grey", np.int32), ("no_extent", np.int32), ("_pad2", np.int32),
])

light_texture_dtype = np.dtype([
    ("right", _f4), ("up", _f4), ("origin", _f4),
    ("scale_x", np.float32), ("scale_y", np.float32),
    ("first_texel", np.int32), ("width", np.int32), ("height", np.int32), ("wrap", np.int32),
    ("textured", np.int32), ("_pad0", np.int32),
])

textured_integrand_dtype = np.dtype([
    ("beta_min", np.float32), ("beta_max", np.float32), ("n_beta", np.int32), ("rank", np.int32),
    ("gamma_samples", np.int32), ("slices", np.int32), ("textured", np.int32), ("_pad0", np.int32),
])

medium_dtype = np.dtype([
    ("box_min", _f4), ("box_max", _f4), ("grid_min", _f4), ("grid_max", _f4),
    ("height_base", np.float32), ("scale_height", np.float32),
    ("grid_nx", np.int32), ("grid_ny", np.int32), ("grid_nz", np.int32),
    ("depth_nx", np.int32), ("depth_ny", np.int32), ("depth_nz", np.int32),
    ("eye_depth_index", np.int32), ("_pad0", np.int32), ("_pad1", np.int32), ("_pad2", np.int32),
])

#: C struct name → dtype, for the layout test.
STRUCTS = {"view_t": view_dtype, "light_t": light_dtype, "frame_t": frame_dtype,
           "epipolar_t": epipolar_dtype, "integrand_t": integrand_dtype,
           "light_texture_t": light_texture_dtype, "textured_integrand_t": textured_integrand_dtype,
           "medium_t": medium_dtype}


def float4(v, w: float = 0.0) -> np.ndarray:
    """A 3-vector as float4 (w = 0 unless given)."""
    return np.array([v[0], v[1], v[2], w], dtype=np.float32)
