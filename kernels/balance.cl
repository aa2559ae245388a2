/* balance.cl — load balancing by moving segment boundaries between face
 * neighbours (see host/include/simdvol/match.hpp for the scheme and
 * match_cl.hpp for the buffers). Integer only: equal to balance_reference.
 *
 * Tables: cidx (int4[P], cell index of each PE), pe_of (int[P], the PE of
 * cell (ix, iy, iz) at (iz * sy + iy) * sx + ix), splits (int4, cells per
 * axis).
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif

SV_FN int sv_cell_pe(global const int* pe_of, int4 splits, int x, int y, int z) {
  return pe_of[(z * splits.y + y) * splits.x + x];
}

/* links[s] = -1, or next * 4 + axis (see balance_links). */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_balance_links(
    __constant sv_view* view, global const int4* cidx, global const int* pe_of, int4 cell,
    int4 splits, int pes, global const int* seg_offset, global const sv_segment* segments,
    global int* links) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  const int4 cp = cidx[p];
  const int D = view->grid[2];
  const int c[3] = {cell.x, cell.y, cell.z};
  const int e = seg_offset[p + 1];
  for (int s = seg_offset[p]; s < e; ++s) {
    const sv_segment g = segments[s];
    int link = -1;
    if (g.k1 < D) {
      int q[3];
      int inside = 1;
      for (int a = 0; a < 3; ++a) {
        const long x = view->origin[a] + (long)g.i * view->step[a][0] +
                       (long)g.j * view->step[a][1] + (long)g.k1 * view->step[a][2];
        const long f = x >> SV_FRAC_BITS;
        if (f < 0 || f >= view->dims[a]) inside = 0;
        q[a] = inside ? (int)(f / c[a]) : 0;
      }
      if (inside) {
        const int d0 = q[0] - cp.x, d1 = q[1] - cp.y, d2 = q[2] - cp.z;
        const int nz = (d0 != 0) + (d1 != 0) + (d2 != 0);
        const int l1 = abs(d0) + abs(d1) + abs(d2);
        if (nz == 1 && l1 == 1) {
          const int axis = d0 != 0 ? 0 : (d1 != 0 ? 1 : 2);
          const int qp = sv_cell_pe(pe_of, splits, q[0], q[1], q[2]);
          int lo = seg_offset[qp], hi = seg_offset[qp + 1];  // first with (j, i) >= g's
          while (lo < hi) {
            const int mid = (lo + hi) / 2;
            const sv_segment h = segments[mid];
            if (h.j < g.j || (h.j == g.j && h.i < g.i))
              lo = mid + 1;
            else
              hi = mid;
          }
          link = lo * 4 + axis;  // the matching guarantees a hit starting at k1
        }
      }
    }
    links[s] = link;
  }
}

/* Length of the giver's segment on linked ray s. */
SV_FN int sv_give_len(global const sv_segment* segments, global const int* links, int s,
                      int front_gives) {
  const sv_segment g = front_gives ? segments[s] : segments[links[s] >> 2];
  return g.k1 - g.k0;
}

/* One round: pairs along `axis` whose lower cell index has parity `par`;
 * dir = sign of the depth step along the axis (non-zero). */
__kernel __attribute__((reqd_work_group_size(WGS, 1, 1))) void simdvol_balance_round(
    global const int4* cidx, global const int* pe_of, int4 splits, int pes, int axis, int par,
    int dir, global const int* seg_offset, global sv_segment* segments, global const int* links,
    global int* loads) {
  const int p = (int)get_global_id(0);
  if (p >= pes) return;
  int4 c = cidx[p];
  const int sa = axis == 0 ? splits.x : (axis == 1 ? splits.y : splits.z);
  int ca = axis == 0 ? c.x : (axis == 1 ? c.y : c.z);
  if ((ca & 1) != par || ca + 1 >= sa) return;
  if (axis == 0)
    c.x += 1;
  else if (axis == 1)
    c.y += 1;
  else
    c.z += 1;
  const int q = sv_cell_pe(pe_of, splits, c.x, c.y, c.z);
  const int F = dir > 0 ? p : q, B = dir > 0 ? q : p;
  const int diff = loads[F] - loads[B];
  const int t = diff / 2; /* truncates towards 0 */
  if (t == 0) return;
  const int front_gives = t > 0;
  const int want = front_gives ? t : -t;
  const int s0 = seg_offset[F], s1 = seg_offset[F + 1];
  long cap = 0;
  for (int s = s0; s < s1; ++s) {
    const int l = links[s];
    if (l < 0 || (l & 3) != axis) continue;
    cap += sv_give_len(segments, links, s, front_gives);
  }
  const long moved = min(cap, (long)want);
  if (moved == 0) return;
  /* Proportional shares, then the remainder one by one in order. */
  long rem = moved;
  for (int s = s0; s < s1; ++s) {
    const int l = links[s];
    if (l < 0 || (l & 3) != axis) continue;
    rem -= moved * sv_give_len(segments, links, s, front_gives) / cap;
  }
  for (int s = s0; s < s1; ++s) {
    const int l = links[s];
    if (l < 0 || (l & 3) != axis) continue;
    const int len = sv_give_len(segments, links, s, front_gives);
    int give = (int)(moved * len / cap);
    if (rem > 0 && give < len) {
      ++give;
      --rem;
    }
    const int shift = front_gives ? -give : give;
    segments[s].k1 += shift;
    segments[l >> 2].k0 += shift;
  }
  loads[F] -= front_gives ? (int)moved : -(int)moved;
  loads[B] += front_gives ? (int)moved : -(int)moved;
}
