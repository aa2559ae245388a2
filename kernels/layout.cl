/* layout.cl — the layout stage: a flat volume (x fastest) to PE-major cells
 * with halo, and back. Geometry arguments as in common.cl; the layout is
 * described in host/include/simdvol/pe_array.hpp.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

/* simdvol_layout: one work-item per (PE, padded row), launched over
 * pes * by * bz work-items (rounded up to WGS) with local size WGS.
 * Work-item g takes PE pe_of_cell[c * sx + ix] and its row r, where
 * (ix, r, c) = (g % sx, (g / sx) % (by * bz), g / (sx * by * bz)) and c =
 * iy + sy * iz: the sx PEs of one row of cells (splits (sx, sy, sz)) come
 * one after the other for each row r, so consecutive work-items read one
 * volume row from left to right. Row r of a PE is (ly, lz) = (r % by - h,
 * r / by - h); the work-item copies its bx values, x clamped into the
 * volume, to the contiguous row of the block (8 at a time where the whole
 * row lies inside the volume). The last row of each block also zeroes the
 * block's alignment tail.
 *
 * Why rows: three variants were timed (PoCL 3.1, 2 cores, 256^3, kernel
 * time from profiling events, best of 7, a loaded shared machine so only
 * ratios mean much): one work-item per buffer element (simdvol_layout_voxel)
 * was 4-7x slower than rows, its four integer divisions per element
 * dominating; one work-item per PE looping over its whole cell was 0.7-1.3x
 * the time of rows at P = 512 and 8192, but gives only P work-items, i.e. a
 * single work-group on one thread for P <= 64. Rows keeps >= 32 groups for
 * every P and amortises the divisions over a row. The same holds for the
 * gather kernels (rows 4-10x faster than per voxel). Why this order: with
 * the rows of one PE after one another (the first form), each volume row was
 * read in pieces of bx floats by sx PEs far apart in time, so a 256^3
 * volume (64 MiB, more than the L3) came from memory about twice; the
 * 256^3 phantom's layout took 33-37 ms against 20-30 ms in this order, and
 * ch2's 20-26 against 11-14 ms (simdvol-bench, alternated three times). */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_layout(
    __global const float* restrict volume, __global float* restrict cells,
    __global const int4* restrict origins, __global const int* restrict pe_of_cell, int4 dims,
    int4 cell, int4 block, int4 splits) {
  const int rows = block.y * block.z;
  const size_t gid = get_global_id(0);
  if (gid >= (size_t)splits.x * (size_t)splits.y * (size_t)splits.z * (size_t)rows) return;
  const int ix = (int)(gid % (size_t)splits.x);
  const size_t t = gid / (size_t)splits.x;
  const int r = (int)(t % (size_t)rows);
  const int c = (int)(t / (size_t)rows);
  const int p = pe_of_cell[c * splits.x + ix];
  const int h = cell.w;
  const int ly = r % block.y - h;
  const int lz = r / block.y - h;
  const int4 o = origins[p];
  const int y = clamp(o.y + ly, 0, dims.y - 1);
  const int z = clamp(o.z + lz, 0, dims.z - 1);
  __global const float* src = volume + sv_flat_index(dims, 0, y, z);
  __global float* dst = cells + sv_block_start(block, p) + (size_t)r * (size_t)block.x;
  const int x0 = o.x - h;
  if (x0 >= 0 && x0 + block.x <= dims.x) {
    __global const float* s = src + x0;
    int i = 0;
    for (; i + 8 <= block.x; i += 8) vstore8(vload8(0, s + i), 0, dst + i);
    for (; i < block.x; ++i) dst[i] = s[i];
  } else {
    for (int i = 0; i < block.x; ++i) dst[i] = src[clamp(x0 + i, 0, dims.x - 1)];
  }
  if (r == rows - 1) {
    __global float* tail = cells + sv_block_start(block, p);
    for (int i = rows * block.x; i < block.w; ++i) tail[i] = 0.0f;
  }
}

/* simdvol_layout_voxel: the alternative, one work-item per element of the
 * PE-major buffer (pes * stride work-items). Kept for benchmarking. */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_layout_voxel(
    __global const float* restrict volume, __global float* restrict cells,
    __global const int4* restrict origins, int4 dims, int4 cell, int4 block, int pes) {
  const size_t gid = get_global_id(0);
  if (gid >= (size_t)pes * (size_t)block.w) return;
  const int p = (int)(gid / (size_t)block.w);
  const int e = (int)(gid - (size_t)p * (size_t)block.w);
  if (e >= block.x * block.y * block.z) {
    cells[gid] = 0.0f;
    return;
  }
  const int h = cell.w;
  const int row = e / block.x;
  const int4 o = origins[p];
  const int x = clamp(o.x + (e - row * block.x) - h, 0, dims.x - 1);
  const int y = clamp(o.y + row % block.y - h, 0, dims.y - 1);
  const int z = clamp(o.z + row / block.y - h, 0, dims.z - 1);
  cells[gid] = volume[sv_flat_index(dims, x, y, z)];
}

/* simdvol_gather: the inverse for interior voxels. One work-item per
 * (PE, interior row), pes * cy * cz work-items with local size WGS; rows and
 * voxels past the volume's far edge (padding) are skipped. */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_gather(
    __global const float* restrict cells, __global float* restrict volume,
    __global const int4* restrict origins, int4 dims, int4 cell, int4 block, int pes) {
  const int rows = cell.y * cell.z;
  const size_t gid = get_global_id(0);
  if (gid >= (size_t)pes * (size_t)rows) return;
  const int p = (int)(gid / (size_t)rows);
  const int r = (int)(gid - (size_t)p * (size_t)rows);
  const int ly = r % cell.y;
  const int lz = r / cell.y;
  const int4 o = origins[p];
  const int y = o.y + ly;
  const int z = o.z + lz;
  if (y >= dims.y || z >= dims.z || o.x >= dims.x) return;
  const int n = min(cell.x, dims.x - o.x);
  __global const float* src =
      cells + sv_block_start(block, p) + sv_block_offset(cell, block, 0, ly, lz);
  __global float* dst = volume + sv_flat_index(dims, o.x, y, z);
  for (int i = 0; i < n; ++i) dst[i] = src[i];
}

/* simdvol_gather_voxel: the alternative, one work-item per flat voxel; the PE
 * comes from pe_of_cell[(iz * sy + iy) * sx + ix] with splits (sx, sy, sz).
 * Kept for benchmarking. */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_gather_voxel(
    __global const float* restrict cells, __global float* restrict volume,
    __global const int4* restrict origins, __global const int* restrict pe_of_cell, int4 dims,
    int4 cell, int4 block, int4 splits) {
  const size_t gid = get_global_id(0);
  const size_t row = gid / (size_t)dims.x;
  if (row >= (size_t)dims.y * (size_t)dims.z) return;
  const int x = (int)(gid - row * (size_t)dims.x);
  const int y = (int)(row % (size_t)dims.y);
  const int z = (int)(row / (size_t)dims.y);
  const int ix = x / cell.x, iy = y / cell.y, iz = z / cell.z;
  const int p = pe_of_cell[(iz * splits.y + iy) * splits.x + ix];
  const int4 o = origins[p];
  volume[gid] =
      cells[sv_block_start(block, p) + sv_block_offset(cell, block, x - o.x, y - o.y, z - o.z)];
}
