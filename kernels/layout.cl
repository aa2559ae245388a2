/* layout.cl — the layout stage: a flat volume (x fastest) to PE-major cells
 * with halo, and back. Geometry arguments as in common.cl; the layout is
 * described in host/include/simdvol/pe_array.hpp.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

/* simdvol_layout: one work-item per padded row of a row of cells,
 * launched over sy * sz * by * bz work-items (splits (sx, sy, sz); rounded
 * up to WGS) with local size WGS. Work-item g takes row r = g % (by * bz)
 * of the sx cells c = g / (by * bz) = iy + sy * iz, PEs pe_of_cell[c * sx +
 * ix] for ix = 0 .. sx - 1, left to right: one volume row read once, from
 * left to right. Row r of a cell is (ly, lz) = (r % by - h, r / by - h);
 * each PE's bx values, x clamped into the volume, go to the contiguous row
 * of its block (8 at a time where they lie inside the volume). Cells are
 * uniform (pe_array.hpp): cell (ix, iy, iz) starts at (ix cx, iy cy, iz cz).
 * The work-item of the blocks' last row also zeroes their alignment tails.
 *
 * Why rows: three variants were timed (PoCL 3.1, 2 cores, 256^3, kernel
 * time from profiling events, best of 7, a loaded shared machine so only
 * ratios mean much): one work-item per buffer element (simdvol_layout_voxel)
 * was 4-7x slower than rows, its four integer divisions per element
 * dominating; one work-item per PE looping over its whole cell was 0.7-1.3x
 * the time of rows at P = 512 and 8192, but gives only P work-items, i.e. a
 * single work-group on one thread for P <= 64. The same holds for the
 * gather kernels (rows 4-10x faster than per voxel). Why whole rows of
 * cells: with the rows of one PE after one another (the first form), each
 * volume row was read in pieces of bx floats by sx PEs far apart in time,
 * so a 256^3 volume (64 MiB, more than the L3) came from memory about
 * twice, and each piece paid the row's index arithmetic. simdvol-bench,
 * layout stage at 8,192 PEs, alternated three times: one work-item per (PE,
 * row) with the sx PEs of a row of cells one after the other 26-28 ms
 * (phantom), 6.2-7.6 (brainsmall), 11.3-13.4 (ch2); one work-item per row
 * of cells 19.9-22.4, 3.9-4.2, 9.0-11.2 ms. (The first form: 37-41 ms on
 * the phantom.) The range has sy * sz * by * bz work-items, at least
 * by * bz >= 9. */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_layout(
    __global const float* restrict volume, __global float* restrict cells,
    __global const int4* restrict origins, __global const int* restrict pe_of_cell, int4 dims,
    int4 cell, int4 block, int4 splits) {
  const int rows = block.y * block.z;
  const size_t gid = get_global_id(0);
  if (gid >= (size_t)splits.y * (size_t)splits.z * (size_t)rows) return;
  const int r = (int)(gid % (size_t)rows);
  const int c = (int)(gid / (size_t)rows);
  const int h = cell.w;
  const int ly = r % block.y - h;
  const int lz = r / block.y - h;
  __global const int* row_pes = pe_of_cell + (size_t)c * (size_t)splits.x;
  const int4 o = origins[row_pes[0]];
  const int y = clamp(o.y + ly, 0, dims.y - 1);
  const int z = clamp(o.z + lz, 0, dims.z - 1);
  __global const float* src = volume + sv_flat_index(dims, 0, y, z);
  for (int ix = 0; ix < splits.x; ++ix) {
    const int p = row_pes[ix];
    const int x0 = ix * cell.x - h;
    __global float* dst = cells + sv_block_start(block, p) + (size_t)r * (size_t)block.x;
    if (x0 >= 0 && x0 + block.x <= dims.x) {
      __global const float* s = src + x0;
      int i = 0;
      for (; i + 8 <= block.x; i += 8) vstore8(SV_VLOAD8(s + i), 0, dst + i);
      for (; i < block.x; ++i) dst[i] = s[i];
    } else {
      for (int i = 0; i < block.x; ++i) dst[i] = src[clamp(x0 + i, 0, dims.x - 1)];
    }
    if (r == rows - 1) {
      __global float* tail = cells + sv_block_start(block, p);
      for (int i = rows * block.x; i < block.w; ++i) tail[i] = 0.0f;
    }
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
