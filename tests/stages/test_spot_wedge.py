"""A spot light's cone as a wedge of γ (cl/lighting.h's ray_wedge and lit_sweep, which the
walk's ray_span takes, and cl/spot_wedge.h's unshadowed weight of 8 rays at a time): the
γ a ray sweeps inside the cone, over d_el, against the cone met along the ray itself in
float64 (the points of the ray inside the cone, their ends found by bisection)."""
import numpy as np
import pytest

from clrays import structs
from clrays.device import build_options

_PROBE = """
#include "common.h"
#include "spot_wedge.h"
/* per 8 rays: their own half-planes' wedges, 8 at a time (gather) and one at a time (the
 * walk's ray_span); and slice s's wedge for the same rays (line_samples: meant for rays in
 * s's half-plane) */
kernel void probe(global const epipolar_t* ep, global const light_t* light, global const float4* rays,
                  float4 side, global float* own, global float* by_slice, global float* walked)
{
    int first = get_global_id(0) * 8;
    float_lanes dx, dy, dz, distance;
    gather_records(rays, first + (int8)(0, 1, 2, 3, 4, 5, 6, 7), &dx, &dy, &dz, &distance);
    float3 a = ep->axis.xyz;
    float_lanes cos_beta = dot_lanes(dx, dy, dz, a.x, a.y, a.z), sin_beta = cross_length_lanes(dx, dy, dz, a.x, a.y, a.z);
    vstore8(spot_weight_lanes(ep, light, dx, dy, dz, cos_beta, sin_beta, distance), 0, own + first);
    float2 wedge = slice_wedge(ep, light, side.xyz);
    vstore8(weight_in_wedge_lanes(ep, (float_lanes)(wedge.x), (float_lanes)(wedge.y), cos_beta, sin_beta, distance),
            0, by_slice + first);
    for (int k = 0; k < 8; ++k) {
        float3 d = rays[first + k].xyz;
        float t = rays[first + k].w, sin_k = inline_length(inline_cross(d, a)), cos_k = inline_dot(d, a);
        float2 lit = lit_sweep(atan2_approx(t * sin_k, ep->d_el - t * cos_k), ray_wedge(light, a, ep->u.xyz, d, sin_k));
        walked[first + k] = inline_fmax(lit.y - lit.x, 0.0f) / ep->d_el;
    }
}
"""


def swept_inside_cone(light_position, cone_axis, cos_cone, direction, distance):
    """The γ (angle at the light from the ray back to the eye at the origin) that the ray
    direction·t, t in [0, distance], sweeps inside the cone, in float64."""

    def inside(t):
        w = np.multiply.outer(t, direction) - light_position
        return w @ cone_axis >= cos_cone * np.linalg.norm(w, axis=-1)

    t = np.linspace(0.0, distance, 4001)
    lit = inside(t)
    if not lit.any():
        return 0.0
    first, last = np.flatnonzero(lit)[[0, -1]]
    assert lit[first:last + 1].all(), "a cone meets a ray in one piece"

    def edge(outside_t, inside_t):
        for _ in range(60):
            middle = 0.5 * (outside_t + inside_t)
            outside_t, inside_t = (outside_t, middle) if inside(middle) else (middle, inside_t)
        return inside_t

    begin = t[first] if first == 0 else edge(t[first - 1], t[first])
    end = t[last] if last == len(t) - 1 else edge(t[last + 1], t[last])
    d_el = np.linalg.norm(light_position)
    axis = light_position / d_el
    sin_beta, cos_beta = np.linalg.norm(np.cross(direction, axis)), direction @ axis

    def gamma(s):
        return np.arctan2(s * sin_beta, d_el - s * cos_beta)

    return (gamma(end) - gamma(begin)) / d_el


def aimed_cone(axis, side, cone_deg, tilt):
    """A cone's axis turned from the light's ray back to the eye by 1.6 half-angles (at most
    150°) towards side s, and tilted out of s's half-plane by `tilt` rad: the eye outside the
    cone, the rays of s's half-plane meeting it at some γ."""
    theta = np.radians(min(1.6 * cone_deg, 150.0))
    normal = np.cross(axis, side)
    return np.cos(theta) * -axis + np.sin(theta) * (np.cos(tilt) * side + np.sin(tilt) * normal)


def _run_probe(device, light_position, cone_axis, cone_deg, rays, side):
    """(own, by_slice, walked): each ray's weight from its own wedge 8 at a time, from
    slice `side`'s wedge, and from its own wedge one at a time (as ray_span)."""
    d_el = np.linalg.norm(light_position)
    axis = light_position / d_el
    epipolar = np.zeros(1, structs.epipolar_dtype)
    epipolar["axis"][0, :3] = axis
    epipolar["u"][0, :3] = np.cross(axis, [0.0, 0.0, 1.0]) / np.linalg.norm(np.cross(axis, [0.0, 0.0, 1.0]))
    epipolar["d_el"] = d_el
    light = np.zeros(1, structs.light_dtype)
    light["position"][0, :3] = light_position
    light["direction"][0, :3] = cone_axis
    light["type"] = structs.LIGHT_SPOT
    light["cos_cone"] = np.cos(np.radians(cone_deg))
    outputs = [device.buffer(nbytes=4 * len(rays)) for _ in range(3)]
    program = device.cl.Program(device.context, _PROBE).build(options=build_options())
    program.probe(device.queue, (len(rays) // 8,), None, device.buffer(epipolar, writable=False),
                  device.buffer(light, writable=False), device.buffer(rays.astype(np.float32), writable=False),
                  np.append(side, 0.0).astype(np.float32), *outputs)
    return tuple(device.read(output, len(rays), np.float32) for output in outputs)


def _half_plane_wedges(light_position, cone_axis, cos_cone, directions):
    """(φ, δ) of each ray's half-plane, in float64."""
    axis = light_position / np.linalg.norm(light_position)
    sides = directions - np.outer(directions @ axis, axis)
    sides /= np.linalg.norm(sides, axis=1, keepdims=True)
    x, y = -(axis @ cone_axis), sides @ cone_axis
    return np.arctan2(y, x), np.arccos(np.clip(cos_cone / np.hypot(x, y), -1.0, 1.0))


@pytest.mark.parametrize("cone_deg", [12.0, 38.0, 89.0])
def test_weights_match_the_cone_met_along_each_ray(device, cone_deg):
    rng = np.random.default_rng(int(cone_deg))
    light_position = np.array([-0.6, 2.6, -11.5])
    d_el = np.linalg.norm(light_position)
    axis = light_position / d_el
    # rays into one half-plane of the light (to compare the slice's wedge), its side s
    side = np.cross(axis, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    beta = rng.uniform(0.02, np.pi - 0.02, 128)
    directions = np.cos(beta)[:, None] * axis + np.sin(beta)[:, None] * side
    distances = d_el * np.exp(rng.uniform(np.log(0.02), np.log(3.0), 128))  # ends before, in and past the cone
    cone_axis = aimed_cone(axis, side, cone_deg, tilt=0.1)
    rays = np.concatenate([directions, distances[:, None]], axis=1)
    own, by_slice, walked = _run_probe(device, light_position, cone_axis, cone_deg, rays, side)
    expected = np.array([swept_inside_cone(light_position, cone_axis, np.cos(np.radians(cone_deg)), d, t)
                         for d, t in zip(directions, distances)])
    assert (expected == 0).sum() >= 8 and (expected > 0).sum() >= 16, "rays that end before the cone, and in or past it"
    tolerance = 2e-6 * np.pi / d_el  # a few of atan2_approx's ulp of γ
    for name, found in (("own", own), ("by_slice", by_slice), ("walked", walked)):
        np.testing.assert_allclose(found, expected, rtol=0, atol=tolerance, err_msg=name)
        assert np.all(found[expected == 0] == 0), f"{name}: a miss weighs 0 exactly"


def test_rays_in_many_half_planes_and_the_eye_inside_the_cone(device):
    """Each ray its own half-plane: rays on the cone's side meet it, the others miss; a cone
    turned back to hold the eye, where rays start lit (γ from 0) and some leave it; and a
    cone aimed away from the eye, whose wedge lies about γ = π, so that in half of the
    half-planes it is the wedge a turn later (φ - δ < -π) that the rays past the light meet."""
    rng = np.random.default_rng(7)
    light_position = np.array([1.0, 3.0, -4.0])
    d_el = np.linalg.norm(light_position)
    axis = light_position / d_el
    side = np.cross(axis, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    directions = rng.normal(size=(128, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions[64:] = axis + 0.4 * directions[64:]  # half of them about the light, to pass it
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    distances = rng.uniform(0.2, 3.0 * d_el, 128)
    rays = np.concatenate([directions, distances[:, None]], axis=1)
    tolerance = 2e-6 * np.pi / d_el
    away = axis + np.array([0.2, -0.1, 0.0])
    cones = {"aside": (aimed_cone(axis, side, 25.0, tilt=0.3), 25.0), "eye inside": (-axis, 20.0),
             "away": (away / np.linalg.norm(away), 40.0)}
    for name, (cone_axis, cone_deg) in cones.items():
        cos_cone = np.cos(np.radians(cone_deg))
        own, _, walked = _run_probe(device, light_position, cone_axis, cone_deg, rays, side)
        expected = np.array([swept_inside_cone(light_position, cone_axis, cos_cone, d, t)
                             for d, t in zip(directions, distances)])
        if name == "eye inside":  # every ray starts lit, and most leave the cone before their end
            whole_ray = np.array([swept_inside_cone(light_position, cone_axis, -1.0, d, t)
                                  for d, t in zip(directions, distances)])
            assert np.all(expected > 0) and (expected < 0.5 * whole_ray).sum() >= 16
        else:
            assert (expected > 0).sum() >= 16 and (expected == 0).sum() >= 16
        if name == "away":
            phi, delta = _half_plane_wedges(light_position, cone_axis, cos_cone, directions)
            assert ((phi - delta < -np.pi) & (expected > 0)).sum() >= 8, "rays that meet the wedge a turn later"
        for label, found in (("own", own), ("walked", walked)):
            np.testing.assert_allclose(found, expected, rtol=0, atol=tolerance, err_msg=f"{name}: {label}")
            assert np.all(found[expected == 0] == 0), f"{name}: {label}: a miss weighs 0 exactly"
