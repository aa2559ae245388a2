/* common.cl — helpers shared by every simdvol kernel file.
 *
 * Each stage file starts with
 *   #ifndef SIMDVOL_COMMON_CL
 *   #include "common.cl"
 *   #endif
 * so it compiles on its own (with -I kernels) and, in the source the host
 * assembles (defines + simdvol_shared.h + common.cl + stage.cl), skips the
 * #include because the guard is already defined.
 *
 * Cell buffers (see host/include/simdvol/pe_array.hpp): PE p's padded block
 * starts at p * stride floats; local position (lx, ly, lz), each in
 * [-halo, cell + halo), is at ((lz + halo) * by + (ly + halo)) * bx + lx + halo
 * with block = (bx, by, bz) = cell + 2 * halo. Kernels receive the geometry as
 *   int4 dims   volume nx, ny, nz (w unused)
 *   int4 cell   interior cell extent cx, cy, cz; w = halo
 *   int4 block  padded extent bx, by, bz; w = stride (floats per PE block)
 *   global const int4* origins   first voxel of each PE's cell (w unused)
 */
#ifndef SIMDVOL_COMMON_CL
#define SIMDVOL_COMMON_CL

#ifndef SIMDVOL_SHARED_H
#include "simdvol_shared.h"
#endif

/* Work-group size of 1-D kernels; the host passes the same value as the
 * local size. */
#ifndef WGS
#define WGS 64
#endif

/* Index of local position (lx, ly, lz) within a PE's block (not counting the
 * block's start p * stride). */
SV_FN size_t sv_block_offset(int4 cell, int4 block, int lx, int ly, int lz) {
  const int h = cell.w;
  return ((size_t)(lz + h) * (size_t)block.y + (size_t)(ly + h)) * (size_t)block.x +
         (size_t)(lx + h);
}

/* Start of PE p's block. */
SV_FN size_t sv_block_start(int4 block, int p) {
  return (size_t)p * (size_t)block.w;
}

/* Index of voxel (x, y, z) in a flat volume, x fastest. */
SV_FN size_t sv_flat_index(int4 dims, int x, int y, int z) {
  return ((size_t)z * (size_t)dims.y + (size_t)y) * (size_t)dims.x + (size_t)x;
}

#endif /* SIMDVOL_COMMON_CL */
