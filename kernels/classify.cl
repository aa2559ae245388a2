/* classify.cl — the classify stage on the PE array (thesis eq 4.4): material
 * mixture or transfer function, opacity-step correction, lit premultiplied
 * RGBA. The mathematics is that of host/core/classify.cpp (see its comment),
 * written again here in float.
 *
 * Input: the shade stage's voxel cells (kernels/shade.cl): (Id, Is, |g|, v)
 * per interior voxel, PE-major, planar per PE block (vstride floats per
 * plane). Output: voxel cells of the same shape holding the premultiplied
 * (a' C_r, a' C_g, a' C_b, a') per interior voxel. Classification is per
 * voxel and the blocks are contiguous, so the kernel runs over every
 * position: a 2-D range (position in a plane, PE) = (vstride rounded up to
 * the local size, pes), one work-item per position, consecutive work-items
 * on consecutive positions of one PE (the block tails are classified too;
 * gathers skip them). With one PE the buffer is the flat volume: the
 * benchmark's "flat" classify is this kernel on a 1-PE buffer, which is
 * why PE-major / flat comes out at 1.0 for classify.
 *
 * Compile-time specialisation (all optional; without them the kernel reads
 * the counts from the parameters and works for every classifier, slower):
 *   SV_KIND        SV_CLASSIFY_MIXTURE or SV_CLASSIFY_TRANSFER
 *   SV_NMAT        number of materials
 *   SV_NK_DENSITY, SV_NK_GRADIENT, SV_NK_RED, SV_NK_GREEN, SV_NK_BLUE
 *                  number of points of each ramp
 * With the counts known, the search for the bracketing material or ramp
 * segment is an unrolled run of compares and selects on values that are the
 * same for every work-item, which PoCL vectorises across work-items (a loop
 * with a run-time trip count would stay scalar).
 *
 * When shade.cl precedes this file in one program (SIMDVOL_SHADE_CL), the
 * fused kernel simdvol_shade_classify (shade + classify in one launch, same
 * decomposition and results as the two stages) and the flat comparison
 * kernel simdvol_shade_classify_flat are compiled too.
 */
#ifndef SIMDVOL_COMMON_CL
#include "common.cl"
#endif
/* float16 values passed to and returned from functions on a target without
 * AVX-512 draw clang's -Wpsabi warning ("changes the ABI") once per call
 * site; harmless here (everything is compiled together and inlined). */
#ifdef __clang__
#pragma clang diagnostic ignored "-Wpsabi"
#endif

#ifdef SV_KIND
#define SV_KIND_OF(cp) (SV_KIND)
#else
#define SV_KIND_OF(cp) ((cp)->kind)
#endif
#ifdef SV_NMAT
#define SV_NMAT_OF(cp) (SV_NMAT)
#else
#define SV_NMAT_OF(cp) ((cp)->material_count)
#endif
#ifdef SV_NK_DENSITY
#define SV_NK_DENSITY_OF(cp) (SV_NK_DENSITY)
#else
#define SV_NK_DENSITY_OF(cp) ((cp)->density.count)
#endif
#ifdef SV_NK_GRADIENT
#define SV_NK_GRADIENT_OF(cp) (SV_NK_GRADIENT)
#else
#define SV_NK_GRADIENT_OF(cp) ((cp)->gradient.count)
#endif
#ifdef SV_NK_RED
#define SV_NK_RED_OF(cp) (SV_NK_RED)
#else
#define SV_NK_RED_OF(cp) ((cp)->red.count)
#endif
#ifdef SV_NK_GREEN
#define SV_NK_GREEN_OF(cp) (SV_NK_GREEN)
#else
#define SV_NK_GREEN_OF(cp) ((cp)->green.count)
#endif
#ifdef SV_NK_BLUE
#define SV_NK_BLUE_OF(cp) (SV_NK_BLUE)
#else
#define SV_NK_BLUE_OF(cp) ((cp)->blue.count)
#endif
/* SV_STEP_ONE 1: the opacity step is 1 for every voxel (step_is_one), so
 * alpha is taken as it is; 0 (the default): cp->step_is_one decides. */
#ifndef SV_STEP_ONE
#define SV_STEP_ONE 0
#endif

/* sv_log, sv_exp and their float16 forms are in common.cl. */

/* Ramp r(v) with n points: y_0 at or below x_0 (and for NaN), y_last at or
 * above x_last, else linear on the segment of the last x_k <= v. The search
 * is a fully unrolled run of compares and selects (bound SV_MAX_KNOTS, the
 * guard k < n - 1 folds away when n is a compile-time constant). */
SV_FN float sv_ramp_eval(__constant const sv_ramp* r, const int n, float v) {
  if (n <= 0) return 1.0f;
  const float x0 = r->x[0], y0 = r->y[0];
  if (n == 1) return y0;
  float xa = x0, ya = y0, xb = r->x[1], yb = r->y[1];
#pragma unroll
  for (int k = 1; k < SV_MAX_KNOTS - 1; ++k) {
    if (k < n - 1) {
      const int in = r->x[k] <= v;
      xa = in ? r->x[k] : xa;
      ya = in ? r->y[k] : ya;
      xb = in ? r->x[k + 1] : xb;
      yb = in ? r->y[k + 1] : yb;
    }
  }
  const float t = (v - xa) / (xb - xa);
  float y = ya + t * (yb - ya);
  y = v >= r->x[n - 1] ? r->y[n - 1] : y;
  y = (isnan(v) || v <= x0) ? y0 : y;
  return y;
}

/* Material mixture of the (at most two) materials bracketing I; returns
 * alpha, (*cr, *cg, *cb) = premultiplied material colour, *trans = its
 * transparency: where alpha >= 1/2, t = p_i (1 - a_i) + p_j (1 - a_j) and
 * alpha = 1 - t (1 - alpha near 1 keeps only the first digits of t: an
 * opaque material's t of 1e-6 rounded 6 % off, which the opacity step's
 * power made differences of 1e-4 from the reference; classify.cpp), else
 * 1 - alpha. */
SV_FN float sv_mixture(__constant const sv_classify_params* cp, const int n, float v, float* cr,
                       float* cg, float* cb, float* trans) {
  __constant const sv_materials* m = &cp->materials;
  float I = v;
  if (cp->relative) I = cp->range_scale > 0.0f ? (v - cp->range_min) * cp->range_scale : 0.0f;
  /* i = last material with mean_i <= I, j = i + 1 (for mean_0 < I < mean_last):
   * unrolled compares and selects (see sv_ramp_eval). */
  const int j0 = n > 1 ? 1 : 0;
  float ai = m->opacity[0], ri = m->r[0], gi = m->g[0], bi = m->b[0];
  float aj = m->opacity[j0], rj = m->r[j0], gj = m->g[j0], bj = m->b[j0];
  float pc = m->pair_c[0], qa = m->pair_qa[0], qb = m->pair_qb[0], qc = m->pair_qc[0];
#pragma unroll
  for (int k = 1; k < SV_MAX_MATERIALS - 1; ++k) {
    if (k < n - 1) {
      const int in = m->mean[k] <= I;
      ai = in ? m->opacity[k] : ai;
      ri = in ? m->r[k] : ri;
      gi = in ? m->g[k] : gi;
      bi = in ? m->b[k] : bi;
      aj = in ? m->opacity[k + 1] : aj;
      rj = in ? m->r[k + 1] : rj;
      gj = in ? m->g[k + 1] : gj;
      bj = in ? m->b[k + 1] : bj;
      pc = in ? m->pair_c[k] : pc;
      qa = in ? m->pair_qa[k] : qa;
      qb = in ? m->pair_qb[k] : qb;
      qc = in ? m->pair_qc[k] : qc;
    }
  }
  /* p_i = 1 / (1 + exp(L_j - L_i)), L_m = -(I - mean_m)^2 / (2 sigma_m^2) -
   * ln sigma_m; L_j - L_i as the pair's quadratic about its c (classify.hpp,
   * mixture_pair: without the cancellation of the two L). */
  const float x = I - pc;
  const float dl = (qa * x + qb) * x + qc;
  /* The smaller fraction from e^-|dl|, not as 1 minus the larger: it keeps
   * its value far below 2^-24 (classify.cpp). */
  const float e = sv_exp(-fabs(dl));
  const float big = 1.0f / (1.0f + e), small = e * big;
  float pi = dl <= 0.0f ? big : small;
  float pj = dl <= 0.0f ? small : big;
  /* Pure first / last material outside the means. */
  const int first = I <= m->mean[0];
  const int last = I >= m->mean[n - 1];
  pi = (first || last) ? 1.0f : pi;
  pj = (first || last) ? 0.0f : pj;
  ai = first ? m->opacity[0] : last ? m->opacity[n - 1] : ai;
  ri = first ? m->r[0] : last ? m->r[n - 1] : ri;
  gi = first ? m->g[0] : last ? m->g[n - 1] : gi;
  bi = first ? m->b[0] : last ? m->b[n - 1] : bi;
  const float wi = pi * ai, wj = pj * aj;
  *cr = wi * ri + wj * rj;
  *cg = wi * gi + wj * gj;
  *cb = wi * bi + wj * bj;
  const float t = pi * (1.0f - ai) + pj * (1.0f - aj);
  const float a = wi + wj >= 0.5f ? 1.0f - t : wi + wj;
  *trans = a >= 0.5f ? t : 1.0f - a;
  return a;
}

/* Transfer function: alpha = density(v) * gradient(|g|), colour alpha * c(v). */
SV_FN float sv_transfer(__constant const sv_classify_params* cp, float v, float gmag, float* cr,
                        float* cg, float* cb) {
  const float a = sv_ramp_eval(&cp->density, SV_NK_DENSITY_OF(cp), v) *
                  sv_ramp_eval(&cp->gradient, SV_NK_GRADIENT_OF(cp), gmag);
  *cr = a * sv_ramp_eval(&cp->red, SV_NK_RED_OF(cp), v);
  *cg = a * sv_ramp_eval(&cp->green, SV_NK_GREEN_OF(cp), v);
  *cb = a * sv_ramp_eval(&cp->blue, SV_NK_BLUE_OF(cp), v);
  return a;
}

/* The series of the opacity step, one expression for the scalar functions
 * below and their 16-lane twins (sv_log1m16, ...), so that both compute
 * the same operations in the same order: 2 atanh(u) from u and u^2; -(1 -
 * e^x) for small |x|; the binomial a' for a small alpha a and step s. */
#define SV_LOG1M_SERIES(u, u2)                                  \
  ((u) *                                                        \
   (2.0f +                                                      \
    (u2) *                                                      \
        (0.666666667f +                                         \
         (u2) * (0.4f +                                         \
                 (u2) * (0.285714286f +                         \
                         (u2) * (0.222222222f +                 \
                                 (u2) * (0.181818182f +         \
                                         (u2) * (0.153846154f + \
                                                 (u2) * (0.133333333f + (u2)*0.117647059f)))))))))
#define SV_ONE_MINUS_EXP_SERIES(x)                              \
  ((x) *                                                        \
   (1.0f +                                                      \
    (x) * (0.5f +                                               \
           (x) * (0.166666667f +                                \
                  (x) * (0.0416666667f +                        \
                         (x) * (0.00833333333f +                \
                                (x) * (0.00138888889f +         \
                                       (x) * (0.000198412698f + \
                                              (x) * (2.48015873e-5f + (x)*2.75573192e-6f)))))))))
#define SV_STEP_SMALL_SERIES(a, s)   \
  ((s) * (a) *                       \
   (1.0f - 0.5f * ((s)-1.0f) * (a) * \
               (1.0f - ((s)-2.0f) * (1.0f / 3.0f) * (a) * (1.0f - ((s)-3.0f) * 0.25f * (a)))))

/* ln(1 - a) for 0 <= a <= 1/2, without forming 1 - a (whose rounding
 * would cost up to 3e-8 absolute, hundreds of ulp of a small a's step):
 * 2 atanh(u), u = -a / (2 - a), |u| <= 1/3, series to u^17 (truncation
 * below 1e-10 relative). */
SV_FN float sv_log1m(float a) {
  const float u = -a / (2.0f - a);
  const float u2 = u * u;
  return SV_LOG1M_SERIES(u, u2);
}
/* 1 - e^x for x <= 0 (where the step's x lies): below |x| 1/2 the series
 * -x (1 + x / 2 (1 + x / 3 (...))) to x^9 (truncation below 1e-9
 * relative), without the cancellation of 1 - e^x; from 1/2 on
 * 1 - sv_exp(x), which keeps at least 0.39. */
SV_FN float sv_one_minus_exp(float x) {
  const float p = SV_ONE_MINUS_EXP_SERIES(x);
  return fabs(x) < 0.5f ? -p : 1.0f - sv_exp(x);
}

/* The opacity for a sampling step s: a' = 1 - t^s = 1 - e^(s ln t), t the
 * transparency. Below 2^-8 the binomial series s a (1 - (s - 1) a / 2 (1 -
 * (s - 2) a / 3 (1 - (s - 3) a / 4))) (truncation below 1e-10 relative):
 * 1 - a would round to 1 below 2^-24 and give a' = 0 where the reference's
 * -expm1(s log1p(-a)) has a' > 0. From 2^-8 to 1/2, ln t = ln(1 - a) from a
 * (sv_log1m); from 1/2 on, ln t from the mixture's own t (sv_mixture; 1 - a
 * for a transfer function), 0 or normal. Then 1 - e^(s ln t) without
 * cancellation (sv_one_minus_exp). Within 4 ulp of the reference's double
 * (before 2026-12-06, with ln(1 - a) of the rounded 1 - a and 1 - e^x in
 * two steps: up to 332 ulp). */
SV_FN float sv_step_alpha(float a, float t, float s) {
  const float lt = a < 0.5f ? sv_log1m(a) : sv_log(t);
  const float big = t < FLT_MIN ? 1.0f : sv_one_minus_exp(s * lt);
  const float small = SV_STEP_SMALL_SERIES(a, s);
  return a < 0.00390625f ? small : big;
}

/* One voxel: (Id, Is, |g|, v) -> premultiplied RGBA in r, g, b, a. */
SV_FN void sv_classify_voxel(__constant const sv_classify_params* cp, float id, float is,
                             float gmag, float v, float* r, float* g, float* b, float* alpha) {
  float cr, cg, cb, t = 1.0f;
  float a;
  if (SV_KIND_OF(cp) == SV_CLASSIFY_TRANSFER) {
    a = sv_transfer(cp, v, gmag, &cr, &cg, &cb);
    t = 1.0f - a;
  } else {
    a = sv_mixture(cp, SV_NMAT_OF(cp), v, &cr, &cg, &cb, &t);
  }
#if SV_STEP_ONE
  const float a1 = a;
#else
  const float a1 = cp->step_is_one ? a : sv_step_alpha(a, t, cp->opacity_step);
#endif
  /* Else transparent (0, 0, 0, 0); so is a subnormal alpha (classify.cpp). */
  const int ok = a >= FLT_MIN && !isnan(v);
  const float inv = 1.0f / a;
  *r = ok ? a1 * fmin(1.0f, cr * inv * id + is) : 0.0f;
  *g = ok ? a1 * fmin(1.0f, cg * inv * id + is) : 0.0f;
  *b = ok ? a1 * fmin(1.0f, cb * inv * id + is) : 0.0f;
  *alpha = ok ? a1 : 0.0f;
}

/* ---------------------------------------------------------------- float16
 * The same classification on 16 voxels at once (explicit float16: PoCL's
 * loop vectoriser did not vectorise the scalar kernel on these machines).
 * The same float operations in the same order as the scalar functions
 * above; selects for their branches. */
SV_FN float16 sv_ramp_eval16(__constant const sv_ramp* r, const int n, float16 v) {
  if (n <= 0) return (float16)(1.0f);
  const float x0 = r->x[0], y0 = r->y[0];
  if (n == 1) return (float16)(y0);
  float16 xa = x0, ya = y0, xb = r->x[1], yb = r->y[1];
#pragma unroll
  for (int k = 1; k < SV_MAX_KNOTS - 1; ++k) {
    if (k < n - 1) {
      const int16 in = r->x[k] <= v;
      xa = select(xa, (float16)(r->x[k]), in);
      ya = select(ya, (float16)(r->y[k]), in);
      xb = select(xb, (float16)(r->x[k + 1]), in);
      yb = select(yb, (float16)(r->y[k + 1]), in);
    }
  }
  const float16 t = (v - xa) / (xb - xa);
  float16 y = ya + t * (yb - ya);
  y = select(y, (float16)(r->y[n - 1]), v >= r->x[n - 1]);
  y = select(y, (float16)(y0), isnan(v) | (v <= x0));
  return y;
}

/* With AVX2 (PoCL compiles for the host CPU and defines __AVX2__) and a
 * compile-time material count of 3..8, sv_mixture16 picks the bracketing
 * materials' parameters with vpermps (__builtin_ia32_permvarsf256) instead
 * of a chain of selects per parameter, which kept 28 vectors live and
 * spilled; OpenCL's shuffle() with a variable mask became per-element
 * extracts and inserts under PoCL 3.1. The values picked are the same.
 * SV_NO_PERMUTE keeps the select chain (for comparison). */
#if defined(__clang__) && defined(__AVX2__) && !defined(SV_NO_PERMUTE) && defined(SV_NMAT) && \
    SV_NMAT >= 3 && SV_NMAT <= 8
#define SV_MIX_PERMUTE 1
#if defined(__AVX512F__) && !defined(SV_NO_PERM512)
/* AVX-512: one vpermps of the 16 lanes (the 8 entries twice over) instead
 * of two 8-lane ones and an insert (the same values). simdvol-bench-options,
 * shade + classify, -DSV_NO_PERM512 -> this: the 256^3 phantom 11.5 / 11.6
 * -> 11.1 / 10.6 ms, ch2 13.8 -> 13.3 ms. */
#define SV_PERM16(t, i) (__builtin_ia32_permvarsf512((float16)((t), (t)), (i)))
#else
#define SV_PERM16(t, i) \
  ((float16)(__builtin_ia32_permvarsf256((t), (i).lo), __builtin_ia32_permvarsf256((t), (i).hi)))
#endif
#endif

/* The mixture's index I of values v (sv_mixture16). */
SV_FN float16 sv_mixture_index16(__constant const sv_classify_params* cp, float16 v) {
  if (cp->relative)
    return cp->range_scale > 0.0f ? (v - cp->range_min) * cp->range_scale : (float16)(0.0f);
  return v;
}

/* -1 in the lanes whose mixture alpha is 0 without evaluating it: I at or
 * below the first material's mean when that material is transparent
 * (there sv_mixture16 takes p_i = 1, a_i = opacity[0] = 0 and p_j = 0, so
 * a0 = 0; NaN fails the compare). 0 elsewhere: those need the mixture. */
SV_FN int16 sv_mixture_zero16(__constant const sv_classify_params* cp, float16 v) {
  if (cp->materials.opacity[0] != 0.0f) return (int16)(0);
  return sv_mixture_index16(cp, v) <= cp->materials.mean[0];
}

SV_FN float16 sv_mixture16(__constant const sv_classify_params* cp, const int n, float16 v,
                           float16* cr, float16* cg, float16* cb, float16* trans) {
  __constant const sv_materials* m = &cp->materials;
  const float16 I = sv_mixture_index16(cp, v);
#ifdef SV_MIX_PERMUTE
  /* i = the number of means mean_1 .. mean_{n-2} <= I (the means ascend, so
   * the last k of the select chain below), j = i + 1; each parameter is
   * picked from its 8-entry table by vpermps. */
  int16 ix = (int16)(0);
#pragma unroll
  for (int k = 1; k < SV_NMAT - 1; ++k) ix -= (int16)(m->mean[k] <= I); /* true is -1 */
  const int16 jx = ix + 1;
  const float8 ta = vload8(0, m->opacity);
  const float8 tr = vload8(0, m->r), tg = vload8(0, m->g), tb = vload8(0, m->b);
  const float8 tc = vload8(0, m->pair_c), tqa = vload8(0, m->pair_qa);
  const float8 tqb = vload8(0, m->pair_qb), tqc = vload8(0, m->pair_qc);
  float16 ai = SV_PERM16(ta, ix), ri = SV_PERM16(tr, ix), gi = SV_PERM16(tg, ix);
  float16 bi = SV_PERM16(tb, ix);
  const float16 aj = SV_PERM16(ta, jx), rj = SV_PERM16(tr, jx), gj = SV_PERM16(tg, jx);
  const float16 bj = SV_PERM16(tb, jx);
  const float16 pc = SV_PERM16(tc, ix), qa = SV_PERM16(tqa, ix);
  const float16 qb = SV_PERM16(tqb, ix), qc = SV_PERM16(tqc, ix);
#else
  const int j0 = n > 1 ? 1 : 0;
  float16 ai = m->opacity[0], ri = m->r[0], gi = m->g[0], bi = m->b[0];
  float16 aj = m->opacity[j0], rj = m->r[j0], gj = m->g[j0], bj = m->b[j0];
  float16 pc = m->pair_c[0], qa = m->pair_qa[0], qb = m->pair_qb[0], qc = m->pair_qc[0];
#pragma unroll
  for (int k = 1; k < SV_MAX_MATERIALS - 1; ++k) {
    if (k < n - 1) {
      const int16 in = m->mean[k] <= I;
      ai = select(ai, (float16)(m->opacity[k]), in);
      ri = select(ri, (float16)(m->r[k]), in);
      gi = select(gi, (float16)(m->g[k]), in);
      bi = select(bi, (float16)(m->b[k]), in);
      aj = select(aj, (float16)(m->opacity[k + 1]), in);
      rj = select(rj, (float16)(m->r[k + 1]), in);
      gj = select(gj, (float16)(m->g[k + 1]), in);
      bj = select(bj, (float16)(m->b[k + 1]), in);
      pc = select(pc, (float16)(m->pair_c[k]), in);
      qa = select(qa, (float16)(m->pair_qa[k]), in);
      qb = select(qb, (float16)(m->pair_qb[k]), in);
      qc = select(qc, (float16)(m->pair_qc[k]), in);
    }
  }
#endif
  const float16 x = I - pc;
  const float16 dl = (qa * x + qb) * x + qc; /* as sv_mixture */
  const float16 e = sv_exp16(-fabs(dl));
  const float16 big = 1.0f / (1.0f + e), small = e * big;
  const int16 lo = dl <= 0.0f;
  const int16 first = I <= m->mean[0];
  const int16 last = I >= m->mean[n - 1];
  const float16 pi = select(select(small, big, lo), (float16)(1.0f), first | last);
  const float16 pj = select(select(big, small, lo), (float16)(0.0f), first | last);
  ai = select(select(ai, (float16)(m->opacity[n - 1]), last), (float16)(m->opacity[0]), first);
  ri = select(select(ri, (float16)(m->r[n - 1]), last), (float16)(m->r[0]), first);
  gi = select(select(gi, (float16)(m->g[n - 1]), last), (float16)(m->g[0]), first);
  bi = select(select(bi, (float16)(m->b[n - 1]), last), (float16)(m->b[0]), first);
  const float16 wi = pi * ai, wj = pj * aj;
  *cr = wi * ri + wj * rj;
  *cg = wi * gi + wj * gj;
  *cb = wi * bi + wj * bj;
  /* the transparency, as sv_mixture */
  const float16 t = pi * (1.0f - ai) + pj * (1.0f - aj);
  const float16 a = select(wi + wj, 1.0f - t, wi + wj >= 0.5f);
  *trans = select(1.0f - a, t, a >= 0.5f);
  return a;
}

/* sv_transfer16 given d = density(v) (the fused kernel has it already). */
SV_FN float16 sv_transfer16_d(__constant const sv_classify_params* cp, float16 d, float16 v,
                              float16 gmag, float16* cr, float16* cg, float16* cb) {
  const float16 a = d * sv_ramp_eval16(&cp->gradient, SV_NK_GRADIENT_OF(cp), gmag);
  *cr = a * sv_ramp_eval16(&cp->red, SV_NK_RED_OF(cp), v);
  *cg = a * sv_ramp_eval16(&cp->green, SV_NK_GREEN_OF(cp), v);
  *cb = a * sv_ramp_eval16(&cp->blue, SV_NK_BLUE_OF(cp), v);
  return a;
}

SV_FN float16 sv_transfer16(__constant const sv_classify_params* cp, float16 v, float16 gmag,
                            float16* cr, float16* cg, float16* cb) {
  return sv_transfer16_d(cp, sv_ramp_eval16(&cp->density, SV_NK_DENSITY_OF(cp), v), v, gmag, cr, cg,
                         cb);
}

/* sv_log1m, sv_one_minus_exp and sv_step_alpha on 16 voxels (the same
 * operations lane by lane). */
SV_FN float16 sv_log1m16(float16 a) {
  const float16 u = -a / (2.0f - a);
  const float16 u2 = u * u;
  return SV_LOG1M_SERIES(u, u2);
}
SV_FN float16 sv_one_minus_exp16(float16 x) {
  const float16 p = SV_ONE_MINUS_EXP_SERIES(x);
  return select(1.0f - sv_exp16(x), -p, fabs(x) < 0.5f);
}
SV_FN float16 sv_step_alpha16(float16 a, float16 t, float s) {
  const float16 lt = select(sv_log16(t), sv_log1m16(a), a < 0.5f);
  const float16 big = select(sv_one_minus_exp16(s * lt), (float16)(1.0f), t < FLT_MIN);
  const float16 small = SV_STEP_SMALL_SERIES(a, s);
  return select(big, small, a < 0.00390625f);
}

/* The lit premultiplied RGBA of 16 voxels from the alpha `a` before the
 * opacity step and its transparency `t` (sv_mixture), where `ok` (else 0),
 * and each colour over that alpha (q = c * (1 / a)): the second half of
 * sv_classify16_lit, and what the fused kernel's kept classification is lit
 * by (kc_mode 2), so both give the same bits. */
SV_FN void sv_lit16(__constant const sv_classify_params* cp, float16 a, float16 t, int16 ok,
                    float16 qr, float16 qg, float16 qb, float16 id, float16 is, float16* r,
                    float16* g, float16* b, float16* alpha) {
#if SV_STEP_ONE
  const float16 a1 = a;
#else
  const float16 a1 = cp->step_is_one ? a : sv_step_alpha16(a, t, cp->opacity_step);
#endif
  const float16 z = 0.0f;
  *r = select(z, a1 * fmin(1.0f, qr * id + is), ok);
  *g = select(z, a1 * fmin(1.0f, qg * id + is), ok);
  *b = select(z, a1 * fmin(1.0f, qb * id + is), ok);
  *alpha = select(z, a1, ok);
}

/* The lit premultiplied RGBA of 16 voxels from the classifier's alpha `a`,
 * its transparency `t` and premultiplied material colour (cr, cg, cb)
 * (sv_classify16's second half). */
SV_FN void sv_classify16_lit(__constant const sv_classify_params* cp, float16 a, float16 t,
                             float16 cr, float16 cg, float16 cb, float16 id, float16 is, float16 v,
                             float16* r, float16* g, float16* b, float16* alpha) {
  const int16 ok = (a >= FLT_MIN) & ~isnan(v); /* else transparent, as sv_classify_voxel */
  const float16 inv = 1.0f / a;
  sv_lit16(cp, a, t, ok, cr * inv, cg * inv, cb * inv, id, is, r, g, b, alpha);
}

SV_FN void sv_classify16(__constant const sv_classify_params* cp, float16 id, float16 is,
                         float16 gmag, float16 v, float16* r, float16* g, float16* b,
                         float16* alpha) {
  float16 cr, cg, cb, a, t;
  if (SV_KIND_OF(cp) == SV_CLASSIFY_TRANSFER) {
    a = sv_transfer16(cp, v, gmag, &cr, &cg, &cb);
    t = 1.0f - a;
  } else {
    a = sv_mixture16(cp, SV_NMAT_OF(cp), v, &cr, &cg, &cb, &t);
  }
  sv_classify16_lit(cp, a, t, cr, cg, cb, id, is, v, r, g, b, alpha);
}

/* One chunk of 16 positions of PE p's planes from `shading` to `out`. The
 * pointers may be equal (simdvol_classify16_in_place): every plane a store
 * touches was loaded before it. */
SV_FN void sv_classify16_chunk(__global const float* shading, __global float* out, int vstride,
                               int p, int e0, __constant const sv_classify_params* cp) {
  const size_t base = (size_t)p * 4 * (size_t)vstride + (size_t)e0;
  __global const float* s = shading + base;
  __global float* o = out + base;
  float16 r, g, b, a;
  /* A chunk whose alpha is 0 without the mixture (sv_mixture_zero16) is
   * stored as zeros without reading the lighting planes or evaluating the
   * mixture: the same bits. */
  if (SV_KIND_OF(cp) == SV_CLASSIFY_MIXTURE &&
      all(sv_mixture_zero16(cp, SV_VLOAD16(s + 3 * vstride)))) {
    const float16 z = 0.0f;
    SV_VSTORE16(z, o);
    SV_VSTORE16(z, o + vstride);
    SV_VSTORE16(z, o + 2 * vstride);
    SV_VSTORE16(z, o + 3 * vstride);
    return;
  }
  sv_classify16(cp, SV_VLOAD16(s), SV_VLOAD16(s + vstride), SV_VLOAD16(s + 2 * vstride),
                SV_VLOAD16(s + 3 * vstride), &r, &g, &b, &a);
  SV_VSTORE16(r, o);
  SV_VSTORE16(g, o + vstride);
  SV_VSTORE16(b, o + 2 * vstride);
  SV_VSTORE16(a, o + 3 * vstride);
}

/* simdvol_classify16 (the default): 16 positions per work-item, 2-D range
 * (chunk, PE) = (vstride / 16 rounded up to the local size, pes). */
__kernel void simdvol_classify16(__global const float* restrict shading,
                                 __global float* restrict out, int vstride, int pes,
                                 __constant const sv_classify_params* cp) {
  const int e0 = 16 * (int)get_global_id(0);
  const int p = (int)get_global_id(1);
  if (e0 >= vstride || p >= pes) return;
  sv_classify16_chunk(shading, out, vstride, p, e0, cp);
}

/* simdvol_classify16_in_place: simdvol_classify16 with the output written
 * over its input. A line that is read and then written back costs one read
 * and one write; a store to a line not read first also reads it
 * (write-allocate), so out of place a voxel moves 48 bytes, in place 32. */
__kernel void simdvol_classify16_in_place(__global float* voxels, int vstride, int pes,
                                          __constant const sv_classify_params* cp) {
  const int e0 = 16 * (int)get_global_id(0);
  const int p = (int)get_global_id(1);
  if (e0 >= vstride || p >= pes) return;
  sv_classify16_chunk(voxels, voxels, vstride, p, e0, cp);
}

/* One position of PE p's planes; the pointers may be equal. */
SV_FN void sv_classify_position(__global const float* shading, __global float* out, int vstride,
                                int p, int e, __constant const sv_classify_params* cp) {
  const size_t base = (size_t)p * 4 * (size_t)vstride + (size_t)e;
  __global const float* s = shading + base;
  __global float* o = out + base;
  float r, g, b, a;
  sv_classify_voxel(cp, s[0], s[vstride], s[2 * vstride], s[3 * vstride], &r, &g, &b, &a);
  o[0] = r;
  o[vstride] = g;
  o[2 * vstride] = b;
  o[3 * vstride] = a;
}

/* simdvol_classify: see the file comment. 2-D range (element of a plane,
 * PE) = (vstride rounded up to the local size, pes). */
__kernel void simdvol_classify(__global const float* restrict shading, __global float* restrict out,
                               int vstride, int pes, __constant const sv_classify_params* cp) {
  const int e = (int)get_global_id(0);
  const int p = (int)get_global_id(1);
  if (e >= vstride || p >= pes) return;
  sv_classify_position(shading, out, vstride, p, e, cp);
}

/* simdvol_classify_in_place: simdvol_classify written over its input. */
__kernel void simdvol_classify_in_place(__global float* voxels, int vstride, int pes,
                                        __constant const sv_classify_params* cp) {
  const int e = (int)get_global_id(0);
  const int p = (int)get_global_id(1);
  if (e >= vstride || p >= pes) return;
  sv_classify_position(voxels, voxels, vstride, p, e, cp);
}

/* simdvol_gather_voxels: the in-volume voxels of voxel cells to a flat
 * array of four floats per voxel (x fastest). Same 3-D range and local size
 * as simdvol_shade. */
SV_FN void sv_gather_voxels(__global const float* restrict voxels, __global float* restrict flat,
                            __global const int4* restrict origins, int4 dims, int4 cell, int pes,
                            int vstride, const int il) {
  const int lx = (int)get_global_id(0);
  const int row = (int)get_global_id(1);
  const int p = (int)get_global_id(2);
  if (p >= pes || row >= cell.y * cell.z || lx >= cell.x) return;
  const int4 o = origins[p];
  const int x = o.x + lx, y = o.y + row % cell.y, z = o.z + row / cell.y;
  if (x >= dims.x || y >= dims.y || z >= dims.z) return;
  const size_t e = (size_t)row * (size_t)cell.x + (size_t)lx;
  /* planar: channel c at c * vstride + e; interleaved: at 4 * e + c */
  const size_t cs = il ? 1 : (size_t)vstride;
  __global const float* s = voxels + (size_t)p * 4 * (size_t)vstride + (il ? 4 * e : e);
  __global float* d = flat + 4 * sv_flat_index(dims, x, y, z);
  d[0] = s[0];
  d[1] = s[cs];
  d[2] = s[2 * cs];
  d[3] = s[3 * cs];
}

__kernel void simdvol_gather_voxels(__global const float* restrict voxels,
                                    __global float* restrict flat,
                                    __global const int4* restrict origins, int4 dims, int4 cell,
                                    int pes, int vstride) {
  sv_gather_voxels(voxels, flat, origins, dims, cell, pes, vstride, 0);
}

/* simdvol_gather_voxels_il: the same from interleaved voxel cells. */
__kernel void simdvol_gather_voxels_il(__global const float* restrict voxels,
                                       __global float* restrict flat,
                                       __global const int4* restrict origins, int4 dims, int4 cell,
                                       int pes, int vstride) {
  sv_gather_voxels(voxels, flat, origins, dims, cell, pes, vstride, 1);
}

#ifdef SIMDVOL_SHADE_CL
/* simdvol_shade_classify: shade and classify in one launch; decomposition
 * and arguments as simdvol_shade (kernels/shade.cl), output as
 * simdvol_classify. Equals running the two stages (the same float code). */
__kernel void simdvol_shade_classify(__global const float* restrict cells,
                                     __global float* restrict out,
                                     __global const int4* restrict origins, int4 dims, int4 cell,
                                     int4 block, int pes, int vstride,
                                     __constant const sv_shade_params* sp,
                                     __constant const sv_classify_params* cp) {
  const int lx = (int)get_global_id(0);
  const int row = (int)get_global_id(1);
  const int p = (int)get_global_id(2);
  const int rows = cell.y * cell.z;
  if (p >= pes) return;
  const int cvox = rows * cell.x;
  __global float* blk = out + (size_t)p * 4 * (size_t)vstride;
  /* The tail (< 16 per plane; the range has >= 16 work-items per PE, see
   * cell_range in host/cl/voxel_ranges.hpp), without a loop: a loop would
   * stop PoCL vectorising. */
  const int t = row * (int)get_global_size(0) + lx;
  if (t < vstride - cvox) sv_store4(blk, vstride, cvox + t, 0.0f, 0.0f, 0.0f, 0.0f);
  if (lx >= cell.x || row >= rows) return;
  const int ly = row % cell.y;
  const int lz = row / cell.y;
  const int4 o = origins[p];
  __global const float* c =
      cells + sv_block_start(block, p) + sv_block_offset(cell, block, lx, ly, lz);
  float id, is, mag, r, g, b, a;
  sv_shade_voxel(sp, c, block.x, block.x * block.y, (float)(o.x + lx), (float)(o.y + ly),
                 (float)(o.z + lz), &id, &is, &mag);
  sv_classify_voxel(cp, id, is, mag, c[0], &r, &g, &b, &a);
  sv_store4(blk, vstride, row * cell.x + lx, r, g, b, a);
}

/* simdvol_shade_classify_flat: the same on the flat volume (x fastest), one
 * work-item per voxel over the 3-D range (nx, ny, nz), neighbours clamped;
 * out is flat and planar too (plane c at c * nx * ny * nz). Not a pipeline
 * stage: kept to measure what the PE-major layout costs
 * (bench/bench_shade_classify.cpp). */
__kernel void simdvol_shade_classify_flat(__global const float* restrict volume,
                                          __global float* restrict out, int4 dims,
                                          __constant const sv_shade_params* sp,
                                          __constant const sv_classify_params* cp) {
  const int x = (int)get_global_id(0);
  const int y = (int)get_global_id(1);
  const int z = (int)get_global_id(2);
  if (x >= dims.x || y >= dims.y || z >= dims.z) return;
  const size_t i = sv_flat_index(dims, x, y, z);
  const int sy = dims.x, sz = dims.x * dims.y;
  const float v = volume[i];
  const float gx = 0.5f * (volume[i + (x + 1 < dims.x)] - volume[i - (x > 0)]) * sp->grad_scale[0];
  const float gy = 0.5f * (volume[i + (y + 1 < dims.y ? sy : 0)] - volume[i - (y > 0 ? sy : 0)]) *
                   sp->grad_scale[1];
  const float gz = 0.5f * (volume[i + (z + 1 < dims.z ? sz : 0)] - volume[i - (z > 0 ? sz : 0)]) *
                   sp->grad_scale[2];
  float g2, m;
  sv_grad_len(gx, gy, gz, &g2, &m);
  const float d =
      sp->depth_dir[0] * x + sp->depth_dir[1] * y + sp->depth_dir[2] * z + sp->depth_offset;
  const float cue = 1.0f / (sp->k1 + sp->k2 * d);
  const float nl = fabs(gx * sp->light[0] + gy * sp->light[1] + gz * sp->light[2]) / m;
  const float nh = fabs(gx * sp->halfway[0] + gy * sp->halfway[1] + gz * sp->halfway[2]) / m;
  const int surface = g2 >= sv_surface_g2(sp);
  float id = surface ? sp->ka + cue * sp->kd * nl : sp->ka;
  float is = surface ? cue * sp->ks * sv_spec_pow(sp, nh) : 0.0f;
  id = sp->enabled ? id : 1.0f;
  is = sp->enabled ? is : 0.0f;
  float r, g, b, a;
  sv_classify_voxel(cp, id, is, m, v, &r, &g, &b, &a);
  const size_t n = (size_t)dims.x * (size_t)dims.y * (size_t)dims.z;
  out[i] = r;
  out[n + i] = g;
  out[2 * n + i] = b;
  out[3 * n + i] = a;
}
#endif /* SIMDVOL_SHADE_CL */

#if defined(SIMDVOL_SHADE_CL) && defined(SV_RW)
/* Stores 16 lanes of (r, g, b, a) at positions e0 .. e0 + 15 of a PE's
 * interleaved block (channel c of position e at float 4 * e + c): the 4 x 16
 * transpose as two rounds of two-source shuffles, then 64 consecutive floats
 * (non-temporally where nt, SV_VSTORE16_NT). */
#if defined(__clang__) && defined(__AVX2__) && !defined(__AVX512F__) && !defined(SV_NO_IL_AVX2)
/* AVX2 (a float16 is two ymm registers): the shuffle2 rounds below became
 * element-by-element inserts and blends there (perf annotate: 139
 * instructions for the 8 stored ymm, vblendps, vinsertf128, vinsertps,
 * vpermilps ..., 40 of them spills and reloads), so each half of 8
 * positions is transposed in 128-bit lanes instead: unpack r with g and b
 * with a (vunpcklps / vunpckhps), their 64-bit pairs (vunpcklpd /
 * vunpckhpd), then the lanes (vperm2f128): 3 shuffles per stored ymm, the
 * same values. On a 2-core Zen 3 EPYC (2026-12-07, simdvol-bench-options
 * --frames 12, alternated twice, -DSV_NO_IL_AVX2 against this): shade +
 * classify of the 256^3 phantom at (20, 35, 10) 46.8 -> 42.2 ms mean
 * (0.90) with shade.cl's SV_SHADE_FN inlining, 61.0 -> 57.3 (0.94)
 * without it. SV_NO_IL_AVX2 keeps the shuffle2 form (for comparison). */
#define SV_IL_AVX2 1
SV_FN_INLINE void sv_il8(float8 r, float8 g, float8 b, float8 a, float16* o0, float16* o1) {
  const float8 t0 = __builtin_shufflevector(r, g, 0, 8, 1, 9, 4, 12, 5, 13);
  const float8 t1 = __builtin_shufflevector(r, g, 2, 10, 3, 11, 6, 14, 7, 15);
  const float8 t2 = __builtin_shufflevector(b, a, 0, 8, 1, 9, 4, 12, 5, 13);
  const float8 t3 = __builtin_shufflevector(b, a, 2, 10, 3, 11, 6, 14, 7, 15);
  /* positions (0, 4), (1, 5), (2, 6), (3, 7), RGBA each */
  const float8 u0 = __builtin_shufflevector(t0, t2, 0, 1, 8, 9, 4, 5, 12, 13);
  const float8 u1 = __builtin_shufflevector(t0, t2, 2, 3, 10, 11, 6, 7, 14, 15);
  const float8 u2 = __builtin_shufflevector(t1, t3, 0, 1, 8, 9, 4, 5, 12, 13);
  const float8 u3 = __builtin_shufflevector(t1, t3, 2, 3, 10, 11, 6, 7, 14, 15);
  *o0 = (float16)(__builtin_shufflevector(u0, u1, 0, 1, 2, 3, 8, 9, 10, 11),
                  __builtin_shufflevector(u2, u3, 0, 1, 2, 3, 8, 9, 10, 11));
  *o1 = (float16)(__builtin_shufflevector(u0, u1, 4, 5, 6, 7, 12, 13, 14, 15),
                  __builtin_shufflevector(u2, u3, 4, 5, 6, 7, 12, 13, 14, 15));
}
#endif
SV_FN void sv_store16_il(__global float* blk, int e0, float16 r, float16 g, float16 b, float16 a,
                         const int nt) {
#ifdef SV_IL_AVX2
  float16 o0, o1, o2, o3;
  sv_il8(r.lo, g.lo, b.lo, a.lo, &o0, &o1);
  sv_il8(r.hi, g.hi, b.hi, a.hi, &o2, &o3);
  __global float* o = blk + 4 * e0;
  SV_VSTORE16_NT(o0, o, nt);
  SV_VSTORE16_NT(o1, o + 16, nt);
  SV_VSTORE16_NT(o2, o + 32, nt);
  SV_VSTORE16_NT(o3, o + 48, nt);
  return;
#else
  const uint16 lo = (uint16)(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
  const uint16 hi = lo + 8u;
  float16 rg0 = shuffle2(r, g, lo), rg1 = shuffle2(r, g, hi);
  float16 ba0 = shuffle2(b, a, lo), ba1 = shuffle2(b, a, hi);
#if defined(__clang__) && defined(__AVX512F__) && !defined(SV_NO_STORE_BARRIER)
  /* An empty asm between the rounds: LLVM folded the two rounds into one
   * chain of about a dozen dependent vpermt2ps per stored vector (each
   * inserting the next element from one of the four inputs); kept apart they
   * are 8 two-source shuffles in all. simdvol-bench-options, shade + classify
   * (-DSV_NO_STORE_BARRIER against this): the 256^3 phantom 14.2 / 14.0 ->
   * 11.4 / 10.9 ms, ch2 16.4 -> 15.3 ms. */
  __asm__("" : "+v"(rg0), "+v"(rg1), "+v"(ba0), "+v"(ba1));
#endif
  const uint16 q0 = (uint16)(0, 1, 16, 17, 2, 3, 18, 19, 4, 5, 20, 21, 6, 7, 22, 23);
  const uint16 q1 = q0 + 8u;
  __global float* o = blk + 4 * e0;
  SV_VSTORE16_NT(shuffle2(rg0, ba0, q0), o, nt);
  SV_VSTORE16_NT(shuffle2(rg0, ba0, q1), o + 16, nt);
  SV_VSTORE16_NT(shuffle2(rg1, ba1, q0), o + 32, nt);
  SV_VSTORE16_NT(shuffle2(rg1, ba1, q1), o + 48, nt);
#endif
}

/* Zeros at positions e0 .. e0 + 15 of a PE's planar (il = 0) or
 * interleaved (il = 1) block: the chunk of a transparent run, without the
 * transpose. */
SV_FN_INLINE void sv_store16_zero(__global float* blk, int vstride, int e0, const int il,
                                  const int nt) {
  const float16 z = 0.0f;
  if (il) {
    __global float* o = blk + 4 * e0;
    SV_VSTORE16_NT(z, o, nt);
    SV_VSTORE16_NT(z, o + 16, nt);
    SV_VSTORE16_NT(z, o + 32, nt);
    SV_VSTORE16_NT(z, o + 48, nt);
  } else {
    sv_store16(blk, vstride, e0, z, z, z, z, nt);
  }
}

/* The classified chunk into planar (il = 0) or interleaved (il = 1) cells
 * (always inlined: LLVM kept it a call, its four float16 through memory). */
SV_FN_INLINE void sv_store16_rgba(__global float* blk, int vstride, int e0, float16 r, float16 g,
                                  float16 b, float16 a, const int il, const int nt) {
  if (il)
    sv_store16_il(blk, e0, r, g, b, a, nt);
  else
    sv_store16(blk, vstride, e0, r, g, b, a, nt);
}

/* sv_shade_classify16's transparent chunks: with use_live, `out` holds
 * what this kernel wrote in the frame before for the same cells,
 * classification and gradient scale (the lighting may differ;
 * enqueue_shade_classify's `live`), so a chunk found transparent holds its
 * zeros already and is left as it is, as the PEs flagged 0 are. The 256^3
 * phantom at (20, 35, 10), simdvol-bench-options --frames 15, two
 * alternations with -DSV_STORE_KEPT_ZEROS (which stores them again, for
 * comparison): shade + classify 13.97 / 13.96 -> 13.38 / 13.35 ms (a 2-core
 * Intel Xeon, 2026-12-05); brainsmall and ch2 within noise. */
#ifndef SV_STORE_KEPT_ZEROS
#define SV_STORE_KEPT_ZEROS 0
#endif
#define SV_ZERO_CHUNK()                                                              \
  {                                                                                  \
    if (kc_op == 1) SV_VSTORE16((float16)(0.0f), kq);                                \
    if (!use_live || SV_STORE_KEPT_ZEROS) sv_store16_zero(dst, vstride, e0, il, nt); \
  }
/* The kept planes of the PE this many PEs after a chunk's, prefetched by
 * the fused kernel's kept reading (0: none; classify.cl below). */
#ifndef SV_KEPT_PF_PE
#define SV_KEPT_PF_PE 1
#endif

/* The kept classification of a chunk (kc_mode 1): where lit, a0 below 1/2
 * and -t0 (its transparency, sv_mixture; -0 for t0 = 0) from 1/2 on, so
 * that both come back (sv_kept_alpha16), else +0; and each colour times 1 /
 * a0 (sv_classify16_lit's cr * inv). */
#define SV_KEEP_CLASS(a0, t0, cr, cg, cb)                                \
  if (kc_op == 1) {                                                      \
    const int16 lit_ = ((a0) >= FLT_MIN) & ~isnan(v) & in;               \
    const float16 inv_ = 1.0f / (a0);                                    \
    SV_VSTORE16(select(z, select((a0), -(t0), (a0) >= 0.5f), lit_), kq); \
    SV_VSTORE16(select(z, (cr)*inv_, lit_), kq + vstride);               \
    SV_VSTORE16(select(z, (cg)*inv_, lit_), kq + 2 * vstride);           \
    SV_VSTORE16(select(z, (cb)*inv_, lit_), kq + 3 * vstride);           \
  }
/* ... and its gradient (kc_mode | 4): gx, gy, gz (g2 and |g| are taken
 * from them again, sv_grad_len16). */
#define SV_KEEP_GRAD(gx, gy, gz)         \
  if (kc_op == 1 && kc_grad) {           \
    SV_VSTORE16((gx), kq + 4 * vstride); \
    SV_VSTORE16((gy), kq + 5 * vstride); \
    SV_VSTORE16((gz), kq + 6 * vstride); \
  }

/* simdvol_shade_classify16: the fused kernel on 16-position chunks
 * (simdvol_shade16 then simdvol_classify16 without the voxel cells in
 * between); range and arguments as simdvol_shade16 plus cp.
 * simdvol_shade_classify16_il: the same into interleaved voxel cells (the
 * float4 RGBA of each position together; stages.hpp), the same values. */
SV_FN void sv_shade_classify16(__global const float* restrict cells, __global float* restrict out,
                               __global const int4* restrict origins, int4 dims, int4 cell,
                               int4 block, int pes, int vstride,
                               __constant const sv_shade_params* sp,
                               __constant const sv_classify_params* cp, __global volatile uint* occ,
                               const int nbx, const int nby, const int mark,
                               __global const uchar* live, const int use_live,
                               __global float* restrict kc, const int kc_mode, const int il) {
  const int e0 = 16 * (int)get_global_id(0);
  const int p = (int)get_global_id(1);
  if (p >= pes || e0 >= vstride) return;
#ifndef SV_NO_LIVE
  /* A PE flagged 0 in `live` (use_live = 1) keeps what `out` holds: the
   * host passes the previous frame's PE mask only where that is the cell's
   * zeros and every voxel of the cell stays transparent (the same volume
   * and classification; engine.cpp), so this is what the kernel would
   * write; its bricks take no mark. -DSV_NO_LIVE writes them again, for
   * comparison. */
  if (use_live && !live[p]) return;
#endif
  int rb[SV_NRB];
  float fx[SV_NR], fy[SV_NR], fz[SV_NR], ok[SV_NR];
  sv_chunk_rows(origins, cell, block, p, e0, rb, fx, fy, fz, ok);
  __global const float* c = cells + sv_block_start(block, p);
  __global float* dst = out + (size_t)p * 4 * (size_t)vstride;
  /* the kept classification (kc_mode & 3: 1 written, 2 read; kc_mode & 4:
   * with the gradient) and the chunk's planes of it */
  const int kc_op = kc_mode & 3, kc_grad = (kc_mode & 4) != 0;
  /* kc_mode & 8: `out` stored non-temporally (the host: where it was
   * stored before; chunk_ranges.hpp, nt_out) */
  const int nt = (kc_mode & 8) != 0;
  __global float* kq = kc + (size_t)p * (kc_grad ? 7 : 4) * (size_t)vstride + e0;
  const int16 in = SV_ROWS16(ok) != 0.0f;
  /* (the cells' values are not read where the kept gradient is, so not
   * prefetched there) */
  if (kc_op != 2 || !kc_grad) sv_prefetch_ahead(c, rb);
  const float16 z = 0.0f;
  float16 id, is, mag, r, g, b, a;
  if (kc_op == 2) {
    /* The kept classification: a0 where the voxel is lit (alpha >= FLT_MIN,
     * its value not NaN, inside the cell), else 0, and each colour over a0;
     * the lighting as below, the same expressions (sv_classify16_lit), so
     * the same bits. A mixture's classification (an exp and the
     * materials' selects per voxel) was about a third of this kernel
     * (a probe without it: 13.7 -> 8.9 ms on the 256^3 phantom); reading
     * 16 bytes a lit voxel instead, scripts/bench-ab against 377a9cd (a
     * 2-core Intel Xeon, 2026-12-05): shade + classify 14.17 -> 11.36 ms
     * (0.809) on the phantom at (20, 35, 10), 13.72 -> 11.37 at (0, 45,
     * 0), ch2 19.04 -> 16.30; frame wall 0.957 / 0.941 / 0.957. A
     * transfer function's ramps cost less than those reads (brainsmall's
     * volpack preset: 1.88 -> 2.10 ms), so the engine keeps only a
     * mixture's. */
#if SV_KEPT_PF_PE > 0
    {
      /* The same chunk's kept planes of the PE SV_KEPT_PF_PE after p
       * prefetched: the next PE's chunks come right after this PE's in the
       * range, and the hardware prefetch does not follow the jump between
       * the PEs' blocks of planes. simdvol-bench-options --frames 12, two
       * alternations with -DSV_KEPT_PF_PE=0 (none) and =2: ch2 (7 planes)
       * 10.23 / 10.24 -> 8.72 / 8.80 ms (8.97 / 8.94 two PEs ahead), the
       * 256^3 phantom (4 planes) 8.56 / 8.50 -> 8.37 / 8.38 (8.45 / 8.43);
       * scripts/bench-ab against 6f98148: ch2 0.861, the phantom 0.990
       * (2-core Intel Xeon, 2026-12-05). A fixed 4096 floats ahead in each
       * plane (a first probe): the phantom 8.35 / 8.29 against 8.63 / 8.67. */
      const int planes = kc_grad ? 7 : 4;
      __global const float* kn = kq + (size_t)planes * (size_t)vstride * SV_KEPT_PF_PE;
      /* Into the second-level cache (-DSV_KEPT_PF_L1: the first, as
       * before the ninth session of 2026-12-05; in turn, two runs each:
       * the phantom 8.41 / 8.43 -> 8.35 / 8.32 ms, ch2 8.49 / 8.44 -> 8.35
       * / 8.33). */
#ifdef SV_KEPT_PF_L1
      for (int k = 0; k < planes; ++k) SV_PREFETCH(kn + k * vstride);
#else
      for (int k = 0; k < planes; ++k) SV_PREFETCH_L2(kn + k * vstride);
#endif
    }
#endif
    const float16 k0 = SV_VLOAD16(kq);
    if (!any(as_int16(k0) != 0)) { /* (a0 >= 1/2 is kept as -t0: sign bit) */
      SV_ZERO_CHUNK();
      return;
    }
    if (kc_grad) {
      /* the kept gradient, its length by the shading's expression: the
       * same lighting */
      const float16 gx = SV_VLOAD16(kq + 4 * vstride), gy = SV_VLOAD16(kq + 5 * vstride),
                    gz = SV_VLOAD16(kq + 6 * vstride);
      float16 g2;
      sv_grad_len16(gx, gy, gz, &g2, &mag);
      sv_light_rows(sp, fx, fy, fz, gx, gy, gz, g2, mag, &id, &is);
    } else {
      sv_shade_rows(sp, c, block, rb, fx, fy, fz, &id, &is, &mag);
    }
    /* a0 and t0 back from SV_KEEP_CLASS's plane: -t0 (its sign bit set,
     * -0 included) from a0 = 1/2 on, where a0 = 1 - t0 (sv_mixture's
     * expression); +0 where unlit */
    const int16 neg = as_int16(k0) < 0;
    const float16 t0 = select(1.0f - k0, -k0, neg);
    sv_lit16(cp, select(k0, 1.0f - t0, neg), t0, as_int16(k0) != 0, SV_VLOAD16(kq + vstride),
             SV_VLOAD16(kq + 2 * vstride), SV_VLOAD16(kq + 3 * vstride), id, is, &r, &g, &b, &a);
  } else {
    const float16 v = SV_LD16(c, rb, 0);
    /* Empty space: a voxel is (0, 0, 0, 0) unless its alpha before lighting is
     * > 0 and its value not NaN (sv_classify16_lit), whatever the shading; a
     * chunk with no such voxel is stored as zeros without being shaded (the
     * same bits). The mixture's alpha needs only v; the transfer function's is
     * density(v) * gradient(|g|), 0 where density(v) is. */
    if (SV_KIND_OF(cp) == SV_CLASSIFY_TRANSFER) {
      const float16 d = sv_ramp_eval16(&cp->density, SV_NK_DENSITY_OF(cp), v);
      if (!any((d != 0.0f) & ~isnan(v) & in)) {
        SV_ZERO_CHUNK();
        return;
      }
      /* The alpha needs only the gradient's magnitude: a chunk whose alpha is
       * transparent in every voxel (sv_classify16_lit's test) is stored as
       * zeros without its lighting (the same bits). brainsmall.den with the
       * volpack preset (its background noise has density > 0 and |g| below
       * the gradient ramp), simdvol-bench-shade --volume ... --runs 25,
       * alternated three times with SV_NO_EARLY_ALPHA (which leaves it out,
       * for comparison): fused 3.77-5.07 -> 3.64-4.29 ms, with the brick
       * marking 4.46-6.01 -> 4.01-4.55 ms. */
      float16 gx, gy, gz, g2, cr, cg, cb;
      sv_grad_rows(sp, c, block, rb, &gx, &gy, &gz, &g2, &mag);
      const float16 a0 = sv_transfer16_d(cp, d, v, mag, &cr, &cg, &cb);
#ifndef SV_NO_EARLY_ALPHA
      if (!any((a0 >= FLT_MIN) & ~isnan(v) & in)) {
        SV_ZERO_CHUNK();
        return;
      }
#endif
      const float16 t0 = 1.0f - a0;
      SV_KEEP_CLASS(a0, t0, cr, cg, cb)
      SV_KEEP_GRAD(gx, gy, gz)
      sv_light_rows(sp, fx, fy, fz, gx, gy, gz, g2, mag, &id, &is);
      sv_classify16_lit(cp, a0, t0, cr, cg, cb, id, is, v, &r, &g, &b, &a);
    } else {
      /* A chunk whose alpha is 0 without the mixture (sv_mixture_zero16). */
      if (!any(in & ~sv_mixture_zero16(cp, v))) {
        SV_ZERO_CHUNK();
        return;
      }
      float16 cr, cg, cb, t0;
      const float16 a0 = sv_mixture16(cp, SV_NMAT_OF(cp), v, &cr, &cg, &cb, &t0);
      if (!any((a0 > 0.0f) & ~isnan(v) & in)) {
        SV_ZERO_CHUNK();
        return;
      }
      SV_KEEP_CLASS(a0, t0, cr, cg, cb)
      /* (sv_shade_rows, its gradient kept on the way) */
      float16 gx, gy, gz, g2;
      sv_grad_rows(sp, c, block, rb, &gx, &gy, &gz, &g2, &mag);
      SV_KEEP_GRAD(gx, gy, gz)
      sv_light_rows(sp, fx, fy, fz, gx, gy, gz, g2, mag, &id, &is);
      sv_classify16_lit(cp, a0, t0, cr, cg, cb, id, is, v, &r, &g, &b, &a);
    }
  }
  sv_store16_rgba(dst, vstride, e0, select(z, r, in), select(z, g, in), select(z, b, in),
                  select(z, a, in), il, nt);
  /* The brick occupancy of resample.cl's simdvol_occupancy, marked here
   * from the values just stored (so no pass reads them again): each voxel
   * of the cell inside the volume with a channel that is not +-0 sets its
   * brick (SV_MARK: bricks straddle chunks and cells, so work-items race,
   * all storing 1). occ must be zero before; chunks stored as zeros above
   * mark nothing. */
  if (mark) {
#if SV_RW == 1
    const float16 xf = SV_ROWS16(fx);
#else
    const float16 xf = fx[0] + SV_IOTA16;
#endif
    const int16 X = convert_int16(xf), Y = convert_int16(SV_ROWS16(fy));
    const int16 Z = convert_int16(SV_ROWS16(fz));
    const int16 nz = ((as_int16(r) | as_int16(g) | as_int16(b) | as_int16(a)) & 0x7fffffff) != 0;
    const int16 set = nz & in & (X < dims.x) & (Y < dims.y) & (Z < dims.z);
    const int16 bi =
        (X >> SV_BRICK_LOG2) + nbx * ((Y >> SV_BRICK_LOG2) + nby * (Z >> SV_BRICK_LOG2));
#if SV_RW != 1 && SV_BRICK_LOG2 >= 2 && !defined(SV_MARK_LANES)
    /* Rows of 16, 8 or 4 start at x multiples of 4 (uniform cells of those
     * widths), so each quad of lanes 4k .. 4k + 3 lies in one row and one
     * brick: the quads' bricks, marked where a lane of the quad is set,
     * each distinct one once (SV_MARK_LANES, and other widths: the lanes' loop below).
     * simdvol-bench-shade on the 256^3 phantom, alternated three times:
     * marking cost the fused kernel 2.2-2.4 ms by the lanes' loop and
     * 1.4-1.9 ms by quads (17.9 / 18.5 / 16.6 -> 15.8 / 16.3 / 15.9 ms);
     * brainsmall the same. */
    const int4 sq = set.s048c | set.s159d | set.s26ae | set.s37bf;
    const int4 bq = bi.s048c;
    if (sq.x) SV_MARK(&occ[bq.x]);
    if (sq.y && !(sq.x && bq.y == bq.x)) SV_MARK(&occ[bq.y]);
    if (sq.z && !(sq.x && bq.z == bq.x) && !(sq.y && bq.z == bq.y)) SV_MARK(&occ[bq.z]);
    if (sq.w && !(sq.x && bq.w == bq.x) && !(sq.y && bq.w == bq.y) && !(sq.z && bq.w == bq.z))
      SV_MARK(&occ[bq.w]);
#else
    /* The distinct bricks of the set lanes, smallest first (usually one to
     * four per chunk): one mark each, no per-lane loop. Against a loop
     * over the 16 lanes (a mark where the brick changed), within each
     * run of simdvol-bench-shade (fused with and without marking, three
     * runs) the marking cost 7.5-7.9 ms that way and 4.2-5.8 ms this way. */
    int16 left = select((int16)(INT_MAX), bi, set);
    while (any(left != INT_MAX)) {
      const int8 m8 = min(left.lo, left.hi);
      const int4 m4 = min(m8.lo, m8.hi);
      const int2 m2 = min(m4.lo, m4.hi);
      const int brick = min(m2.x, m2.y);
      SV_MARK(&occ[brick]);
      left = select(left, (int16)(INT_MAX), left == brick);
    }
#endif
  }
}
#undef SV_ZERO_CHUNK
#undef SV_KEEP_CLASS
#undef SV_KEEP_GRAD

__kernel void simdvol_shade_classify16(
    __global const float* restrict cells, __global float* restrict out,
    __global const int4* restrict origins, int4 dims, int4 cell, int4 block, int pes, int vstride,
    __constant const sv_shade_params* sp, __constant const sv_classify_params* cp,
    __global volatile uint* occ, const int nbx, const int nby, const int mark,
    __global const uchar* live, const int use_live, __global float* restrict kc,
    const int kc_mode) {
  sv_shade_classify16(cells, out, origins, dims, cell, block, pes, vstride, sp, cp, occ, nbx, nby,
                      mark, live, use_live, kc, kc_mode, 0);
}

__kernel void simdvol_shade_classify16_il(
    __global const float* restrict cells, __global float* restrict out,
    __global const int4* restrict origins, int4 dims, int4 cell, int4 block, int pes, int vstride,
    __constant const sv_shade_params* sp, __constant const sv_classify_params* cp,
    __global volatile uint* occ, const int nbx, const int nby, const int mark,
    __global const uchar* live, const int use_live, __global float* restrict kc,
    const int kc_mode) {
  sv_shade_classify16(cells, out, origins, dims, cell, block, pes, vstride, sp, cp, occ, nbx, nby,
                      mark, live, use_live, kc, kc_mode, 1);
}
#endif

#ifdef SIMDVOL_SHADE_CL
/* simdvol_shade_classify_flat16: simdvol_shade_classify_flat with 16
 * consecutive voxels of a row per work-item (float16), 3-D range
 * (nx / 16, ny, nz); needs nx a multiple of 16. Not a pipeline stage: the
 * flat side of the PE-major / flat comparison for the float16 kernels. */
__kernel void simdvol_shade_classify_flat16(__global const float* restrict volume,
                                            __global float* restrict out, int4 dims,
                                            __constant const sv_shade_params* sp,
                                            __constant const sv_classify_params* cp) {
  const int x0 = 16 * (int)get_global_id(0);
  const int y = (int)get_global_id(1);
  const int z = (int)get_global_id(2);
  if (x0 >= dims.x || y >= dims.y || z >= dims.z) return;
  const size_t i = sv_flat_index(dims, x0, y, z);
  const int sy = dims.x, sz = dims.x * dims.y;
  __global const float* c = volume + i;
  const float16 v = SV_VLOAD16(c);
  /* x neighbours clamped at the row's ends (lane 0 / 15 reuse themselves) */
  const float16 xm =
      x0 > 0 ? SV_VLOAD16(c - 1) : (float16)(v.s0, v.s0, v.s1, v.s23, v.s4567, v.s89ab, v.scde);
  const float16 xp = x0 + 16 < dims.x
                         ? SV_VLOAD16(c + 1)
                         : (float16)(v.s1, v.s23, v.s4567, v.s89ab, v.scde, v.sf, v.sf);
  const float16 ym = SV_VLOAD16(c - (y > 0 ? sy : 0)),
                yp = SV_VLOAD16(c + (y + 1 < dims.y ? sy : 0));
  const float16 zm = SV_VLOAD16(c - (z > 0 ? sz : 0)),
                zp = SV_VLOAD16(c + (z + 1 < dims.z ? sz : 0));
  const float16 iota = (float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const size_t n = (size_t)dims.x * (size_t)dims.y * (size_t)dims.z;
  const float16 zero = 0.0f;
  float16 id, is, mag, r, g, b, a;
  /* Empty chunks as in simdvol_shade_classify16 (the same tests, so that
   * the PE-major / flat comparison compares layouts, not skips). */
  float16 cr, cg, cb, a0, t0;
  bool empty;
  if (SV_KIND_OF(cp) == SV_CLASSIFY_TRANSFER) {
    const float16 d = sv_ramp_eval16(&cp->density, SV_NK_DENSITY_OF(cp), v);
    empty = !any((d != 0.0f) & ~isnan(v));
    if (!empty) {
      float16 gx, gy, gz, g2;
      sv_grad16(sp, xm, xp, ym, yp, zm, zp, &gx, &gy, &gz, &g2, &mag);
      a0 = sv_transfer16_d(cp, d, v, mag, &cr, &cg, &cb);
      t0 = 1.0f - a0;
#ifndef SV_NO_EARLY_ALPHA
      empty = !any((a0 >= FLT_MIN) & ~isnan(v));
#endif
      if (!empty)
        sv_light16(sp, gx, gy, gz, g2, mag, (float)x0 + iota, (float16)((float)y),
                   (float16)((float)z), &id, &is);
    }
  } else {
    empty = all(sv_mixture_zero16(cp, v));
    if (!empty) {
      a0 = sv_mixture16(cp, SV_NMAT_OF(cp), v, &cr, &cg, &cb, &t0);
      empty = !any((a0 > 0.0f) & ~isnan(v));
      if (!empty)
        sv_shade16(sp, xm, xp, ym, yp, zm, zp, (float)x0 + iota, (float16)((float)y),
                   (float16)((float)z), &id, &is, &mag);
    }
  }
  if (empty) {
    SV_VSTORE16(zero, out + i);
    SV_VSTORE16(zero, out + n + i);
    SV_VSTORE16(zero, out + 2 * n + i);
    SV_VSTORE16(zero, out + 3 * n + i);
    return;
  }
  sv_classify16_lit(cp, a0, t0, cr, cg, cb, id, is, v, &r, &g, &b, &a);
  SV_VSTORE16(r, out + i); /* 64-byte aligned when nx is a multiple of 16 */
  SV_VSTORE16(g, out + n + i);
  SV_VSTORE16(b, out + 2 * n + i);
  SV_VSTORE16(a, out + 3 * n + i);
}
#endif /* SIMDVOL_SHADE_CL */
