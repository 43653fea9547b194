/* minmax.h — the layout of the min-max tree: the 1D min-max mipmap of each epipolar
 * slice (docs/design.md §4, §5). rectify writes level 0, minmax the levels above it,
 * traverse walks them.
 *
 * Row α of the tree holds slice α's whole mip chain, packed in one row of 2N float2
 * (min, max) nodes, N = gamma_samples (a power of two), L = log2(N):
 *
 *   node  0                   N              N + N/2              2N - 2       2N - 1
 *         | level 0: N texels | level 1: N/2 | level 2: N/4 | ... | level L: 1 | unused |
 *
 * Level 0 is S[α, γ] itself (min = max = S). Node i of level k covers texels
 * [i·2^k, (i + 1)·2^k) and is (min of the mins, max of the maxes) of nodes 2i and
 * 2i + 1 of level k - 1. */
#ifndef CLRAYS_MINMAX_H
#define CLRAYS_MINMAX_H

/* Offset of level k inside a row of 2N nodes: N + N/2 + ... (k terms) = 2N - 2N/2^k. */
inline int level_offset(int gamma_samples, int level)
{
    return 2 * gamma_samples - (2 * gamma_samples >> level);
}

#endif
