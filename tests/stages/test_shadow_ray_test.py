"""cl/bvh.h's ray-triangle test for shadow rays: a ray through the edge two triangles share
meets one of them, whatever float32 makes of the edge (the watertight test), where
Möller–Trumbore's barycentrics, each from a whole triangle, let some rays slip between."""
import numpy as np

from clrays.device import build_options

_PROBE = """
#include "common.h"
#include "bvh.h"

/* bvh.h's test before it was watertight: Möller–Trumbore, two-sided, edges inclusive. */
inline int moller_trumbore(float3 origin, float3 dir, float t_max, float3 v0, float3 v1, float3 v2)
{
    float3 e1 = v1 - v0, e2 = v2 - v0;
    float3 pv = cross(dir, e2);
    float det = dot(e1, pv);
    if (det == 0.0f) return 0;
    float inv = 1.0f / det;
    float3 tv = origin - v0;
    float u = dot(tv, pv) * inv;
    if (u < 0.0f || u > 1.0f) return 0;
    float3 qv = cross(tv, e1);
    float v = dot(dir, qv) * inv;
    if (v < 0.0f || u + v > 1.0f) return 0;
    float t = dot(e2, qv) * inv;
    return t > 0.0f && t < t_max;
}

/* Per ray k: from origins[k] towards targets[k], a point on the edge (q0, q1) that triangles
 * (q0, q1, a) and (q1, q0, b) share (quad k): whether each test meets either triangle. */
kernel void probe(global const float4* origins, global const float4* targets, global const float4* quads,
                  global int* watertight, global int* barycentric)
{
    int k = get_global_id(0);
    float3 origin = origins[k].xyz, dir = targets[k].xyz - origin;
    float3 q0 = quads[4 * k].xyz, q1 = quads[4 * k + 1].xyz, a = quads[4 * k + 2].xyz, b = quads[4 * k + 3].xyz;
    test_ray_t ray = test_ray(origin, dir);
    watertight[k] = ray_meets_triangle(&ray, 0.0f, 2.0f, q0, q1, a) || ray_meets_triangle(&ray, 0.0f, 2.0f, q1, q0, b);
    barycentric[k] = moller_trumbore(origin, dir, 2.0f, q0, q1, a) || moller_trumbore(origin, dir, 2.0f, q1, q0, b);
}
"""


def test_a_ray_through_a_shared_edge_meets_a_triangle(device):
    """200 000 random pairs of triangles sharing an edge (a fold of any angle, the two faces
    on either side of the ray), each crossed by a ray aimed at a float32 point of the edge
    from a random origin: every ray meets one of the two. Möller–Trumbore lets some through
    (the test of the test; measured on PoCL: 18 096 of 200 000)."""
    rng = np.random.default_rng(7)
    n = 200_000
    q0, q1 = rng.uniform(-5, 5, (n, 3)), rng.uniform(-5, 5, (n, 3))
    along = (q1 - q0) / np.linalg.norm(q1 - q0, axis=1, keepdims=True)
    origin = rng.uniform(-20, 20, (n, 3))
    target = (q0 + rng.uniform(0.05, 0.95, (n, 1)) * (q1 - q0)).astype(np.float32)  # on the edge, as float32 has it
    # the third corners on either side of the plane through the edge and the ray, so the ray crosses the fold
    side = np.cross(along, target - origin)
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    mid = 0.5 * (q0 + q1)
    in_plane = lambda x: x - side * np.sum(x * side, axis=1, keepdims=True)  # noqa: E731  (off the plane by `side` alone)
    a = mid + side * rng.uniform(0.5, 4, (n, 1)) + in_plane(rng.normal(0, 1, (n, 3)))
    b = mid - side * rng.uniform(0.5, 4, (n, 1)) + in_plane(rng.normal(0, 1, (n, 3)))
    rows = lambda x: np.concatenate([x, np.zeros((len(x), 1))], axis=1).astype(np.float32)  # noqa: E731
    quads = np.stack([rows(q0), rows(q1), rows(a), rows(b)], axis=1).reshape(-1, 4)
    program = device.cl.Program(device.context, _PROBE).build(options=build_options())
    watertight, barycentric = device.buffer(nbytes=4 * n), device.buffer(nbytes=4 * n)
    inputs = [device.buffer(array, writable=False) for array in (rows(origin), rows(target), quads)]
    program.probe(device.queue, (n,), None, *inputs, watertight, barycentric)
    missed = n - int(device.read(watertight, n, np.int32).sum())
    slipped = n - int(device.read(barycentric, n, np.int32).sum())
    print(f"rays through a shared edge that meet neither triangle: watertight {missed}, Möller–Trumbore {slipped}")
    assert slipped > 0, "the rays must test the edge (else this tests nothing)"
    assert missed == 0
