"""Stage rectify against numpy: level 0 of the min-max tree, S[α, γ], equals the β of the
blocker that a plain numpy walk finds along the same light rays through the same
shadow-map texels (cl/rectify.cl; docs/design.md §2, §3)."""
import math

import numpy as np
import pytest

from clrays import structs
from clrays.device import StageTimer
from clrays.inputs import frame_inputs, upload
from clrays.scene.geometry import box_triangles
from clrays.scene.model import Phase
from clrays.stages.raster import raster, read_shadow_depth
from clrays.stages.rectify import rectify
from conftest import DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, v3

PI_F = float(np.float32(math.pi))  # S of an unblocked light ray, as the kernel writes it

# Where a light ray passes within this many texels of a texel's edge (or this fraction of a
# cube-face edge), float32 on the device and float64 here may pick either neighbour.
TEXEL_SLACK = 1e-3
# S from the same texel: float32 angles (α, γ, atan2) against float64, in radians.
BETA_TOLERANCE = 1e-6

LIGHTS = {
    "point": PointLight(v3(0.4, 4.5, -0.6), np.full(3, 40.0)),  # cube map, the epipole on screen
    "spot": SpotLight(v3(0.3, 5.0, -0.5), v3(0.1, -1.0, 0.1) / np.linalg.norm([0.1, -1.0, 0.1]), 35.0,
                      np.full(3, 60.0)),  # one perspective view
    "directional": DirectionalLight(v3(0.35, -1.0, -0.25) / np.linalg.norm([0.35, -1.0, -0.25]),
                                    np.full(3, 1.5)),  # one orthographic view
}


def _scene(light):
    triangles = np.concatenate([grid_plane(0.0, 8.0, 4), box_triangles([-1.0, 1.2, -1.0], [1.0, 1.6, 0.8]),
                                box_triangles([1.5, 0.0, -2.0], [2.3, 2.5, -1.2])])
    return make_scene(triangles, [light], width=48, height=32, position=(0, 2.5, 8), look_at=(0, 2.0, 0),
                      shadow_map=128, slices=48, gamma_samples=128)


def _epipolar_of(device, scene):
    """The frame's buffers, its raster stage (the camera and every light's map, as
    `stages.raster.raster` wires them) and the first light rectified."""
    buffers = upload(device, frame_inputs(scene))
    timer = StageTimer()
    rastered = raster(device, buffers, timer)
    return buffers, rastered, rectify(device, buffers, rastered, 0, timer)


def _rectified(device, scene):
    """Raster and rectify the first light; returns the frame inputs, the epipolar params,
    the shadow depths and level 0 of the tree (slices × N)."""
    buffers, rastered, epipolar = _epipolar_of(device, scene)
    params = device.read(epipolar.buffer, (), structs.epipolar_dtype)  # as the kernels read it: γ step included
    n, slices = int(params["gamma_samples"]), int(params["slices"])
    tree = device.read(epipolar.tree, (slices, 2 * n, 2), np.float32)
    shadow = read_shadow_depth(device, rastered.shadow_depth, buffers.inputs.shadow_texels,
                               rastered.depth_in_keys)
    return buffers.inputs, params, shadow, tree[:, :n]


def _vector(field) -> np.ndarray:
    return np.asarray(field, dtype=np.float64)[:3]


def _stored_depth(view, shadow, texel_x, texel_y, clamp):
    """The blocker depth at continuous texel coordinates, as `shadow_texel` reads it
    ((int) truncates towards zero, then clamps to the map); +inf off the map unless `clamp`."""
    width, height = int(view["width"]), int(view["height"])
    tx, ty = np.trunc(texel_x).astype(np.int64), np.trunc(texel_y).astype(np.int64)
    inside = (texel_x >= 0) & (texel_y >= 0) & (texel_x < width) & (texel_y < height)
    tx, ty = np.clip(tx, 0, width - 1), np.clip(ty, 0, height - 1)
    stored = shadow[int(view["depth_offset"]) + ty * width + tx].astype(np.float64)
    return stored if clamp else np.where(inside, stored, np.inf)


def _project(view, points):
    """Continuous texel coordinates and whether the point is in front (`view_project`)."""
    q = points - _vector(view["origin"])
    x, y, z = q @ _vector(view["right"]), q @ _vector(view["up"]), q @ _vector(view["forward"])
    if int(view["projection"]) == structs.PROJECTION_PERSPECTIVE:
        in_front = z > 0
        z = np.where(in_front, z, 1.0)
        sx, sy = x / (z * float(view["scale_x"])), y / (z * float(view["scale_y"]))
    else:
        in_front = np.ones(len(points), bool)
        sx, sy = x / float(view["scale_x"]), y / float(view["scale_y"])
    width, height = int(view["width"]), int(view["height"])
    return (sx + 1) * 0.5 * width, (1 - sy) * 0.5 * height, in_front


def _cube_faces(light, w):
    """The face `light_view_index` picks for direction w, and the runner-up major axis's
    face where the two are within TEXEL_SLACK (an edge of the cube)."""
    first = int(light["first_view"])
    if int(light["view_count"]) == 1:
        return [np.full(len(w), first)]
    magnitude = np.abs(w)
    order = np.argsort(-magnitude, axis=1, kind="stable")
    faces = []
    for rank in (0, 1):
        axis = order[:, rank]
        component = w[np.arange(len(w)), axis]
        faces.append(first + 2 * axis + (component < 0))
    near_edge = (magnitude[np.arange(len(w)), order[:, 0]] - magnitude[np.arange(len(w)), order[:, 1]]
                 < TEXEL_SLACK * magnitude.max(axis=1))
    return [faces[0], np.where(near_edge, faces[1], faces[0])]


def numpy_rectify(inputs, params, shadow) -> np.ndarray:
    """Every S[α, γ] the kernel may write: (candidates, slices, N), the first candidate the
    texel the light ray meets, the others its neighbours across an edge within TEXEL_SLACK."""
    light = inputs.lights[int(params["light_index"])]
    views = inputs.views
    n, slices = int(params["gamma_samples"]), int(params["slices"])
    alpha = float(params["alpha_min"]) + (np.arange(slices) + 0.5) * float(params["alpha_step"])
    gamma = structs.texel_gamma(float(np.float32(params["gamma_step"])), n, np.arange(n) + 0.5,
                                float(params["gamma_warp"]))
    gamma[0] = 0.0  # texel 0 is the eye's own light ray
    alpha, gamma = np.meshgrid(alpha, gamma, indexing="ij")
    alpha, gamma = alpha.ravel(), gamma.ravel()
    r = np.cos(alpha)[:, None] * _vector(params["u"]) + np.sin(alpha)[:, None] * _vector(params["w"])
    axis, d_el = _vector(params["axis"]), float(params["d_el"])
    offsets = [(0.0, 0.0)] + [(dx, dy) for dx in (-TEXEL_SLACK, 0.0, TEXEL_SLACK)
                              for dy in (-TEXEL_SLACK, 0.0, TEXEL_SLACK) if dx or dy]
    candidates = []
    if int(light["type"]) == structs.LIGHT_DIRECTIONAL:
        # Light ray γ·r + t·ω; the orthographic map stores depth along -ω from its origin.
        view = views[int(light["first_view"])]
        texel_x, texel_y, _ = _project(view, gamma[:, None] * r)
        to_blocker = -float(_vector(view["origin"]) @ _vector(view["forward"]))
        for dx, dy in offsets:
            stored = _stored_depth(view, shadow, texel_x + dx, texel_y + dy, clamp=False)
            candidates.append(np.where(np.isinf(stored), PI_F, np.arctan2(gamma, to_blocker - stored)))
    else:
        # Light ray from l at angle γ to l → e, in slice α; the blocker at its stored distance.
        direction = -axis * np.cos(gamma)[:, None] + r * np.sin(gamma)[:, None]
        probe = _vector(light["position"]) + direction
        for face in _cube_faces(light, direction):
            for dx, dy in offsets:
                stored = np.full(len(gamma), np.inf)
                for index in np.unique(face):
                    view, mine = views[index], face == index
                    texel_x, texel_y, in_front = _project(view, probe[mine])
                    depth = _stored_depth(view, shadow, texel_x + dx, texel_y + dy, clamp=True)
                    stored[mine] = np.where(in_front, depth, np.inf)
                with np.errstate(invalid="ignore"):
                    beta = np.arctan2(stored * np.sin(gamma), d_el - stored * np.cos(gamma))
                candidates.append(np.where(np.isinf(stored), PI_F, beta))
    return np.array(candidates).reshape(-1, slices, n)


@pytest.mark.parametrize("kind", LIGHTS)
def test_rectify_matches_numpy_walk_of_the_shadow_map(device, kind):
    inputs, params, shadow, level0 = _rectified(device, _scene(LIGHTS[kind]))
    assert (level0[..., 0] == level0[..., 1]).all(), "level 0 holds (S, S)"
    rectified = level0[..., 0].astype(np.float64)
    blocked = rectified < PI_F
    assert 0.05 < blocked.mean() < 0.95, "the scene should mix blocked and unblocked light rays"
    assert (rectified[~blocked] == PI_F).all()
    assert (rectified >= 0).all()

    candidates = numpy_rectify(inputs, params, shadow)
    error = np.abs(candidates - rectified).min(axis=0)
    same_texel = np.abs(candidates[0] - rectified) <= BETA_TOLERANCE
    print(f"{kind}: max |ΔS| {error.max():.2e} rad; {1 - same_texel.mean():.2%} of texels from a neighbour")
    worst = np.unravel_index(np.argmax(error), error.shape)
    assert error.max() <= BETA_TOLERANCE, f"slice, texel {worst}: device {rectified[worst]}"
    assert same_texel.mean() > 0.99, "only light rays on a texel's edge may read its neighbour"


@pytest.mark.parametrize("kind", LIGHTS)
@pytest.mark.parametrize("batches", [1, 3])
def test_rectify_batches_give_the_same_texture(device, monkeypatch, kind, batches):
    # A CPU's rectify work-item takes 8 batches of 8 texels, a GPU's one (rectify_batches):
    # the texture must be the same bits however many (3: an item's last batches past the
    # row's end, whose lanes compute the last texel again and store nothing). A row is a
    # power of two of texels, at least 16 (epipolar_frame), so a batch lies wholly in it or
    # wholly past it.
    import clrays.stages.rectify as rectify_stage

    scene = _scene(LIGHTS[kind])
    _, _, _, level0 = _rectified(device, scene)
    monkeypatch.setattr(rectify_stage, "rectify_batches", lambda device: batches)
    _, _, _, other = _rectified(device, scene)
    assert np.array_equal(level0.view(np.uint32), other.view(np.uint32))


@pytest.mark.parametrize("kind", LIGHTS)
def test_bounds_match_numpy_over_the_camera_samples(device, kind):
    # rectify_bounds reduces pseudo-angles (tan(θ/2), 2 - cot(θ/2)) on the device and the
    # host takes the arc tangent of the extremes: the β range and γ_max must be those of
    # a float64 loop over the same camera samples (docs/design.md §4.2).
    from clrays.scene.camera import primary_rays

    scene = _scene(LIGHTS[kind])
    buffers, rastered, epipolar = _epipolar_of(device, scene)
    depth = device.read(rastered.camera_depth, buffers.inputs.samples, np.uint32).view(np.float32).astype(np.float64)
    distance = np.minimum(depth, float(buffers.inputs.params["far"]))
    dirs = primary_rays(scene.camera, scene.image).reshape(-1, 3)
    axis = _vector(epipolar.params["axis"])
    cos_beta, sin_beta = dirs @ axis, np.linalg.norm(np.cross(dirs, axis), axis=1)
    beta = np.arctan2(sin_beta, cos_beta)
    d_el = epipolar.d_el
    gamma = distance * sin_beta if kind == "directional" else np.arctan2(distance * sin_beta,
                                                                         d_el - distance * cos_beta)
    # float32 directions and products on the device against float64 here.
    assert epipolar.beta_min == pytest.approx(beta.min(), abs=2e-6)
    assert epipolar.beta_max == pytest.approx(min(beta.max(), math.pi), abs=2e-6)
    assert epipolar.gamma_max == pytest.approx(gamma.max(), rel=2e-6, abs=2e-6)


def test_angle_of_pseudo_inverts_the_pseudo_angle():
    from clrays.stages.rectify import angle_of_pseudo

    theta = np.linspace(0.0, math.pi, 1001)
    q = np.where(theta <= math.pi / 2, np.tan(theta / 2), 2.0 - 1.0 / np.tan(np.maximum(theta, 1e-300) / 2))
    assert np.allclose([angle_of_pseudo(v) for v in q], theta, rtol=0, atol=1e-12)
    assert angle_of_pseudo(math.inf) == math.inf


@pytest.mark.parametrize("kind", LIGHTS)
def test_device_ranges_are_the_host_rules_bits(device, kind):
    """The β and γ ranges stay on the device (rectify_ranges, integrand_rows): the γ step,
    texel angles, ranges and integrand rows they give are the bits the host's float64
    rules give from the same bounds, so moving them changed no image."""
    from clrays.stages.integrand import build_integrand, device_rows, pack_integrand, table_rows
    from clrays.stages.rectify import _defines, texel_angles

    scene = _scene(LIGHTS[kind])
    buffers, _, epipolar = _epipolar_of(device, scene)
    beta_min, beta_max, gamma_max, gamma_step = epipolar.visible.host()
    assert 0.0 <= beta_min < beta_max <= math.pi and gamma_max > 0
    on_device = device.read(epipolar.buffer, (), structs.epipolar_dtype)
    assert on_device["gamma_step"] == np.float32(gamma_max / int(epipolar.params["gamma_samples"]))
    assert on_device["gamma_step"] == np.float32(gamma_step)
    assert on_device["gamma_warp"] == np.float32(0.0 if kind == "directional" else structs.GAMMA_TEXEL_WARP)
    ranges = device.read(epipolar.visible.ranges, 4, np.float32)
    expected = np.array([beta_min, beta_max, gamma_max, 1.0 / max(beta_max - beta_min, 1e-6)]).astype(np.float32)
    np.testing.assert_array_equal(ranges, expected)
    n = int(on_device["gamma_samples"])
    angles = device.buffer(nbytes=16 * n)  # rectify_ranges again, its texel angles kept this time
    device.kernel("rectify", "rectify_ranges", _defines(device))(
        device.queue, (n,), None, epipolar.visible.bounds, buffers.lights, epipolar.buffer, angles,
        device.buffer(nbytes=16))
    np.testing.assert_array_equal(device.read(angles, (n, 4), np.float32), texel_angles(on_device, gamma_step))

    light = scene.lights[0]
    directional = isinstance(light, DirectionalLight)
    power = light.irradiance if directional else light.intensity
    tables = build_integrand("table", "directional" if directional else "point", scene.medium.sigma_s,
                             scene.medium.sigma_t, Phase("hg", 0.35), power, epipolar.d_el, beta_min, beta_max,
                             gamma_max, n_beta=64, n_gamma=64, s_max=30.0, rows=False)
    params = device.buffer(pack_integrand(tables)[0].reshape(1))
    rows = device_rows(device, tables, epipolar.visible, params)
    np.testing.assert_array_equal(device.read(rows, (64, 4), np.float32), table_rows(tables))
    written = device.read(params, (), structs.integrand_dtype)
    assert written["beta_min"] == np.float32(beta_min) and written["beta_max"] == np.float32(beta_max)


def _along_the_axis(light, sampling="epipolar", method="minmax", wall=True):
    """A 1×1 image whose one ray runs along `light`'s epipolar axis (to a wall before the
    light, or into the open): no visible ray has extent in γ. A second light lights the fog."""
    triangles = np.array([[[3, -5, -5], [3, 5, -5], [3, -5, 5]], [[3, 5, -5], [3, 5, 5], [3, -5, 5]]], float)
    return make_scene(triangles if wall else None, [light, PointLight(v3(1, 3, 1), np.full(3, 30.0))], width=1,
                      height=1, position=(0, 1, 0), look_at=(5, 1, 0), slices=16, gamma_samples=16, shadow_map=64,
                      sampling=sampling, method=method, aovs=("in_scatter_light0", "in_scatter_light1"))


@pytest.mark.parametrize("light, wall", [(DirectionalLight(v3(-1, 0, 0), np.full(3, 2.0)), True),
                                         (DirectionalLight(v3(-1, 0, 0), np.full(3, 2.0)), False),
                                         (PointLight(v3(5, 1, 0), np.full(3, 30.0)), True)],
                         ids=["directional", "directional-open", "point"])
@pytest.mark.parametrize("sampling, method", [("epipolar", "minmax"), ("pixel", "minmax"),
                                              ("pixel", "volume_moments")])
def test_no_visible_extent_in_gamma_adds_nothing(device, monkeypatch, light, wall, sampling, method):
    """γ_max = 0 (the one ray along the light's axis): the host no longer reads the bounds
    to skip the light, the device finds every ray's span empty instead (integrand_t's
    no_extent), and the light's in-scattering is exactly 0, as when it was skipped, while
    the other light's is not. Its texture spans γ ∈ [0, 1]."""
    import clrays.session
    from clrays.session import Renderer

    built = []
    monkeypatch.setattr(clrays.session, "rectify", lambda *args: built.append(rectify(*args)) or built[-1])
    result = Renderer(device, reuse=False).render(_along_the_axis(light, sampling, method, wall))
    assert built[0].gamma_max == 0.0 and built[0].gamma_step == np.float32(1 / 16) and built[1].gamma_max > 0
    assert np.all(result.passes["in_scatter_light0"] == 0.0)
    assert np.all(result.passes["in_scatter_light1"] > 0) and np.all(np.isfinite(result.image))


def test_gamma_texels_grow_from_the_eyes_light_ray():
    """A point or spot light's γ texels span [0, N·gamma_step] (structs.texel_gamma), finest at
    γ = 0 and growing evenly: with W = 0.7 the first is 0.3 of the even width, the last 1.7;
    texel_coordinate inverts texel_gamma."""
    n, step, warp = 1024, 3e-3, structs.GAMMA_TEXEL_WARP
    edges = structs.texel_gamma(step, n, np.arange(n + 1), warp)
    widths = np.diff(edges)
    assert edges[0] == 0.0 and edges[-1] == pytest.approx(n * step, rel=1e-12)
    assert np.all(widths > 0) and np.all(np.diff(widths) > 0)
    assert widths[0] / step == pytest.approx(0.3, abs=1e-3) and widths[-1] / step == pytest.approx(1.7, abs=1e-3)
    np.testing.assert_allclose(structs.texel_coordinate(step, n, edges, warp), np.arange(n + 1), atol=1e-9)
    # A directional light's γ is a length, even along the ray: its texels stay even.
    np.testing.assert_allclose(structs.texel_gamma(step, n, np.arange(n + 1), 0.0), step * np.arange(n + 1))
    np.testing.assert_allclose(structs.texel_coordinate(step, n, step * np.arange(n + 1), 0.0), np.arange(n + 1))
