/* light_depth — each light's optical depth ∫ρ ds (unit density) from every node of its
 * optical-depth grid to the light, by a march through the density grid (medium.h), so that a
 * sample in the grid finds its T_l = e^{-σt·depth} by one trilinear lookup (nodes_trilinear);
 * and the eye's, at medium->eye_depth_index after the lights', for T_e (eye_path_depth).
 * Reads medium, density_grid, lights; writes light_depth_grid (light l's depth_nx·depth_ny·
 * depth_nz floats from l·count, x fastest; the nodes span the density grid's bounds corner
 * to corner, so a lookup anywhere inside them interpolates and never holds a value).
 *
 *     light *                    node c ── march ──> the light, clipped to the box and
 *            \                   the grid's bounds (ρ = 0 beyond them)
 *         c---\--c---c
 *         |    \  |   |
 *         c---c-\-c---c
 *         |   |  \|   |
 *         c---c---c---c */
#include "medium.h"

/* Each node's march is made once a frame: finer steps than a per-sample march (medium.h's
 * GRID_STEPS_PER_VOXEL) quarter the midpoint rule's error across the voxel-centre kinks. */
#define LIGHT_DEPTH_STEPS_PER_VOXEL 4.0f

kernel void light_depth(global const medium_t* medium, global const float* density_grid,
                        global const light_t* lights, global float* light_depth_grid)
{
    int node_index = get_global_id(0), light_index = get_global_id(1);
    int nx = medium->depth_nx, ny = medium->depth_ny, count = nx * ny * medium->depth_nz;
    if (node_index >= count) return;
    float3 node = (float3)((float)(node_index % nx), (float)((node_index / nx) % ny), (float)(node_index / (nx * ny)));
    float3 last = (float3)((float)(nx - 1), (float)(ny - 1), (float)(medium->depth_nz - 1));
    float3 node_position = medium->grid_min.xyz + node / last * (medium->grid_max.xyz - medium->grid_min.xyz);
    float3 towards;
    float reach;
    if (light_index == medium->eye_depth_index) { /* the eye, at the origin of eye space */
        reach = length(node_position);
        towards = reach > 0.0f ? -node_position / reach : (float3)(0.0f, 1.0f, 0.0f);
    } else {
        reach = toward_light(lights + light_index, node_position, &towards);
    }
    float t0 = 0.0f;
    light_depth_grid[light_index * count + node_index] =
        medium_extent(medium, node_position, towards, &t0, &reach)
            ? grid_march_depth(medium, density_grid, node_position, towards, t0, reach, LIGHT_DEPTH_STEPS_PER_VOXEL)
            : 0.0f;
}
