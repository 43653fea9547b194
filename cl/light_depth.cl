/* light_depth — each light's optical depth ∫ρ ds (unit density) from every voxel centre of
 * its optical-depth grid to the light, by a march through the density grid (medium.h), so
 * that a sample in the grid finds its T_l = e^{-σt·depth} by one trilinear lookup.
 * Reads medium, density_grid, lights; writes light_depth_grid (light l's depth_nx·depth_ny·
 * depth_nz floats from l·count, x fastest, over the density grid's bounds).
 *
 *     light *                    voxel centre c ── march ──> the light, clipped to the
 *            \                   box and the grid's bounds (ρ = 0 beyond them)
 *         +---\-------+
 *         |  · \ ·  · |
 *         |  ·  c·  · |
 *         +-----------+ */
#include "medium.h"

kernel void light_depth(global const medium_t* medium, global const float* density_grid,
                        global const light_t* lights, global float* light_depth_grid)
{
    int voxel = get_global_id(0), light_index = get_global_id(1);
    int nx = medium->depth_nx, ny = medium->depth_ny, count = nx * ny * medium->depth_nz;
    if (voxel >= count) return;
    float3 cell = (float3)((float)(voxel % nx), (float)((voxel / nx) % ny), (float)(voxel / (nx * ny))) + 0.5f;
    float3 size = (float3)((float)nx, (float)ny, (float)medium->depth_nz);
    float3 centre = medium->grid_min.xyz + cell / size * (medium->grid_max.xyz - medium->grid_min.xyz);
    global const light_t* light = lights + light_index;
    float3 towards;
    float reach;
    if (light->type == LIGHT_DIRECTIONAL) {
        towards = -light->direction.xyz;
        reach = INFINITY;
    } else {
        float3 w = light->position.xyz - centre;
        reach = length(w);
        towards = reach > 0.0f ? w / reach : (float3)(0.0f, 1.0f, 0.0f);
    }
    light_depth_grid[light_index * count + voxel] = segment_depth(medium, density_grid, centre, towards, 0.0f, reach);
}
