/* resample.cl — the resample stage on the PE array (thesis 5.6.3–5.6.4):
 * every sample of every segment by Aitken/Neville interpolation of order
 * ORDER (0..3), exactly as host/core/resample.cpp's resample_rgba: nested
 * stencils, Neville in insertion order, x then y then z, indices clamped into
 * the volume, the same float expressions (no contraction into FMA).
 *
 * Voxels are read from the classified voxel cells (stages.hpp): the stencil
 * voxel at global g (clamped) is read from the cell of the PE that owns it,
 * the resampling PE's own or a neighbour's (an X-Net read). The k-d split
 * makes the owner separable per axis (owner = bits_x[gx] | bits_y[gy] |
 * bits_z[gz], local position g - origin per axis), so the float index of
 * channel 0 of voxel g is
 *   addr[gx] + addr[nx + gy] + addr[nx + ny + gz]
 * with one table of nx + ny + nz ints the host builds (owner bits times the
 * PE block size plus the local coordinate times its stride); channel c is at
 * + c * cs (cs = the plane stride of planar cells, 1 for interleaved float4).
 *
 * Denominators: Neville divides by x_k - x_i, which is +-1, +-2 or +-3 (its
 * sign given by the stencil's direction). For +-1 and +-2 the kernel
 * multiplies by the exact reciprocal (bit-identical to the division); for
 * +-3 it divides.
 *
 * Kernels here:
 *   simdvol_resample   one work-item per segment: its samples, in order, to
 *                      out[sample_off[s] ...] (float4 premultiplied RGBA).
 *   simdvol_resample_v8  the same, 8 segments per work-item in float8 lanes
 *                      (the default; equal bit for bit).
 *   simdvol_resample_v8_il  the same on interleaved voxel cells (stages.hpp;
 *                      a corner's RGBA in one load; equal bit for bit).
 *   simdvol_occupancy, simdvol_occupancy_il, simdvol_occupancy_reach  the
 *                      brick occupancy and reach of empty-space skipping.
 *   simdvol_zero4      zero-fills n float4 (footprints before the local stage).
 * local.cl adds the local compositing kernels (and, with this file, the fused
 * resample + local kernel).
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif
#define SIMDVOL_RESAMPLE_CL

#pragma OPENCL FP_CONTRACT OFF

#ifndef ORDER
#define ORDER 1
#endif
#define SV_M (ORDER + 1)

/* Stencil of the low side (t <= 1/2), relative to f, in insertion order; the
 * high side is 1 - these (resample.cpp: stencil()). */
#define SV_LOWPOS(e) ((e) == 0 ? 0 : (e) == 1 ? 1 : (e) == 2 ? -1 : 2)

/* One axis of a sample: float index contribution and x - x_e per stencil
 * position, and the stencil's side. */
SV_FN void sv_axis(long X, int n, __global const int* table, int* addr, float* d, int* low) {
  const int f = (int)(X >> SV_FRAC_BITS);
  const float t = (float)(uint)(X & 0xFFFFFFFFL) * (1.0f / 4294967296.0f);
  const int lo = t <= 0.5f;
  *low = lo;
#pragma unroll
  for (int e = 0; e < SV_M; ++e) {
    const int p = lo ? SV_LOWPOS(e) : 1 - SV_LOWPOS(e);
    addr[e] = table[clamp(f + p, 0, n - 1)];
    d[e] = (float)(-p) + t;
  }
}

/* Neville in insertion order on R rows at once (resample.cpp:
 * neville_rows): q[i * R + r] holds f_i of row r; on exit q[r] = P_{0..ORDER}. */
SV_FN_INLINE void sv_neville(float* q, const int R, const float* d, const int low) {
#pragma unroll
  for (int k = 1; k <= ORDER; ++k) {
#pragma unroll
    for (int i = k - 1; i >= 0; --i) {
      const int c = SV_LOWPOS(k) - SV_LOWPOS(i); /* x_k - x_i on the low side */
      const float di = d[i], dk = d[k];
      if (c == 3 || c == -3) {
        const float den = low ? (float)c : (float)(-c);
#pragma unroll
        for (int r = 0; r < R; ++r)
          q[i * R + r] = (di * q[(i + 1) * R + r] - dk * q[i * R + r]) / den;
      } else {
        const float rc = low ? 1.0f / (float)c : -1.0f / (float)c; /* exact: c = +-1, +-2 */
#pragma unroll
        for (int r = 0; r < R; ++r)
          q[i * R + r] = (di * q[(i + 1) * R + r] - dk * q[i * R + r]) * rc;
      }
    }
  }
}

/* A sample as compositing takes it (resample.hpp: clamp_sample): at
 * orders >= 2 (Lagrange weights below 0 and above 1) alpha clamped to [0,
 * 1] and each premultiplied colour to [0, alpha], a NaN to 0; over() with
 * alpha outside [0, 1] amplifies instead of attenuating. Orders 0 and 1 are
 * left as they are (no instruction). */
#if ORDER >= 2
SV_FN_INLINE float4 sv_clamp_sample(const float4 s) {
  const float a = fmin(fmax(s.w, 0.0f), 1.0f);
  return fmin(fmax(s, (float4)(0.0f)), (float4)(a));
}
#else
#define sv_clamp_sample(s) (s)
#endif

/* The sample at fixed-point position (X0, X1, X2) (inside the volume). */
SV_FN float4 sv_sample(long X0, long X1, long X2, int4 dims, __global const int* table,
                       __global const float* vox, int cs) {
  int ax[SV_M], ay[SV_M], az[SV_M];
  float dx[SV_M], dy[SV_M], dz[SV_M];
  int lx, ly, lz;
  sv_axis(X0, dims.x, table, ax, dx, &lx);
  sv_axis(X1, dims.y, table + dims.x, ay, dy, &ly);
  sv_axis(X2, dims.z, table + dims.x + dims.y, az, dz, &lz);
  /* v[a * R + ch * M * M + c * M + b], R = 4 * M * M */
  float v[SV_M * 4 * SV_M * SV_M];
  const int R = 4 * SV_M * SV_M;
#pragma unroll
  for (int c = 0; c < SV_M; ++c)
#pragma unroll
    for (int b = 0; b < SV_M; ++b) {
      const int row = ay[b] + az[c];
#pragma unroll
      for (int a = 0; a < SV_M; ++a) {
        const int o = row + ax[a];
#pragma unroll
        for (int ch = 0; ch < 4; ++ch)
          v[a * R + ch * SV_M * SV_M + c * SV_M + b] = vox[o + ch * cs];
      }
    }
  sv_neville(v, R, dx, lx); /* v[ch * M * M + c * M + b] along x */
  float w[SV_M * 4 * SV_M]; /* w[b * 4M + ch * M + c] */
#pragma unroll
  for (int ch = 0; ch < 4; ++ch)
#pragma unroll
    for (int c = 0; c < SV_M; ++c)
#pragma unroll
      for (int b = 0; b < SV_M; ++b)
        w[b * 4 * SV_M + ch * SV_M + c] = v[ch * SV_M * SV_M + c * SV_M + b];
  sv_neville(w, 4 * SV_M, dy, ly); /* w[ch * M + c] along y */
  float u[SV_M * 4];               /* u[c * 4 + ch] */
#pragma unroll
  for (int ch = 0; ch < 4; ++ch)
#pragma unroll
    for (int c = 0; c < SV_M; ++c) u[c * 4 + ch] = w[ch * SV_M + c];
  sv_neville(u, 4, dz, lz);
  return sv_clamp_sample((float4)(u[0], u[1], u[2], u[3]));
}

/* Position of sample k of ray (i, j), per axis. */
SV_FN long sv_pos(__global const sv_view* v, int a, int i, int j, int k) {
  return v->origin[a] + (long)i * v->step[a][0] + (long)j * v->step[a][1] + (long)k * v->step[a][2];
}

__kernel void simdvol_resample(__global const sv_segment* segs, const int nseg,
                               __global const int* sample_off, __global const sv_view* view,
                               __global const int* table, __global const float* vox, const int cs,
                               __global float4* out) {
  const int s = (int)get_global_id(0);
  if (s >= nseg) return;
  const sv_segment g = segs[s];
  const int4 dims = (int4)(view->dims[0], view->dims[1], view->dims[2], 0);
  long X0 = sv_pos(view, 0, g.i, g.j, g.k0), X1 = sv_pos(view, 1, g.i, g.j, g.k0),
       X2 = sv_pos(view, 2, g.i, g.j, g.k0);
  const long s0 = view->step[0][2], s1 = view->step[1][2], s2 = view->step[2][2];
  __global float4* o = out + sample_off[s];
  for (int k = g.k0; k < g.k1; ++k) {
    *o++ = sv_sample(X0, X1, X2, dims, table, vox, cs);
    X0 += s0;
    X1 += s1;
    X2 += s2;
  }
}

/* ---- explicit float8 lanes: simdvol_resample_v8 (and local.cl's fused
 * simdvol_resample_local_v8) ----
 * PoCL vectorises only loops over work-items whose bodies have no inner
 * loops of varying trip count; a segment's samples are such a loop, so the
 * one-segment-per-work-item kernels run scalar. Here each work-item
 * takes 8 consecutive segments (of one PE, mostly: neighbouring rays of
 * similar length) as the 8 lanes of float8/int8/long8 values and steps them
 * together max(k1 - k0) times; a lane whose segment has ended keeps its
 * composite (select) and reads clamped, harmless voxels. Element-wise vector
 * arithmetic is the scalar IEEE arithmetic, so the results are those of
 * simdvol_resample (simdvol_resample_local) bit for bit. Voxel gathers are
 * 8 scalar loads each. */
/* long8/float8 arguments of helper functions change the ABI without AVX-512;
 * clang warns once per call site (-Wpsabi). Harmless inside one program. */
#ifdef __clang__
#pragma clang diagnostic ignored "-Wpsabi"
#endif
#define SV_G8(p, ix)                                                                            \
  ((float8)((p)[(ix).s0], (p)[(ix).s1], (p)[(ix).s2], (p)[(ix).s3], (p)[(ix).s4], (p)[(ix).s5], \
            (p)[(ix).s6], (p)[(ix).s7]))
#define SV_GI8(p, ix)                                                                         \
  ((int8)((p)[(ix).s0], (p)[(ix).s1], (p)[(ix).s2], (p)[(ix).s3], (p)[(ix).s4], (p)[(ix).s5], \
          (p)[(ix).s6], (p)[(ix).s7]))
/* (AVX2 gathers, __builtin_ia32_gatherd_ps256 in place of these, gave the
 * same times on the 2-core EPYC (simdvol-bench-frame), so the portable form
 * stays.) */

/* Without AVX-512 (PoCL's haswell target: AVX2) the order-1 sampler on
 * interleaved cells with the cell bits (sv_sample8_il1, cb: the _ilc
 * kernels) takes its lanes' corner offsets through memory as with AVX-512:
 * stored as vectors, loaded back as scalars, instead of vextracti128 /
 * vpextrd / vmovd and a movslq per offset; -DSV_OFFS_EXTRACT extracts them,
 * as before (on either target). Without the cell bits it reads the pair
 * table's entries (one 64-bit word per lane and axis) by two AVX2 gathers
 * (vpgatherdq, 4 lanes each) instead of 8 extracted indices and 8 scalar
 * loads inserted one by one: the same entries (indices clamped into the
 * table, every lane read). The builtin takes a plain pointer: the table's
 * __global one is passed through an integer, which CPU devices (one address
 * space) allow. -DSV_NO_GATHER_AVX2 loads them one by one, as before; the
 * offsets are extracted there (with the gathers, the round trip through
 * memory measured no faster). The general sampler (orders 0, 2, 3) keeps
 * the extracts and scalar loads on AVX2: both forms measured slower there
 * at order 3. Measured in docs/PERFORMANCE.md (Zen 3, 2026-12-07,
 * thirty-third session). */
#if defined(__clang__) && defined(__AVX2__) && !defined(__AVX512F__) && !defined(SV_OFFS_EXTRACT)
#define SV_OFFS_AVX2 1
#endif
#if defined(__clang__) && defined(__AVX2__) && !defined(__AVX512F__) && !defined(SV_NO_GATHER_AVX2)
#define SV_GATHER_AVX2 1
#endif
/* With the pair table's gathers (SV_GATHER_AVX2: the _il kernels at order 1)
 * the fused resample + local's step loop is pipelined (local.cl): step
 * t + 1's gathers and corner offsets (sv_addr8_il1) come before step t's
 * loads and interpolation (sv_interp8_il1), so that the next step's gathers
 * run beside this step's arithmetic instead of ahead of its own loads. The
 * same offsets, loads and arithmetic, so the same samples. -DSV_NO_PIPE
 * samples each step whole (sv_sample8_il1), as before; -DSV_NO_GATHER_AVX2
 * implies it. simdvol-bench-options --frames 10, 2-core Zen 3 EPYC, three
 * alternations, -DSV_NO_PIPE -> this, resample + local: ch2 0.940 / 0.957 /
 * 0.946, the cranium (data/ct/cranium.nhdr, classifier ct) 0.936 / 0.921 /
 * 0.914; the same images (docs/PERFORMANCE.md, thirty-fourth session). The
 * cell bits' kernels (_ilc) step as before: pipelined the same way they
 * measured no faster on the 256^3 phantom. */
#if defined(SV_GATHER_AVX2) && !defined(SV_NO_PIPE) && ORDER == 1 && !defined(SV_IL1_GENERIC)
#define SV_PIPE_AVX2 1
#endif

/* The fixed-point positions X as their floors F = X >> 32 and fractions
 * L = X & (2^32 - 1) (SV_FRAC_BITS = 32): the float8 kernels step them so
 * (sv_step8, the same integers as the 64-bit sums), and the samplers and the
 * reach test take them so, which saves the 64-bit lanes' shifts and
 * narrowing at each step. */
SV_FN_INLINE void sv_floors8(const long8* X, int8* F) {
#pragma unroll
  for (int a = 0; a < 3; ++a) F[a] = convert_int8(X[a] >> SV_FRAC_BITS);
}
SV_FN_INLINE void sv_split8(const long8* X, int8* F, uint8* L) {
  sv_floors8(X, F);
#pragma unroll
  for (int a = 0; a < 3; ++a) L[a] = convert_uint8(X[a] & 0xFFFFFFFFL);
}
/* One axis of 8 lanes at split positions (floor f, fraction l: sv_split8). */
SV_FN_INLINE void sv_axis8(const int8 f, const uint8 l, int n, __global const int* table,
                           int8* addr, float8* d, int8* low) {
  const float8 t = convert_float8(l) * (1.0f / 4294967296.0f);
  const int8 lo = t <= 0.5f; /* -1 where low */
  *low = lo;
#pragma unroll
  for (int e = 0; e < SV_M; ++e) {
    const int8 p = select((int8)(1 - SV_LOWPOS(e)), (int8)(SV_LOWPOS(e)), lo);
    const int8 g = clamp(f + p, (int8)(0), (int8)(n - 1));
    addr[e] = SV_GI8(table, g);
    d[e] = convert_float8(-p) + t;
  }
}

SV_FN void sv_neville8(float8* q, const int R, const float8* d, const int8 low) {
#pragma unroll
  for (int k = 1; k <= ORDER; ++k) {
#pragma unroll
    for (int i = k - 1; i >= 0; --i) {
      const int c = SV_LOWPOS(k) - SV_LOWPOS(i);
      const float8 di = d[i], dk = d[k];
      if (c == 3 || c == -3) {
        const float8 den = select((float8)((float)(-c)), (float8)((float)c), low);
#pragma unroll
        for (int r = 0; r < R; ++r)
          q[i * R + r] = (di * q[(i + 1) * R + r] - dk * q[i * R + r]) / den;
      } else {
        const float8 rc = select((float8)(-1.0f / (float)c), (float8)(1.0f / (float)c), low);
#pragma unroll
        for (int r = 0; r < R; ++r)
          q[i * R + r] = (di * q[(i + 1) * R + r] - dk * q[i * R + r]) * rc;
      }
    }
  }
}

/* sv_axis8 for the three axes of 8 lanes at split positions F, L [0..2]. */
#define SV_AXES8(F, L, nx, ny, nz, table)                      \
  int8 ax[SV_M], ay[SV_M], az[SV_M];                           \
  float8 dx[SV_M], dy[SV_M], dz[SV_M];                         \
  int8 lx, ly, lz;                                             \
  sv_axis8((F)[0], (L)[0], (nx), (table), ax, dx, &lx);        \
  sv_axis8((F)[1], (L)[1], (ny), (table) + (nx), ay, dy, &ly); \
  sv_axis8((F)[2], (L)[2], (nz), (table) + (nx) + (ny), az, dz, &lz)

/* The samples at the split positions F, L [0..2] of 8 lanes: u[ch] =
 * channel ch of each lane's sample (sv_sample per lane). */
SV_FN_INLINE void sv_sample8(const int8* F, const uint8* L, int nx, int ny, int nz,
                             __global const int* table, __global const float* vox, int cs,
                             float8* u) {
  SV_AXES8(F, L, nx, ny, nz, table);
  /* z outermost: the x pass of a row (b, c) runs as soon as its SV_M
   * corners are loaded, the y pass of a plane c as soon as its rows are
   * done, so about 4 * (SV_M + 2) float8 values are live instead of the
   * 4 * SV_M^3 gathered ones. Each column is interpolated by the same
   * operations as when every corner was gathered first (the columns are
   * independent), so the samples are the same bit for bit. Gathering every
   * corner first kept most of its 32 float8 values (order 1) in memory (a
   * store after each gather in the profile): the fused kernel on the 256^3
   * phantom (simdvol-bench-frame, column `skip`, alternated four times)
   * took 95-115 / 172-188 / 150-175 ms at 0 / 30 / 45 degrees against
   * 84-102 / 145-164 / 130-162 ms now; order 3 the same within the noise. */
  float8 qz[SV_M * 4];
#pragma unroll
  for (int c = 0; c < SV_M; ++c) {
    float8 qy[SV_M * 4];
#pragma unroll
    for (int b = 0; b < SV_M; ++b) {
      const int8 row = ay[b] + az[c];
      float8 qx[SV_M * 4];
#pragma unroll
      for (int a = 0; a < SV_M; ++a) {
        const int8 o = row + ax[a];
#pragma unroll
        for (int ch = 0; ch < 4; ++ch) {
          /* the channel's plane, then the lanes' offsets: the 8 offsets are
           * taken out of `o` once for the 4 channels (o + ch * cs took them
           * out 4 times: -20% in the fused kernel). */
          __global const float* vc = vox + ch * cs;
          qx[a * 4 + ch] = SV_G8(vc, o);
        }
      }
      sv_neville8(qx, 4, dx, lx);
#pragma unroll
      for (int ch = 0; ch < 4; ++ch) qy[b * 4 + ch] = qx[ch];
    }
    sv_neville8(qy, 4, dy, ly);
#pragma unroll
    for (int ch = 0; ch < 4; ++ch) qz[c * 4 + ch] = qy[ch];
  }
  sv_neville8(qz, 4, dz, lz);
#if ORDER >= 2
  { /* sv_clamp_sample on the 8 lanes */
    const float8 a = fmin(fmax(qz[3], 0.0f), 1.0f);
#pragma unroll
    for (int ch = 0; ch < 4; ++ch) u[ch] = fmin(fmax(qz[ch], 0.0f), a);
  }
#else
#pragma unroll
  for (int ch = 0; ch < 4; ++ch) u[ch] = qz[ch];
#endif
}

/* ---- interleaved voxel cells: sv_sample8_il (simdvol_resample_v8_il and
 * local.cl's simdvol_resample_local_v8_il) ----
 * The float8 lanes' kernels (the same lanes, trim, skipping and writes) on
 * interleaved voxel cells (stages.hpp: the RGBA of a position in 16
 * consecutive bytes; the address table gives the float index of channel 0,
 * cs = 1). A corner's four channels are one 16-byte load instead of four
 * lane gathers, and lanes 0-3 and 4-7 are computed as two float16 of
 * (lane, channel), 4 x RGBA: each axis's x - x_e and stencil side per lane
 * spread over its 4 channels (sv_spread4), Neville on float16 with the same
 * element-wise operations as sv_neville8 (so the samples, and the
 * footprints, are those of simdvol_resample_local_v8 bit for bit; tested).
 * The lanes' x, y, z arithmetic is sv_axis8's. On the 2-core Zen 5 EPYC
 * (AVX-512; PoCL's skylake-avx512 target), the 256^3 phantom at 8,192 PEs,
 * simdvol-bench-frame (columns `ordered` and `ordered4`, the frame path with
 * the lane order and skipping): see docs/PERFORMANCE.md. */
SV_FN float16 sv_spread4(const float8 v, const uint base) {
  const uint16 k = (uint16)(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3) + base;
  return shuffle(v, k);
}

/* sv_neville8 on (lane, channel) float16 values; low = -1 bits in the
 * lanes whose stencil is on the low side. */
SV_FN void sv_neville16(float16* q, const float16* d, const int16 low) {
#pragma unroll
  for (int k = 1; k <= ORDER; ++k) {
#pragma unroll
    for (int i = k - 1; i >= 0; --i) {
      const int c = SV_LOWPOS(k) - SV_LOWPOS(i);
      if (c == 3 || c == -3) {
        const float16 den = select((float16)((float)(-c)), (float16)((float)c), low);
        q[i] = (d[i] * q[i + 1] - d[k] * q[i]) / den;
      } else {
        const float16 rc = select((float16)(-1.0f / (float)c), (float16)(1.0f / (float)c), low);
        q[i] = (d[i] * q[i + 1] - d[k] * q[i]) * rc;
      }
    }
  }
}

/* Order 1 on interleaved cells, the stencil in its natural order: corner
 * (a, b, c) of a lane is table_x[f + a] + table_y[f + b] + table_z[f + c]
 * (f clamped per axis), and the table is separable, so it is the lane's
 * base (a = b = c = 0) plus a * dX + b * dY + c * dZ, each the table's step
 * from f to f + 1 on that axis (4 floats, a row or a plane inside the cell;
 * a jump into the neighbour PE's block at its edge; 0 where the volume's edge
 * clamps). So a lane's 8 corner addresses come from 4 integers instead of 8
 * extracted sums (vpextrq and its kin had about a quarter of the fused
 * kernel's samples). Each axis is then t * v(f + 1) - (t - 1) * v(f): the
 * products and the difference of sv_neville16's low-side lane (whose
 * factor is 1); its high-side lanes compute -((t - 1) * v(f) - t * v(f +
 * 1)), the same rounding of the negated difference, so the samples are
 * sv_sample8_il's bit for bit but for the sign of a zero or of a NaN, which
 * over cannot tell (resample.cl, empty-space skipping; a NaN stays a NaN). */
#if ORDER == 1 && !defined(SV_IL1_GENERIC)
#define SV_IL1_ROWS 1
#if defined(__clang__) && defined(__AVX2__) && !defined(__AVX512F__)
/* Entry i (0 .. 31) of a 32-entry table per lane, by AVX2 permutes: vpermd
 * picks within each quarter by the index's low 3 bits, two blends on bits 3
 * and 4 pick the quarter (select takes the mask's sign bit). The entries are
 * those of the 8 scalar loads it replaces (-DSV_CELL_GATHER), which LLVM
 * emits for PoCL's haswell target as extracts and inserts. 2-core Zen 3
 * EPYC, simdvol-bench-options --frames 12, resample + local of the 256^3
 * phantom, alternated: (0, 45, 0) 89.7 / 83.1 -> 84.4 / 77.0 ms, (20, 35,
 * 10) 96.8 / 88.5 -> 91.2 / 84.7 ms; the same images. */
SV_FN_INLINE int8 sv_lookup32(__global const int* t, const int8 i) {
  const int8 q0 = __builtin_ia32_permvarsi256(vload8(0, t), i);
  const int8 q1 = __builtin_ia32_permvarsi256(vload8(1, t), i);
  const int8 q2 = __builtin_ia32_permvarsi256(vload8(2, t), i);
  const int8 q3 = __builtin_ia32_permvarsi256(vload8(3, t), i);
  const int8 m3 = i << 28, m4 = i << 27;
  return select(select(q0, q1, m3), select(q2, q3, m3), m4);
}
#endif
/* Without AVX-512 the corners are loaded as ints and reinterpreted: loaded as
 * floats, LLVM 15 (PoCL's haswell target) built half of the lanes' pairs
 * (v(f), v(f + 1)) from 8-byte halves (64 vmovsd and 16 vunpcklpd in the
 * kernel against 4 and 0; 90 instructions fewer). The same bits.
 * simdvol-bench-options --frames 12, resample + local, 2-core Zen 3 EPYC,
 * float loads (-DSV_LD4_FLOAT) -> int loads, alternated: the 256^3 phantom
 * at (0, 45, 0) 84.2 / 88.1 -> 79.3 / 84.4 ms, at (20, 35, 10) 80.5 / 88.9
 * -> 76.4 / 87.4, ch2 80.3 -> 78.8, brainsmall 12.8 -> 11.6; order 3
 * (sv_sample8_il, the same change) at (0, 45, 0), --frames 6: 591 / 670 ->
 * 475 / 521 ms. (AVX-512 not measured: its loads stay floats.) */
#if defined(__AVX512F__) || defined(SV_LD4_FLOAT)
#define SV_LD4(l) vload4(0, vox + o.s##l), vload4(0, vox + o.s##l + dx.s##l)
#else
#define SV_LD4(l)                                          \
  as_float4(vload4(0, (__global const int*)vox + o.s##l)), \
      as_float4(vload4(0, (__global const int*)vox + o.s##l + dx.s##l))
#endif
SV_FN_INLINE void sv_sample8_il1(const int8* F, const uint8* L, int nx, int ny, int nz,
                                 __global const int* table, __global const long* pairs,
                                 __global const float* vox, float16* u, const int cb) {
  const int n[3] = {nx, ny, nz};
  int8 base = (int8)(0), dd[3];
  float8 tt[3];
  __global const int* tab = table;
  __global const long* pt = pairs;
  /* the cell bits after the pairs (resample_cell_bits): per axis 32 entries,
   * then the 3 shifts and the 3 strides */
  __global const int* cbits = (__global const int*)(pairs + nx + ny + nz + 6);
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    const int8 f = F[a];
    tt[a] = convert_float8(L[a]) * (1.0f / 4294967296.0f);
    int8 t0, t1;
    if (cb) {
      /* Cells of 2^s positions along the axis, at most 32 of them: entry g
       * of the table is the cell's entry bits[g >> s] plus (g & (2^s - 1))
       * times the axis's stride (checked on the host for every g), so a
       * lane's two entries come from one permute of the 32 cell entries
       * (f's cell in the low 8 lanes, f + 1's in the high 8) instead of a
       * gather. simdvol-bench-options, resample + local on the 256^3
       * phantom (cells 8 x 16 x 16), the _il kernels -> these: 30.7 -> 27.9
       * ms at (20, 35, 10), 31.4 -> 28.5 at (0, 45, 0), 26.0 -> 24.0 at 0
       * degrees; the same images. */
      const int sh = cbits[96 + a], mul = cbits[99 + a];
      const int8 g0 = clamp(f, (int8)(0), (int8)(n[a] - 1));
      const int8 g1 = clamp(f + 1, (int8)(0), (int8)(n[a] - 1));
      const int8 m = (int8)((1 << sh) - 1);
#if defined(__clang__) && defined(__AVX512F__) && !defined(SV_CELL_GATHER)
      const int16 lo = vload16(0, cbits + 32 * a), hi = vload16(1, cbits + 32 * a);
      const int16 bits = __builtin_ia32_vpermi2vard512(lo, (int16)(g0 >> sh, g1 >> sh), hi);
      const int8 b0 = bits.lo, b1 = bits.hi;
#elif defined(__clang__) && defined(__AVX2__) && !defined(SV_CELL_GATHER)
      const int8 b0 = sv_lookup32(cbits + 32 * a, g0 >> sh);
      const int8 b1 = sv_lookup32(cbits + 32 * a, g1 >> sh);
#else
      const int8 b0 = SV_GI8(cbits + 32 * a, g0 >> sh), b1 = SV_GI8(cbits + 32 * a, g1 >> sh);
#endif
      t0 = b0 + (g0 & m) * mul;
      t1 = b1 + (g1 & m) * mul;
    } else {
#ifndef SV_NO_PAIRS
      /* Both entries in one 64-bit gather (resample_pair_table: entry f + 1
       * holds t[clamp(f)] low, t[clamp(f + 1)] high, for f = -1 .. n; f
       * clamped to that range gives the same two entries as the two gathers
       * of -DSV_NO_PAIRS). Those 8-lane gathers, two per axis, had about a
       * sixth of the fused kernel's time (a probe without them, wrong images:
       * 29.6 -> 23.2 ms). simdvol-bench-options, resample + local, -DSV_NO_PAIRS
       * -> pairs: the phantom 29.3 / 28.7 -> 27.1 / 28.0 ms, at (0, 45, 0)
       * 29.4 -> 27.5, ch2 25.7 -> 24.9, brainsmall 4.37 -> 4.22 ms. */
      const int8 e = clamp(f, (int8)(-1), (int8)(n[a])) + 1;
#ifdef SV_GATHER_AVX2
      /* (AVX2: two vpgatherdq; SV_GATHER_AVX2 above) */
      const long* pp = (const long*)(size_t)pt;
      const long8 q = (long8)(__builtin_ia32_gatherd_q256((long4)(0), pp, e.lo, (long4)(-1), 8),
                              __builtin_ia32_gatherd_q256((long4)(0), pp, e.hi, (long4)(-1), 8));
#else
      const long8 q =
          (long8)(pt[e.s0], pt[e.s1], pt[e.s2], pt[e.s3], pt[e.s4], pt[e.s5], pt[e.s6], pt[e.s7]);
#endif
      t0 = convert_int8(q & 0xFFFFFFFFL);
      t1 = convert_int8(q >> 32);
#else
      t0 = SV_GI8(tab, clamp(f, (int8)(0), (int8)(n[a] - 1)));
      t1 = SV_GI8(tab, clamp(f + 1, (int8)(0), (int8)(n[a] - 1)));
#endif
    }
    base += t0;
    dd[a] = t1 - t0;
    tab += n[a];
    pt += n[a] + 2;
  }
  const int8 dx = dd[0];
  const int8 rows[4] = {base, base + dd[1], base + dd[2], base + dd[1] + dd[2]}; /* (b, c) */
#if defined(__AVX512F__) && !defined(SV_OFFS_EXTRACT)
  /* With AVX-512 the lanes' offsets go through memory: the 4 rows' and dx's
   * 8 ints each are stored as vectors and loaded back one by one (volatile,
   * so that LLVM keeps the round trip), and each corner's address is a
   * scalar load forwarded from the store instead of an extract
   * (vpextrq / vmovq / vextracti32x4 with the sign extensions: 90 of the
   * loop's ~400 instructions, most on the one shuffle port that the lane
   * inserts need too). The same loads, so the same samples.
   * -DSV_OFFS_EXTRACT extracts them, as before. simdvol-bench-options
   * --frames 12, the 256^3 phantom at (20, 35, 10), 2-core Xeon (family 6,
   * model 167), four runs of both orders: resample + local 34.94 / 34.25 /
   * 34.74 / 34.59 -> 33.32 / 32.72 / 33.16 / 33.01 ms. */
  volatile int ofs[5][8];
#pragma unroll
  for (int r = 0; r < 4; ++r) *(volatile int8*)ofs[r] = rows[r];
  *(volatile int8*)ofs[4] = dx;
#ifndef SV_OFFS_RELOAD
  int dxs[8];
#pragma unroll
  for (int l = 0; l < 8; ++l) dxs[l] = ofs[4][l];
#endif
#undef SV_LD4
#define SV_LD4(l) vload4(0, vox + ofs[r][l]), vload4(0, vox + ofs[r][l] + ofs[4][l])
#elif defined(SV_OFFS_AVX2)
  /* AVX2: the same round trip (each offset loaded once), the corners
   * loaded as ints as SV_LD4 loads them; with the cell bits (cb) only: with
   * the pair table's gathers the extracts measured as fast (above) */
  volatile int ofs[5][8];
  int dxs[8];
  if (cb) {
#pragma unroll
    for (int r = 0; r < 4; ++r) *(volatile int8*)ofs[r] = rows[r];
    *(volatile int8*)ofs[4] = dx;
#pragma unroll
    for (int l = 0; l < 8; ++l) dxs[l] = ofs[4][l];
  }
#endif
#pragma unroll
  for (int h = 0; h < 2; ++h) {
    const uint hb = 4 * h;
    const float16 w1x = sv_spread4(tt[0], hb), w0x = sv_spread4(tt[0] - 1.0f, hb);
    const float16 w1y = sv_spread4(tt[1], hb), w0y = sv_spread4(tt[1] - 1.0f, hb);
    const float16 w1z = sv_spread4(tt[2], hb), w0z = sv_spread4(tt[2] - 1.0f, hb);
    float16 q[4];
#pragma unroll
    for (int r = 0; r < 4; ++r) {
      /* lanes 4h .. 4h + 3: v(f) and v(f + 1) of each, as sv_sample8_il
       * assembles a float16 from two float8 halves */
      float8 l0, l1, l2, l3;
#if defined(__AVX512F__) && !defined(SV_OFFS_EXTRACT) && !defined(SV_OFFS_RELOAD)
      /* each offset loaded once (-DSV_OFFS_RELOAD: once per corner, as
       * the volatile array made LLVM do: 96 loads a step instead of 40;
       * simdvol-bench-options as above: 32.19 / 32.23 / 32.28 / 32.35 ->
       * 30.90 / 31.08 / 30.94 / 30.84 ms) */
      const int b = 4 * h, a0 = ofs[r][b], a1 = ofs[r][b + 1], a2 = ofs[r][b + 2],
                a3 = ofs[r][b + 3];
      l0 = (float8)(vload4(0, vox + a0), vload4(0, vox + a0 + dxs[b]));
      l1 = (float8)(vload4(0, vox + a1), vload4(0, vox + a1 + dxs[b + 1]));
      l2 = (float8)(vload4(0, vox + a2), vload4(0, vox + a2 + dxs[b + 2]));
      l3 = (float8)(vload4(0, vox + a3), vload4(0, vox + a3 + dxs[b + 3]));
#else
#ifdef SV_OFFS_AVX2
      if (cb) {
        const int b = 4 * h, a0 = ofs[r][b], a1 = ofs[r][b + 1], a2 = ofs[r][b + 2],
                  a3 = ofs[r][b + 3];
        __global const int* vi = (__global const int*)vox;
        l0 = as_float8((int8)(vload4(0, vi + a0), vload4(0, vi + a0 + dxs[b])));
        l1 = as_float8((int8)(vload4(0, vi + a1), vload4(0, vi + a1 + dxs[b + 1])));
        l2 = as_float8((int8)(vload4(0, vi + a2), vload4(0, vi + a2 + dxs[b + 2])));
        l3 = as_float8((int8)(vload4(0, vi + a3), vload4(0, vi + a3 + dxs[b + 3])));
      } else
#endif
      {
        const int8 o = rows[r]; /* (SV_LD4 without AVX-512: the extracts) */
        if (h == 0) {
          l0 = (float8)(SV_LD4(0));
          l1 = (float8)(SV_LD4(1));
          l2 = (float8)(SV_LD4(2));
          l3 = (float8)(SV_LD4(3));
        } else {
          l0 = (float8)(SV_LD4(4));
          l1 = (float8)(SV_LD4(5));
          l2 = (float8)(SV_LD4(6));
          l3 = (float8)(SV_LD4(7));
        }
      }
#endif
      const float16 v0 = (float16)((float8)(l0.lo, l1.lo), (float8)(l2.lo, l3.lo));
      const float16 v1 = (float16)((float8)(l0.hi, l1.hi), (float8)(l2.hi, l3.hi));
      q[r] = w1x * v1 - w0x * v0;
    }
    const float16 y0 = w1y * q[1] - w0y * q[0], y1 = w1y * q[3] - w0y * q[2];
    u[h] = w1z * y1 - w0z * y0;
  }
}
#undef SV_LD4
#ifdef SV_PIPE_AVX2
/* sv_sample8_il1 without the cell bits (cb = 0) in two parts, for
 * local.cl's pipelined step loop (SV_PIPE_AVX2 above): sv_addr8_il1 gathers
 * the lanes' pair-table entries as sv_sample8_il1 does and stores the 4
 * rows' offsets and dx in ofs[0..4] (the same integers); sv_interp8_il1
 * loads each offset back once (as SV_OFFS_AVX2 does with the cell bits),
 * loads the corners there and interpolates with the weights tt
 * (convert_float8(L) * 2^-32, as sv_sample8_il1 computes them): the same
 * loads and the same element-wise operations, so the same samples bit for
 * bit. */
SV_FN_INLINE void sv_addr8_il1(const int8* F, int nx, int ny, int nz, __global const long* pairs,
                               volatile int (*ofs)[8]) {
  const int n[3] = {nx, ny, nz};
  int8 base = (int8)(0), dd[3];
  __global const long* pt = pairs;
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    const int8 e = clamp(F[a], (int8)(-1), (int8)(n[a])) + 1;
    const long* pp = (const long*)(size_t)pt;
    const long8 q = (long8)(__builtin_ia32_gatherd_q256((long4)(0), pp, e.lo, (long4)(-1), 8),
                            __builtin_ia32_gatherd_q256((long4)(0), pp, e.hi, (long4)(-1), 8));
    const int8 t0 = convert_int8(q & 0xFFFFFFFFL), t1 = convert_int8(q >> 32);
    base += t0;
    dd[a] = t1 - t0;
    pt += n[a] + 2;
  }
  *(volatile int8*)ofs[0] = base;
  *(volatile int8*)ofs[1] = base + dd[1];
  *(volatile int8*)ofs[2] = base + dd[2];
  *(volatile int8*)ofs[3] = base + dd[1] + dd[2];
  *(volatile int8*)ofs[4] = dd[0];
}
SV_FN_INLINE void sv_interp8_il1(const float8* tt, __global const float* vox,
                                 volatile int (*ofs)[8], float16* u) {
  int dxs[8];
#pragma unroll
  for (int l = 0; l < 8; ++l) dxs[l] = ofs[4][l];
  __global const int* vi = (__global const int*)vox;
#pragma unroll
  for (int h = 0; h < 2; ++h) {
    const uint hb = 4 * h;
    const float16 w1x = sv_spread4(tt[0], hb), w0x = sv_spread4(tt[0] - 1.0f, hb);
    const float16 w1y = sv_spread4(tt[1], hb), w0y = sv_spread4(tt[1] - 1.0f, hb);
    const float16 w1z = sv_spread4(tt[2], hb), w0z = sv_spread4(tt[2] - 1.0f, hb);
    float16 q[4];
#pragma unroll
    for (int r = 0; r < 4; ++r) {
      const int b = 4 * h, a0 = ofs[r][b], a1 = ofs[r][b + 1], a2 = ofs[r][b + 2],
                a3 = ofs[r][b + 3];
      const float8 l0 = as_float8((int8)(vload4(0, vi + a0), vload4(0, vi + a0 + dxs[b])));
      const float8 l1 = as_float8((int8)(vload4(0, vi + a1), vload4(0, vi + a1 + dxs[b + 1])));
      const float8 l2 = as_float8((int8)(vload4(0, vi + a2), vload4(0, vi + a2 + dxs[b + 2])));
      const float8 l3 = as_float8((int8)(vload4(0, vi + a3), vload4(0, vi + a3 + dxs[b + 3])));
      const float16 v0 = (float16)((float8)(l0.lo, l1.lo), (float8)(l2.lo, l3.lo));
      const float16 v1 = (float16)((float8)(l0.hi, l1.hi), (float8)(l2.hi, l3.hi));
      q[r] = w1x * v1 - w0x * v0;
    }
    const float16 y0 = w1y * q[1] - w0y * q[0], y1 = w1y * q[3] - w0y * q[2];
    u[h] = w1z * y1 - w0z * y0;
  }
}
#endif
#endif

/* The samples of 8 lanes at F, L [0..2]: u[h] = lanes 4h .. 4h + 3, each its
 * premultiplied RGBA (sv_sample8's values, as (lane, channel)). */
SV_FN_INLINE void sv_sample8_il(const int8* F, const uint8* L, int nx, int ny, int nz,
                                __global const int* table, __global const long* pairs,
                                __global const float* vox, float16* u, const int cb) {
#ifdef SV_IL1_ROWS
  sv_sample8_il1(F, L, nx, ny, nz, table, pairs, vox, u, cb);
#else
  SV_AXES8(F, L, nx, ny, nz, table);
#if defined(__AVX512F__) && !defined(SV_OFFS_EXTRACT)
  /* The axes' offsets through memory, as sv_sample8_il1's (AVX-512): stored
   * as vectors, each loaded back once as a scalar; a corner's offset is
   * then two scalar additions instead of a vector addition and an extract.
   * simdvol-bench-options, the 256^3 phantom at (20, 35, 10), 2-core Xeon
   * (family 6, model 167), -DSV_OFFS_EXTRACT -> this, resample + local:
   * order 3 222.3 / 223.1 -> 171.1 / 174.1 ms, order 2 103.8 -> 87.6, order
   * 0 20.5 -> 20.4; ch2 at order 3 176.0 -> 135.5 ms; the same images. */
  volatile int vofs[3][SV_M][8];
#pragma unroll
  for (int e = 0; e < SV_M; ++e) {
    *(volatile int8*)vofs[0][e] = ax[e];
    *(volatile int8*)vofs[1][e] = ay[e];
    *(volatile int8*)vofs[2][e] = az[e];
  }
  int sofs[3][SV_M][8];
#pragma unroll
  for (int k = 0; k < 3; ++k)
#pragma unroll
    for (int e = 0; e < SV_M; ++e)
#pragma unroll
      for (int l = 0; l < 8; ++l) sofs[k][e][l] = vofs[k][e][l];
#endif
#pragma unroll
  for (int h = 0; h < 2; ++h) {
    const uint base = 4 * h;
    float16 wx[SV_M], wy[SV_M], wz[SV_M];
#pragma unroll
    for (int e = 0; e < SV_M; ++e) {
      wx[e] = sv_spread4(dx[e], base);
      wy[e] = sv_spread4(dy[e], base);
      wz[e] = sv_spread4(dz[e], base);
    }
    const int16 mx = as_int16(sv_spread4(as_float8(lx), base));
    const int16 my = as_int16(sv_spread4(as_float8(ly), base));
    const int16 mz = as_int16(sv_spread4(as_float8(lz), base));
    /* z outermost, as sv_sample8 (few values live) */
    float16 qz[SV_M];
#pragma unroll
    for (int c = 0; c < SV_M; ++c) {
      float16 qy[SV_M];
#pragma unroll
      for (int b = 0; b < SV_M; ++b) {
#if defined(__AVX512F__) && !defined(SV_OFFS_EXTRACT)
        int row[4];
#pragma unroll
        for (int l = 0; l < 4; ++l) row[l] = sofs[1][b][4 * h + l] + sofs[2][c][4 * h + l];
#else
        const int8 row = ay[b] + az[c];
#endif
        float16 qx[SV_M];
#pragma unroll
        for (int a = 0; a < SV_M; ++a) {
#if defined(__AVX512F__) && !defined(SV_OFFS_EXTRACT)
          const int4 o = (int4)(row[0] + sofs[0][a][4 * h], row[1] + sofs[0][a][4 * h + 1],
                                row[2] + sofs[0][a][4 * h + 2], row[3] + sofs[0][a][4 * h + 3]);
#else
          const int8 o8 = row + ax[a];
          const int4 o = h ? o8.hi : o8.lo;
#endif
          /* two float8 halves, then the float16: written as one float16 of
           * four float4, LLVM 15 split half of the 16-byte loads into two
           * 8-byte loads and a permute (64 vmovsd, 32 vpermpd in the kernel);
           * this way each is one vmovups or vinsertf128 from memory. */
#if defined(__AVX512F__) || defined(SV_LD4_FLOAT)
          const float8 lo = (float8)(vload4(0, vox + o.s0), vload4(0, vox + o.s1));
          const float8 hi = (float8)(vload4(0, vox + o.s2), vload4(0, vox + o.s3));
#else
          /* as ints, as sv_sample8_il1's SV_LD4 */
          __global const int* vi = (__global const int*)vox;
          const float8 lo = as_float8((int8)(vload4(0, vi + o.s0), vload4(0, vi + o.s1)));
          const float8 hi = as_float8((int8)(vload4(0, vi + o.s2), vload4(0, vi + o.s3)));
#endif
          qx[a] = (float16)(lo, hi);
        }
        sv_neville16(qx, wx, mx);
        qy[b] = qx[0];
      }
      sv_neville16(qy, wy, my);
      qz[c] = qy[0];
    }
    sv_neville16(qz, wz, mz);
    u[h] = qz[0];
  }
#endif
#if ORDER >= 2
  /* sv_clamp_sample on (lane, channel): each lane's alpha spread over its
   * channels */
  const uint16 ai = (uint16)(3, 3, 3, 3, 7, 7, 7, 7, 11, 11, 11, 11, 15, 15, 15, 15);
#pragma unroll
  for (int h = 0; h < 2; ++h) {
    const float16 a = fmin(fmax(shuffle(u[h], ai), 0.0f), 1.0f);
    u[h] = fmin(fmax(u[h], 0.0f), a);
  }
#endif
}

/* The 8 lanes' float4 results: from two float16 of (lane, channel), lanes
 * 0-3 and 4-7 (interleaved cells), or from the four channels' float8. */
SV_FN void sv_lanes_of16(const float16* u, float4* res) {
#pragma unroll
  for (int h = 0; h < 2; ++h) {
    res[4 * h] = u[h].s0123;
    res[4 * h + 1] = u[h].s4567;
    res[4 * h + 2] = u[h].s89ab;
    res[4 * h + 3] = u[h].scdef;
  }
}
SV_FN void sv_lanes_of8(const float8 r, const float8 g, const float8 b, const float8 a,
                        float4* res) {
  float rr[8], gg[8], bb[8], aa[8];
  vstore8(r, 0, rr);
  vstore8(g, 0, gg);
  vstore8(b, 0, bb);
  vstore8(a, 0, aa);
#pragma unroll
  for (int l = 0; l < 8; ++l) res[l] = (float4)(rr[l], gg[l], bb[l], aa[l]);
}

/* The voxels of the PE whose segments come SV_VOX_PF positions after the
 * work-item's (256: half a work-group ahead at 8 segments per work-item;
 * 0: none) are prefetched: the cell and the halo its stencils read, each
 * work-item its share of the rows in proportion to where those positions
 * lie in the PE's range (origins: each PE's cell origin; pe_cell = the
 * cell's extents and, in .w, 1 to prefetch, 0 for none). The blocks come
 * from memory, written by the shade + classify before (the 256^3 phantom's are
 * 268 MB): with every voxel load folded into 2 MiB (scratch build, wrong
 * images) the kernel took 24 against 52 ms at view (20, 35, 10), so it
 * waited on memory more than it computed; stencils walking a 32 KiB block
 * give the hardware's stream prefetch little to follow. Frames alternated
 * in one process (docs/PERFORMANCE.md), resample + local of the phantom /
 * ch2 at view (20, 35, 10): no prefetch 61.2 / 49.7 ms; 64 positions
 * ahead 57.5 / 48.4, 128 53.8 / 38.2, 256 44.8 / 36.8, 512 49.8 / 39.2,
 * 1024 56.6 ms (phantom); the PE's block alone without the halo (an
 * earlier form) 56.5 against 46.3 ms. A prefetch is a hint: it
 * changes no result. */
#ifndef SV_VOX_PF
#define SV_VOX_PF 256
#endif
/* The prefetch's rows as a cursor (sv_pf_begin sets it, sv_pf_row asks
 * for one row and steps on), so that the fused resample + local can spread
 * them over its steps (local.cl); sv_prefetch_pe_ahead asks for them all at
 * once. */
typedef struct {
  int r, r1, ly, ry, y0, z, x0, x1, run, tx0, lo, hi, nx, ny, nz;
} sv_pf;
SV_FN_INLINE void sv_pf_begin(__global const int* seg_off, const int log2p, const int nseg,
                              const int s0, const int p0, __global const sv_view* view,
                              __global const int* table, __global const int4* origins,
                              const int4 pe_cell, const int il, sv_pf* c) {
  c->r = c->r1 = 0;
#if SV_VOX_PF > 0
  const int sa = s0 + SV_VOX_PF;
  if (sa >= nseg || pe_cell.w <= 0) return;
#ifdef SV_PE_SEARCH2
  const int q = sv_pe_of_segment(seg_off, log2p, sa);
#else
  const int q = sv_pe_after(seg_off, log2p, p0, sa);
#endif
  const int a = seg_off[q], n = seg_off[q + 1] - a; /* n >= 1: sa is in q's range */
  /* This work-item's share [k0, k1) of K items: the same expression at both
   * ends, so the shares of consecutive work-items tile the items (double:
   * no 64-bit division). */
  const double share = 1.0 / (double)n;
#define SV_SHARE(K, d) min((int)((double)(sa - a + (d)) * (double)(K)*share), (K))
  /* The rows (y, z) of the cell and its stencils' halo (low 1, high 1 at
   * orders 0 and 1, high 2 at orders 2 and 3) that lie in the volume; this
   * work-item takes its share of them: the cell's part of each row (one
   * run in q's block) and its halo voxels in the neighbours' blocks. */
  const int4 o = origins[q];
  c->nx = view->dims[0];
  c->ny = view->dims[1];
  c->nz = view->dims[2];
  c->lo = ORDER >= 2 ? 1 : 0;
  c->hi = ORDER >= 2 ? 2 : 1;
  c->ry = pe_cell.y + c->lo + c->hi;
  const int rows = c->ry * (pe_cell.z + c->lo + c->hi);
  c->r = SV_SHARE(rows, 0);
  c->r1 = SV_SHARE(rows, 8);
#undef SV_SHARE
  /* (clamped: origins of another split would make a wrong hint, never a
   * read outside the table) */
  c->x0 = clamp(o.x, 0, c->nx - 1);
  c->x1 = min(c->x0 + pe_cell.x, c->nx);       /* the cell's x run */
  c->run = (c->x1 - 1 - c->x0) * (il ? 4 : 1); /* floats after the run's first */
  c->tx0 = table[c->x0];
  c->ly = c->r % c->ry;
  c->y0 = o.y - c->lo;
  c->z = o.z - c->lo + c->r / c->ry;
#endif
}
/* The rows' lines asked for into the second-level cache (prefetcht1; the
 * PE's steps come 256 positions later, about 32 work-items): with the rows
 * spread over the steps (local.cl) simdvol-bench-options --frames 12, in
 * turn, locality 3 (the first level, -DSV_VOX_PF_L1) -> 2, resample +
 * local, two runs each: the 256^3 phantom 25.45 / 25.40 -> 25.10 / 25.10
 * ms, at 512^2 25.64 / 25.68 -> 25.48 / 25.49, ch2 23.56 / 23.37 -> 23.31 /
 * 22.85 (2-core Intel Xeon, 2026-12-05; locality 1, prefetcht2, in between;
 * with the rows all at once before the steps the localities had measured
 * the same). */
#ifdef SV_VOX_PF_L1
#define SV_PFR(p) SV_PREFETCH(p)
#else
#define SV_PFR(p) SV_PREFETCH_L2(p)
#endif
SV_FN_INLINE void sv_pf_row(sv_pf* c, __global const int* table, __global const float* vox,
                            const int cs, const int il) {
  __global const int* tx = table;
  __global const int* ty = table + c->nx;
  __global const int* tz = table + c->nx + c->ny;
  const int y = c->y0 + c->ly, z = c->z;
  if (y >= 0 && y < c->ny && z >= 0 && z < c->nz) {
    const int row = ty[y] + tz[z];
    for (int ch = 0; ch < (il ? 1 : 4); ++ch) {
      __global const float* p = vox + row + ch * cs;
#ifndef SV_PF_STRIDE16
      {
        /* Each 64-byte line of the run once, from the line of its first
         * float to that of its last (the last voxel's 4 channels when
         * interleaved). -DSV_PF_STRIDE16 asks as before: every 16th float
         * of the run and its last, which asked for a line twice where the
         * run's end shares the line of the last 16th float (the phantom's
         * 128-byte rows: three prefetches for two lines) and missed none.
         * simdvol-bench-options, variants in turn in one process, twice
         * each, resample + local (2-core Intel Xeon, the tenth session of
         * 2026-12-05): ch2 (rows of 12 voxels, 192 bytes) 23.43 / 23.61 ->
         * 22.97 / 22.90 ms, brainsmall 3.49 / 3.49 -> 3.46 / 3.47, the
         * 256^3 phantom 25.73 / 25.66 -> 25.72 / 25.52 (at 512^2 25.68 /
         * 25.72 -> 25.81 / 25.75); the same images. */
        const ulong l0 = (ulong)(p + c->tx0) & ~(ulong)63;
        const ulong l1 = (ulong)(p + c->tx0 + c->run + (il ? 3 : 0));
        for (ulong q = l0; q <= l1; q += 64) SV_PFR((__global const float*)q);
      }
#else
      for (int e = 0; e < c->run; e += 16) SV_PFR(p + c->tx0 + e);
      SV_PFR(p + c->tx0 + c->run);
#endif
      for (int x = c->x0 - c->lo; x < c->x0; ++x)
        if (x >= 0) SV_PFR(p + tx[x]);
      for (int x = c->x1; x < min(c->x1 + c->hi, c->nx); ++x) SV_PFR(p + tx[x]);
    }
  }
  ++c->r;
  if (++c->ly == c->ry) {
    c->ly = 0;
    ++c->z;
  }
}
SV_FN void sv_prefetch_pe_ahead(__global const int* seg_off, const int log2p, const int nseg,
                                const int s0, const int p0, __global const sv_view* view,
                                __global const int* table, __global const float* vox, const int cs,
                                __global const int4* origins, const int4 pe_cell, const int il) {
  sv_pf c;
  sv_pf_begin(seg_off, log2p, nseg, s0, p0, view, table, origins, pe_cell, il, &c);
  while (c.r < c.r1) sv_pf_row(&c, table, vox, cs, il);
}

/* The PE of a float8 work-item's first position s0: written by the
 * segment order after it where `ordered` = 2 (simdvol_segment_order's
 * with_pe), else searched in seg_off. */
SV_FN_INLINE int sv_first_pe(__global const int* order, const int ordered,
                             __global const int* seg_off, const int log2p, const int nseg,
                             const int s0) {
  return ordered == 2 ? order[nseg + (s0 >> 3)] : sv_pe_of_segment(seg_off, log2p, s0);
}

/* Lanes of the segments at positions s0 .. s0 + 7 (those past nseg repeat
 * the last with length 0): segment order[position] if `ordered`, else the
 * position itself. (i, j, k0) and length per lane, and X[a] = the
 * fixed-point position of each lane's first sample; returns the longest
 * length.
 * The segments SV_SEG_PF positions ahead (4 KiB; 0: none) are prefetched:
 * the lanes' segment loads, scattered by `order` within their PE's range,
 * had about 7 % of the fused kernel's samples (perf annotate).
 * simdvol-bench-frame, its `ordered4` (the frame's kernel, every PE),
 * alternated three times: 0 / 30 / 45 deg 34.1-34.6 / 58.7-63.2 /
 * 66.3-72.7 -> 32.7-33.3 / 54.2-56.9 / 58.3-61.0 ms. */
#ifndef SV_SEG_PF
#define SV_SEG_PF 256
#endif
SV_FN int sv_lanes8(__global const sv_segment* segs, __global const int* order, const int ordered,
                    const int nseg, const int s0, __global const sv_view* view, int* li, int* lj,
                    int* lk, int* ln, long8* X, __global const short2* kb, const int use_kb) {
#if SV_SEG_PF > 0
  SV_PREFETCH(segs + min(s0 + SV_SEG_PF, nseg - 1));
  SV_PREFETCH(segs + min(s0 + SV_SEG_PF + 4, nseg - 1));
  if (use_kb) SV_PREFETCH(kb + min(s0 + SV_SEG_PF, nseg - 1));
#endif
  int T = 0;
#pragma unroll
  for (int l = 0; l < 8; ++l) {
    const int pos = min(s0 + l, nseg - 1);
    const int s = ordered ? order[pos] : pos;
    const sv_segment g = segs[s];
    /* use_kb: the balanced bounds a deferred unpack left in kb (match_cl.hpp:
     * BalanceUnpack); the segment's own k0, k1 are the matching's then */
    const short2 b = use_kb ? kb[s] : (short2)(0);
    const int k0 = use_kb ? b.x : g.k0, k1 = use_kb ? b.y : g.k1;
    li[l] = g.i;
    lj[l] = g.j;
    lk[l] = k0;
    ln[l] = s0 + l < nseg ? k1 - k0 : 0;
    T = max(T, ln[l]);
  }
  const int8 I = (int8)(li[0], li[1], li[2], li[3], li[4], li[5], li[6], li[7]);
  const int8 J = (int8)(lj[0], lj[1], lj[2], lj[3], lj[4], lj[5], lj[6], lj[7]);
  const int8 K = (int8)(lk[0], lk[1], lk[2], lk[3], lk[4], lk[5], lk[6], lk[7]);
#pragma unroll
  for (int a = 0; a < 3; ++a)
    X[a] = (long8)(view->origin[a]) + convert_long8(I) * view->step[a][0] +
           convert_long8(J) * view->step[a][1] + convert_long8(K) * view->step[a][2];
  return T;
}

/* The 8 lanes' positions one step on, the lanes with `on` clear kept where
 * they are: a lane past its segment's end reads clamped voxels whose values
 * are discarded (select), and frozen its reads hit the lines it read last
 * instead of walking on through lines nobody prefetched. Frames alternated
 * in one process (simdvol-bench-options, 20 frames, view (20, 35, 10)):
 * resample + local of the phantom 34.5 -> 32.4 ms, ch2 33.5 -> 32.4 ms,
 * brainsmall 5.41 -> 4.97 ms; -DSV_NO_FREEZE steps every lane.
 * The positions are split (sv_split8): the fraction's sum with the carry out
 * of it into the floor, the same integers as the 64-bit sum (frozen lanes
 * add 0 and carry nothing). Stepped as 64-bit sums and split at each sample
 * (before 2026-12-03), the fused resample + local at order 1 took 2-10 %
 * longer on the phantom (docs/PERFORMANCE.md). */
SV_FN void sv_step8(int8* F, uint8* L, int8 on, const long s0, const long s1, const long s2) {
#ifdef SV_NO_FREEZE
  on = (int8)(-1);
#endif
  const long s[3] = {s0, s1, s2};
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    const uint8 add = (uint8)((uint)(s[a] & 0xFFFFFFFFL)) & as_uint8(on);
    const uint8 l = L[a] + add;
    F[a] = F[a] + ((int8)((int)(s[a] >> SV_FRAC_BITS)) & on) - (l < add);
    L[a] = l;
  }
}

/* ---- empty-space skipping (the fused kernel's `reach` argument) ----
 * Bricks: the volume cut into SV_BRICK^3 voxel bricks, nb = ceil(n / SV_BRICK)
 * per axis, brick (bx, by, bz) at index bx + nbx * (by + nby * bz).
 *   simdvol_occupancy        occ[b] = 1 if some channel of some voxel of
 *                            brick b is not +-0 (NaN and inf count), else 0.
 *   simdvol_occupancy_reach  reach[b] = OR of occ over bricks b - lo .. b + hi
 *                            per axis (clipped to the grid).
 * A sample at fixed-point position X with floor f (clamped into the volume)
 * lies in brick f >> SV_BRICK_LOG2; its stencil reads voxels f + p, p in
 * 0..1 (orders 0, 1) or -1..2 (orders 2, 3), clamped into the volume, all
 * within bricks b - lo .. b + 1 (lo = ORDER >= 2, SV_BRICK >= 2). If
 * reach[b] = 0 every stencil value is +-0, so Neville gives +-0 in every
 * channel and over leaves the composite as it was, bit for bit (the
 * composite starts at +0 and never becomes -0: x + y = -0 needs x = y = -0).
 * The fused kernel skips a step when no lane still stepping is in one (and,
 * with -DSV_TRIM, first trims each lane to its first .. last sample in a
 * brick with reach, sv_trim8): the same bits as without skipping (tested). */
#define SV_BRICK (1 << SV_BRICK_LOG2) /* SV_BRICK_LOG2: simdvol_shared.h */

/* One work-item per (PE p, plane lz of its cell): 2-D range (cz, P). Scans
 * the plane's voxels inside the volume (padding is never read by a stencil)
 * in the PE's block: voxel (lx, ly, lz) channel c at
 * p * 4 * stride + c * stride + (lz * cy + ly) * cx + lx; sets occ[b] = 1
 * (SV_MARK: bricks straddle cells, so work-items race, all storing 1) for
 * each brick b holding a voxel with a channel that is not +-0. occ must be
 * zero before. */
SV_FN void sv_occupancy(__global const float* vox, const int stride, const int4 cell,
                        __global const int4* origins, const int4 dims, const int nbx, const int nby,
                        __global volatile uint* occ, const int il) {
  const int lz = (int)get_global_id(0), p = (int)get_global_id(1);
  if (lz >= cell.z) return;
  const int4 o = origins[p];
  const int gz = o.z + lz;
  if (gz >= dims.z) return;
  const int cx = min(cell.x, dims.x - o.x), cy = min(cell.y, dims.y - o.y);
  __global const float* v = vox + (size_t)p * 4 * stride + (size_t)lz * cell.y * cell.x;
  const int bz = (gz >> SV_BRICK_LOG2) * nby;
  for (int ly = 0; ly < cy; ++ly) {
    const int row = ly * cell.x;
    const int by = (bz + ((o.y + ly) >> SV_BRICK_LOG2)) * nbx;
    int b = o.x >> SV_BRICK_LOG2;
    uint any = 0;
    for (int lx = 0; lx < cx; ++lx) {
      const int bx = (o.x + lx) >> SV_BRICK_LOG2;
      if (bx != b) {
        if (any & 0x7fffffffu) SV_MARK(&occ[by + b]);
        b = bx;
        any = 0;
      }
      const int e = row + lx;
      if (il) {
        const uint4 q = as_uint4(vload4(0, v + 3 * (size_t)lz * cell.y * cell.x + 4 * e));
        any |= q.x | q.y | q.z | q.w;
      } else {
        any |= as_uint(v[e]) | as_uint(v[stride + e]) | as_uint(v[2 * stride + e]) |
               as_uint(v[3 * stride + e]);
      }
    }
    if (any & 0x7fffffffu) SV_MARK(&occ[by + b]);
  }
}

__kernel void simdvol_occupancy(__global const float* vox, const int stride, const int4 cell,
                                __global const int4* origins, const int4 dims, const int nbx,
                                const int nby, __global volatile uint* occ) {
  sv_occupancy(vox, stride, cell, origins, dims, nbx, nby, occ, 0);
}

/* simdvol_occupancy_il: the same on interleaved voxel cells (channel c of
 * position e at p * 4 * stride + 4 * e + c). */
__kernel void simdvol_occupancy_il(__global const float* vox, const int stride, const int4 cell,
                                   __global const int4* origins, const int4 dims, const int nbx,
                                   const int nby, __global volatile uint* occ) {
  sv_occupancy(vox, stride, cell, origins, dims, nbx, nby, occ, 1);
}

/* reach[b] from occ (lo, hi as above; lo, hi in 0..1). One work-item per
 * row of bricks (by, bz), 1-D range nby * nbz: the OR of the (lo + hi + 1)^2
 * rows (by', bz') around it, each read at x offsets -lo .. hi, 16 bricks at a
 * time in uint16 (a row's ends, and rows shorter than 16, element by
 * element with the offsets outside the row read as 0). The earlier kernel
 * took one work-item per brick (its index split by divisions, clipped
 * loops over up to 27 bricks, which PoCL ran as scalar code): on the 256^3
 * phantom (64^3 bricks, order 1) it took 1.8-2.2 ms of a frame that makes
 * the reach (the engine keeps it while the classification stays), this one
 * 0.15-0.29 ms (simdvol-bench-frame --views 45, the reach's profiling
 * event over 5 runs each; a 2-core Zen 4 EPYC, 2026-12-02). */
SV_FN uint16 sv_occ_row16(__global const uint* row, const int s, const int n) {
  if (s >= 0 && s + 16 <= n) return vload16(0, row + s);
  uint t[16];
  for (int i = 0; i < 16; ++i) t[i] = s + i >= 0 && s + i < n ? row[s + i] : 0u;
  return vload16(0, t);
}

__kernel void simdvol_occupancy_reach(__global const uint* occ, const int nbx, const int nby,
                                      const int nbz, const int lo, const int hi,
                                      __global uchar* reach) {
  const int w = (int)get_global_id(0);
  if (w >= nby * nbz) return;
  const int by = w % nby, bz = w / nby;
  const int y0 = max(by - lo, 0), y1 = min(by + hi, nby - 1);
  const int z0 = max(bz - lo, 0), z1 = min(bz + hi, nbz - 1);
  __global uchar* out = reach + (size_t)w * nbx;
  for (int x0 = 0; x0 < nbx; x0 += 16) {
    uint16 r = (uint16)(0);
    for (int z = z0; z <= z1; ++z)
      for (int y = y0; y <= y1; ++y) {
        __global const uint* row = occ + (size_t)nbx * (y + nby * z);
        for (int d = -lo; d <= hi; ++d) r |= sv_occ_row16(row, x0 + d, nbx);
      }
    const uchar16 u = convert_uchar16(r);
    if (x0 + 16 <= nbx) {
      vstore16(u, 0, out + x0);
    } else {
      uchar t[16];
      vstore16(u, 0, t);
      for (int i = 0; x0 + i < nbx; ++i) out[x0 + i] = t[i];
    }
  }
}

/* -1 in the lanes with on[l] whose sample at floors F is in a brick with
 * reach 1. */
SV_FN int8 sv_reach8(const int8* F, int nx, int ny, int nz, int nbx, int nby,
                     __global const uchar* reach, const int8 on) {
  const int8 fx = clamp(F[0], (int8)(0), (int8)(nx - 1));
  const int8 fy = clamp(F[1], (int8)(0), (int8)(ny - 1));
  const int8 fz = clamp(F[2], (int8)(0), (int8)(nz - 1));
  const int8 b =
      (fx >> SV_BRICK_LOG2) + nbx * ((fy >> SV_BRICK_LOG2) + nby * (fz >> SV_BRICK_LOG2));
  return (SV_GI8(reach, b) != 0) & on;
}

/* Trims each lane to its first .. last sample in a brick with reach 1 (the
 * samples before and after are +-0: skipping them changes no composite):
 * advances X to each lane's first such sample and sets N to the trimmed
 * lengths (0 if none); returns the longest. */
SV_FN int sv_trim8(long8* X, int8* N, const int T, const long s0, const long s1, const long s2,
                   int nx, int ny, int nz, int nbx, int nby, __global const uchar* reach) {
  int8 first = *N, last = (int8)(-1);
  /* the walk on split positions, every lane stepping */
  int8 F[3];
  uint8 L[3];
  sv_split8(X, F, L);
  for (int t = 0; t < T; ++t) {
    const int8 r = sv_reach8(F, nx, ny, nz, nbx, nby, reach, (int8)(t) < *N);
    first = select(first, min(first, (int8)(t)), r);
    last = select(last, (int8)(t), r);
    sv_step8(F, L, (int8)(-1), s0, s1, s2);
  }
  const int8 n = max(last - first + 1, (int8)(0));
  const long8 k = convert_long8(select((int8)(0), first, n > 0));
  X[0] += k * s0;
  X[1] += k * s1;
  X[2] += k * s2;
  *N = n;
  const int4 m4 = max(n.lo, n.hi);
  const int2 m2 = max(m4.lo, m4.hi);
  return max(m2.x, m2.y);
}

/* simdvol_resample_v8: simdvol_resample with 8 consecutive segments per
 * work-item as float8 lanes (range: ceil(nseg / 8) work-items); lane l
 * stores its sample t at out[sample_off[s] + t] while t < its length, s =
 * order[s0 + l] if `ordered` (local.cl: simdvol_segment_order), else
 * s0 + l. With `skip`, a step at which no lane still stepping has its
 * sample in a brick with reach (sv_reach8) stores +0 in every channel of
 * those lanes' samples without gathering: the gathered samples would be
 * +-0 there (see above), so the samples are the same but for the sign of
 * a zero, which neither over, nor adaptive compositing, nor a Monte Carlo
 * walk can tell (a walk stops where a draw is below alpha, and no draw in
 * [0, 1) is below +-0). */
/* simdvol_resample_v8 (planar cells, il = 0) and simdvol_resample_v8_il
 * (interleaved cells, il = 1: sv_sample8_il; the same samples bit for bit):
 * one body, the layout a constant. */
SV_FN_INLINE void sv_resample8(__global const sv_segment* segs, const int nseg,
                               __global const int* sample_off, __global const sv_view* view,
                               __global const int* table, __global const float* vox, const int cs,
                               __global float4* out, __global const int* order, const int ordered,
                               __global const uchar* reach, const int nbx, const int nby,
                               const int skip, __global const int* seg_off, const int log2p,
                               __global const int4* origins, const int4 pe_cell,
                               __global const long* pairs, const int il, const int cb) {
  const int s0 = (int)get_global_id(0) * 8;
  if (s0 >= nseg) return;
  int li[8], lj[8], lk[8], ln[8], lo[8];
  long8 X[3];
  const int T = sv_lanes8(segs, order, ordered, nseg, s0, view, li, lj, lk, ln, X, 0, 0);
  const int p0 = sv_first_pe(order, ordered, seg_off, log2p, nseg, s0);
  sv_prefetch_pe_ahead(seg_off, log2p, nseg, s0, p0, view, table, vox, cs, origins, pe_cell, il);
#pragma unroll
  for (int l = 0; l < 8; ++l) {
    const int pos = min(s0 + l, nseg - 1);
    lo[l] = sample_off[ordered ? order[pos] : pos];
  }
  const long s_0 = view->step[0][2], s_1 = view->step[1][2], s_2 = view->step[2][2];
  const int nx = view->dims[0], ny = view->dims[1], nz = view->dims[2];
  const int8 N = (int8)(ln[0], ln[1], ln[2], ln[3], ln[4], ln[5], ln[6], ln[7]);
  int8 F[3];
  uint8 L[3];
  sv_split8(X, F, L);
  for (int t = 0; t < T; ++t) {
    const int8 on = (int8)(t) < N;
    if (skip && !any(sv_reach8(F, nx, ny, nz, nbx, nby, reach, on))) {
#pragma unroll
      for (int l = 0; l < 8; ++l)
        if (t < ln[l]) out[lo[l] + t] = (float4)(0.0f);
      sv_step8(F, L, on, s_0, s_1, s_2);
      continue;
    }
    float4 res[8];
    if (il) {
      float16 u[2];
      sv_sample8_il(F, L, nx, ny, nz, table, pairs, vox, u, cb);
      sv_lanes_of16(u, res);
    } else {
      float8 u[4];
      sv_sample8(F, L, nx, ny, nz, table, vox, cs, u);
      sv_lanes_of8(u[0], u[1], u[2], u[3], res);
    }
#pragma unroll
    for (int l = 0; l < 8; ++l)
      if (t < ln[l]) out[lo[l] + t] = res[l];
    sv_step8(F, L, on, s_0, s_1, s_2);
  }
}

/* The kernels: planar cells (il = 0), interleaved cells (il = 1), and
 * interleaved cells whose pair table carries the cell bits (_ilc: cb = 1 at
 * order 1; resample_cell_bits): the same samples, bit for bit. */
#define SV_RESAMPLE_KERNEL(NAME, IL, CB)                                                         \
  __kernel void NAME(__global const sv_segment* segs, const int nseg,                            \
                     __global const int* sample_off, __global const sv_view* view,               \
                     __global const int* table, __global const float* vox, const int cs,         \
                     __global float4* out, __global const int* order, const int ordered,         \
                     __global const uchar* reach, const int nbx, const int nby, const int skip,  \
                     __global const int* seg_off, const int log2p, __global const int4* origins, \
                     const int4 pe_cell, __global const long* pairs) {                           \
    sv_resample8(segs, nseg, sample_off, view, table, vox, cs, out, order, ordered, reach, nbx,  \
                 nby, skip, seg_off, log2p, origins, pe_cell, pairs, IL, CB);                    \
  }
SV_RESAMPLE_KERNEL(simdvol_resample_v8, 0, 0)
SV_RESAMPLE_KERNEL(simdvol_resample_v8_il, 1, 0)
SV_RESAMPLE_KERNEL(simdvol_resample_v8_ilc, 1, ORDER == 1)
#undef SV_RESAMPLE_KERNEL

__kernel void simdvol_zero4(__global float4* p, const int n) {
  const int q = (int)get_global_id(0);
  if (q < n) p[q] = (float4)(0.0f);
}
