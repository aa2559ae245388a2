#!/usr/bin/python3
"""Independent check of simdvol's images against indep_render.py.

usage: python3 run_cases.py --simdvol PATH [--work DIR] [--data DIR] [--quick]
       [--engines reference,opencl] [--only SUBSTRING] [--tol 1e-4]
       [--no-brain] [--jobs 2] [--fragile 16] [--nudge 1e-6] [--list]
       rival conventions (each fails some case, --quick included):
       [--depth faces] [--zphase half|int] [--igrid aligned] [--no-clamp]
       [--at-mean lower] [--rotation inverse|neg-angles|reversed]
       [--order2 centred-strict|far|low|high] [--sample-clamp none|alpha|unit]
       [--spacing-unit largest] [--grad-scale index] [--positions float]
       [--ramp-ends zero] [--tie-frac exact]
       --composite adaptive and mc: [--thr-nudge 1e-6] [--mc-tol 1e-5]
       [--mc-eps 2e-6] [--mc-fragile 8] [--zmax 4]; their rival conventions
       (each fails some --quick case): [--weight-frac exact]
       [--tiny-alphas plain] [--adaptive-stop early|late]
       [--adaptive-compare float64] [--mc-u low24]
       [--mc-counter swap] [--mc-simd 0x646d6973] [--mc-key swap]
       [--mc-ray col] [--mc-shared-key 0] [--mc-depth opaque]
       [--mc-exact-depth zero] [--mc-colour premult] [--mc-fallback none]
       [--mc-strata unscaled]; biased or wrong statistics:
       [--mc-expect eq7.12|drop-last|premult|ge] [--mc-var walks2x]
Writes volumes, classifier files and images under --work (default: a
temporary directory, removed after); uses brainsmall.den from --data
(default $SIMDVOL_DATA_DIR, else the repository's data/) where it is there,
and fails without it when SIMDVOL_REQUIRE_DATA=1; the full set also renders
ct/cranium.nhdr (0.957 x 0.957 x 1.5 mm) where it is there.  Exit 1 if a
case fails.

A pixel passes when every channel is within --tol of ours.  Our samples
lie where simdvol's do: on the 32.32 fixed-point grid that README
"Conventions" and KERNELS.md (sv_view) describe (the first sample's position
and the grid's three steps rounded to 2^-32), the half-voxel ties decided on
the fraction as a float (view.hpp's fixed_frac).  In float64 instead
(--positions float, --tie-frac exact) samples on or within 1e-8 voxel of a
voxel boundary, of the volume's face (the inside test floor(X) in [0, n)) or
of a half-voxel tie (orders 0 and 2) may fall the other way: at 45,45,45 and
at the rational view (cos 0.8, sin 0.6) tens to hundreds of pixels then
differ by up to 1.  Such a pixel is *fragile*: some copy of our image with
every sample moved by --nudge voxels (each of the 8 sign patterns along x,
y, z) matches simdvol's within --tol there.  A nudge of 1e-6 is far above
the grids' difference and far below anything else (a smooth pixel moves by
about 1e-6 times its gradient).  A pixel over --tol passes only if it is
fragile, and at most --fragile of an image (16: a residual 2^-32 mismatch
of the grid's origin could move a boundary sample of a few rays; a wrong
convention moves whole regions, hundreds of pixels, which no nudge
explains).  With the grid modelled no case here needs one.  The test
simdvol_independent_check runs --quick.

--composite adaptive (README: direct's over, stopping at --threshold) is
judged as direct: --tol, the nudges, and also a copy of our image with the
threshold moved by +-(--thr-nudge) (simdvol sums the alphas in float, so a
ray whose alpha lands within a rounding of the threshold may stop one sample
earlier or later); the accumulated alpha is compared with the threshold
as floats (bone's alpha 0.3 reaches --threshold 0.3 exactly in float32,
where float64's 0.3 lies below 0.3f: --adaptive-compare float64 fails 140
pixels there).  Both compositing modes below take their samples as README
"Where the samples lie" says, the fraction within a voxel a float also in
the interpolation weights (--weight-frac; a t within 2^-25 of 1 is 1, so a
voxel's weight 1 - t is 0 where float64 gives 1e-9), and a voxel's alpha
below 2^-126 as 0 with the opacity step taken without cancellation
(--tiny-alphas; found only in classify.cpp).  Neither changes a sample by
more than 1e-7, so direct keeps its float64 weights.  They matter because
the exact-opacity draws are keyed by the first sample with alpha > 0: an
alpha of 1e-20 in one renderer and 0 in the other moves every draw of the
ray (--tiny-alphas plain: 634 pixels of a --quick image off by up to 0.12).

Whole-ray --composite mc is reproduced: Philox4x32-10 (checked against
Random123's known answers first), key (seed mod 2^32, seed >> 32), counter
(ray, walk / 4, depth, 0x73696d64 "simd"), word walk mod 4, u = (word >> 8)
2^-24; ray = j * width + i on the viewing grid (the intermediate image with
voxel sampling, the output with pixel sampling), 0xFFFFFFFF for every ray
with --streams shared; depth = the sample's absolute index k on the ray (0
.. D - 1).  Walk m stops at the first sample with u(m, k) < alpha_k and
picks C'_k / alpha_k; colour = mean of the picks (black for a walk that
stops nowhere), alpha = the fraction that stopped.  --exact-opacity: alpha
= over's, colour = alpha * mean of the stopped walks' picks, or, with none
stopped, alpha * the pick of inverting the cumulative opacity at t = u
alpha (u: walk n's draw at the depth of the first sample with alpha > 0;
the first sample with alpha > 0 whose cumulative opacity exceeds t, else
the last).  --mc-stratified: walk m draws at that depth and inverts at t_m
= ((m + u_m) / n) alpha; colour = alpha * mean.  Then voxel sampling's warp.
Our samples are rounded to float32 and the picks, the cumulative opacity
and t computed in float32 as simdvol's are (ir.mc_composite).  A pixel
passes when every channel is within --mc-tol (1e-5).  Near ties: our
samples are simdvol's to a few float ulp, so a comparison (u against
alpha_k, t against a cumulative opacity) within --mc-eps (2e-6) may fall
the other way there.  So may the depth that keys the exact-opacity draws
where a ray's first samples with alpha > 0 have alphas below 2^-126:
subnormal in float32, they are 0 or not as the order of simdvol's float
operations rounds them (ours are float64 products rounded once); each of
those samples and the first one above 2^-126 is then a candidate depth.  A pixel over
--mc-tol passes only if taking the other outcome of one or two near ties of
its rays (the pixel's ray; with voxel sampling the 2 x 2 rays its warp
reads) brings it within --mc-tol, and at most --mc-fragile (8) such pixels
in an image: a wrong convention changes hundreds.  In the full set one
image needs a walk's near tie (1 pixel) and one the draws' depth (4 pixels,
a material mixture's Gaussian tail whose alphas underflow); --quick none.

Statistics, independent of how the random numbers are made: with per-ray
streams at pixel sampling (or voxel sampling where the warp is 1:1) each
pixel is one ray's estimate, independent of the others, whose exact
distribution follows from the ray's samples (ir.mc_moments: the mean is
the direct image; the variance v and fourth moment of the n-walk estimate
for plain, exact-opacity (H ~ Binomial(n, alpha) walks stop, at least one
pick) and stratified walks).  Per channel, e = simdvol - mean:
  z mean = sum e / sqrt(sum v),
  z sq   = (sum e^2 - sum v) / sqrt(sum (E e^4 - v^2))  (exact, not a bound);
both must lie within --zmax (4); a channel with no randomness (exact
opacity's alpha) must be within 1e-5 everywhere.  Per sub-ray Monte Carlo
(--mc-scope subray, with or without --allocate): the expectation is the
direct image too (each sub-ray's estimate is unbiased for its over, and the
sub-rays' draws are independent, being keyed by the absolute depth (HDR
mc.hpp), so eq 7.15's over of them is unbiased), but the variance depends
on where the PE cells and the balancing cut the rays, which the docs do
not give; two seeds give it: z = sum(x1 + x2 - 2 mean) / sqrt(sum (x1 -
x2)^2), since E (x1 - x2)^2 = 2 v whatever v is.  --mc-expect and --mc-var
are biased or wrong statistics, each failing some --quick case.
"""
import argparse
import dataclasses
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import indep_render as ir  # noqa: E402
from tiffread import read_tiff  # noqa: E402

SIMDVOL = 'simdvol'
HERE = os.path.dirname(os.path.abspath(__file__))
WORK = ''
DATA = os.environ.get('SIMDVOL_DATA_DIR') or os.path.join(HERE, '..', '..', 'data')


# ------------------------------------------------------------- volumes
def vol_a():
    """32^3 u8: a soft-edged sphere (~200) and a noisy box (~100)."""
    n = 32
    z, y, x = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing='ij')
    r = np.sqrt((x - 11.3) ** 2 + (y - 13.0) ** 2 + (z - 15.6) ** 2)
    v = 200.0 * np.clip((9.5 - r) / 3.0, 0, 1)
    box = (x >= 17) & (x < 29) & (y >= 5) & (y < 27) & (z >= 9) & (z < 25)
    rng = np.random.default_rng(7)
    v = np.where(box & (v < 100), 100 + rng.integers(-12, 13, v.shape), v)
    v[2, 2, 2] = 100          # exactly a material's mean
    v[0, 5:9, 20:24] = 150    # on the front face (z = 0)
    return np.rint(v).astype(np.uint8)


MAT_A = """# independent check: u8 materials
material air     0  18   0 0 0        0
material soft  100  20   0.9 0.5 0.3  0.12
material bone  200  30   1 0.95 0.8   0.55
"""

# density, gradient and colour ramps (README "Transfer-function files");
# knots inside the values' range, so that both ends are held somewhere.
TF_A = """# independent check: ramps on the u8 volume
density  40 0   90 0.15   160 0.4   230 0.9
gradient 2 0.1   12 0.6   40 1
color    0 0.2 0.3 0.9   110 0.9 0.6 0.3   210 1 0.95 0.7
"""


def vol_b():
    """48 x 40 x 36 (x, y, z) i16, CT-like: air -1000, a soft block, a bone
    shell, smooth edges."""
    nx, ny, nz = 48, 40, 36
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing='ij')
    r = np.sqrt(((x - 22.0) / 1.2) ** 2 + (y - 19.5) ** 2 + ((z - 17.0) / 0.9) ** 2)
    v = np.full((nz, ny, nx), -1000.0)
    soft = np.clip((15.0 - r) / 2.0, 0, 1)
    v += soft * 1040.0
    shell = np.exp(-((r - 11.0) / 1.3) ** 2)
    v += shell * 900.0 * (x > 15)
    v[(x > 38) & (x < 45) & (y > 4) & (y < 30) & (z > 3) & (z < 33)] = 1000 + (x[(x > 38) & (x < 45) & (y > 4) & (y < 30) & (z > 3) & (z < 33)] - 41) * 90
    return np.rint(v).astype(np.int16)


MAT_B = """# README's example mixture, absolute (Hounsfield-like)
material air   -1000 120  0 0 0        0
material soft     40  60  0.85 0.45 0.4 0.03
material bone   1000 250  1 0.97 0.9   0.3
"""


def vol_c():
    """40 x 30 x 24 (x, y, z) u16 for non-unit spacing (0.8, 1, 1.6 by
    default): a smooth ellipsoid of soft tissue around a denser core, and two
    sharp dense slabs with a transparent gap two voxels wide between them
    (where orders 2 and 3 overshoot: HARDENING's case)."""
    nx, ny, nz = 40, 30, 24
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing='ij')
    # physical coordinates (spacing 0.8, 1, 1.6)
    px, py, pz = (x - 16.0) * 0.8, (y - 14.0) * 1.0, (z - 12.5) * 1.6
    r = np.sqrt((px / 10.0) ** 2 + (py / 9.0) ** 2 + (pz / 12.0) ** 2)
    v = 320.0 * np.clip((1.0 - r) / 0.25, 0, 1)
    v += 500.0 * np.clip((0.45 - r) / 0.2, 0, 1)
    slab = (y >= 4) & (y < 26) & (z >= 3) & (z < 21)
    v = np.where(slab & ((x == 31) | (x == 32) | (x == 35) | (x == 36)), 900.0, v)
    rng = np.random.default_rng(11)
    v += np.where(v > 0, rng.integers(-15, 16, v.shape), 0)
    return np.clip(np.rint(v), 0, 65535).astype(np.uint16)


MAT_C = """# independent check: u16 materials
material air     0   60   0 0 0        0
material soft  320   70   0.8 0.55 0.45 0.1
material dense 850  120   0.95 0.95 1   0.6
"""

TF_C = """# ramps without a colour (white), over the gradient per smallest spacing
density  100 0   400 0.3   900 1
gradient 5 0   60 1
"""

MAT_BRAIN = """relative
material background 0.0  0.05  0 0 0       0
material csf        0.15 0.05  0.3 0.4 0.8 0.004
material grey       0.45 0.07  0.8 0.6 0.55 0.02
material white      0.6  0.06  0.95 0.9 0.85 0.04
material skin       0.85 0.1   1 0.8 0.65  0.2
"""

# the same materials of the range up to the 99th percentile of the
# foreground (the "mri" preset's rule; 'relative 99')
MAT_BRAIN99 = MAT_BRAIN.replace('relative\n', 'relative 99\n', 1)

# README "Transfer-function files": VolPack's example, verbatim
TF_BRAIN = """# VolPack's example: opacity = density ramp x gradient ramp, white
density  0 0   24 1   255 1
gradient 0 0   5 0   20 1   221 1
color    0 1 1 1
"""

SPACING_C = (0.8, 1.0, 1.6)
# data/ct/cranium.nhdr's spacings, as its header writes them
SPACING_CT = (0.9570312, 0.9570312, 1.5)


def load_den(path):
    b = open(path, 'rb').read()
    nx, ny, nz = np.frombuffer(b[50:56], '<i2')
    return np.frombuffer(b[62:], np.uint8).reshape(nz, ny, nx)


@dataclass
class Vol:
    data: np.ndarray
    args: list          # simdvol's volume arguments
    cls: dict           # classifier name -> file
    face: tuple         # default output size
    spacing: tuple = (1.0, 1.0, 1.0)


def write_inputs():
    os.makedirs(WORK, exist_ok=True)
    a, b, c = vol_a(), vol_b(), vol_c()
    a.tofile(os.path.join(WORK, 'a.raw'))
    b.astype('<i2').tofile(os.path.join(WORK, 'b.raw'))
    c.astype('<u2').tofile(os.path.join(WORK, 'c.raw'))
    for name, text in (('a.mat', MAT_A), ('a.tf', TF_A), ('b.mat', MAT_B), ('c.mat', MAT_C),
                       ('c.tf', TF_C), ('brain.mat', MAT_BRAIN), ('brain.tf', TF_BRAIN),
                       ('brain99.mat', MAT_BRAIN99)):
        open(os.path.join(WORK, name), 'w').write(text)
    w = lambda n: os.path.join(WORK, n)  # noqa: E731
    raw = lambda n, d, t: [w(n), '--raw-dims', d, '--raw-type', t]  # noqa: E731
    vols = {
        'a': Vol(a, raw('a.raw', '32,32,32', 'u8'), {'mat': w('a.mat'), 'tf': w('a.tf')}, (32, 32)),
        'b': Vol(b, raw('b.raw', '48,40,36', 'i16'), {'mat': w('b.mat'), 'mat99': w('brain99.mat')},
                 (48, 48)),
        'c': Vol(c, raw('c.raw', '40,30,24', 'u16') + ['--raw-spacing', '%g,%g,%g' % SPACING_C],
                 {'mat': w('c.mat'), 'tf': w('c.tf')}, (48, 48), SPACING_C),
        # the same voxels, spacing the other way round (largest along x)
        'c2': Vol(c, raw('c.raw', '40,30,24', 'u16') + ['--raw-spacing', '2,1,1.25'],
                  {'mat': w('c.mat')}, (64, 64), (2.0, 1.0, 1.25)),
    }
    den = os.path.join(DATA, 'brainsmall.den')
    if os.path.exists(den):
        vols['brain'] = Vol(load_den(den), [den], {'mat': w('brain.mat'), 'tf': w('brain.tf'),
                                                   'mat99': w('brain99.mat')},
                            (128, 128))
    elif os.environ.get('SIMDVOL_REQUIRE_DATA') == '1':
        raise SystemExit('run_cases.py: %s missing (scripts/fetch-data) and SIMDVOL_REQUIRE_DATA=1'
                         % den)
    # the real head CT (full set only: tens of seconds a case here), its
    # slices 1.5 mm apart and its pixels 0.957 mm: the one real volume whose
    # spacing differs along z; README's absolute mixture
    ct = os.path.join(DATA, 'ct', 'cranium.nhdr')
    if os.path.exists(ct):
        raw = np.fromfile(os.path.join(DATA, 'ct', 'cranium.raw'), '<i2')
        vols['ct'] = Vol(raw.reshape(108, 256, 256), [ct], {'mat': w('b.mat')}, (64, 64),
                         SPACING_CT)
    return vols


AXIS_VIEWS = [(0, 0, 0), (0, 90, 0), (0, 180, 0), (0, -90, 0), (0, 0, 90), (0, 0, -90),
              (90, 0, 0), (0, 90, 90)]
# oblique: the README's bench view, a turn in the image plane, about the
# vertical, all three at 45, and one with no special angle
OBLIQUE = [(20, 35, 10), (30, 0, 0), (0, 45, 0), (45, 45, 45), (-73.4, 151.7, 12.9)]
# a rotation with rational entries (cos 0.8, sin 0.6 about the vertical):
# many samples lie within the 32.32 grid's rounding of a voxel boundary
RATIONAL = (0, math.degrees(math.atan2(3, 4)), 0)

SHADINGS = {
    'noshade': (ir.Shade(enabled=False), ['--no-shade']),
    'phong': (ir.Shade(), []),
    'phong2': (ir.Shade(light=(0.3, -0.2, -1.0), ka=0.1, kd=0.6, ks=0.5, n=8, k1=1.0, k2=1.5),
               ['--light', '0.3,-0.2,-1', '--phong', '0.1,0.6,0.5,8', '--depth-cue', '1,1.5']),
    'phong-nocue': (ir.Shade(k1=1.0, k2=0.0), ['--depth-cue', '1,0']),
}


@dataclass(frozen=True)
class Comp:
    """--composite and its options (README render table)."""
    mode: str = 'direct'            # direct, adaptive, mc
    threshold: float = 0.95         # adaptive
    samples: int = 16               # mc: walks per ray
    seed: int = 1
    streams: str = 'per-ray'
    exact: bool = False             # --exact-opacity
    strat: bool = False             # --mc-stratified (with exact)
    scope: str = 'whole'            # --mc-scope
    allocate: bool = False          # --allocate (subray)

    def args(self, seed=None):
        if self.mode == 'direct':
            return []
        if self.mode == 'adaptive':
            return ['--composite', 'adaptive', '--threshold', repr(self.threshold)]
        a = ['--composite', 'mc', '--samples', str(self.samples),
             '--seed', str(self.seed if seed is None else seed)]
        if self.streams != 'per-ray':
            a += ['--streams', self.streams]
        if self.exact:
            a.append('--exact-opacity')
        if self.strat:
            a.append('--mc-stratified')
        if self.scope != 'whole':
            a += ['--mc-scope', self.scope]
        if self.allocate:
            a.append('--allocate')
        return a

    def label(self):
        if self.mode == 'adaptive':
            return 'adaptive t=%g' % self.threshold
        s = 'mc%d' % self.samples + ('x' if self.exact else '') + ('s' if self.strat else '')
        if self.scope != 'whole':
            s += ' ' + self.scope + (' alloc' if self.allocate else '')
        if self.streams != 'per-ray':
            s += ' ' + self.streams
        return s + ' seed=%d' % self.seed

    def params(self, seed=None):
        return ir.McParams(self.samples, self.seed if seed is None else seed, self.streams,
                           self.exact or self.strat, self.strat)


DIRECT = Comp()


@dataclass(frozen=True)
class Case:
    group: str
    vol: str
    view: tuple
    order: int
    shading: str
    size: tuple = None
    sampling: str = 'voxel'
    fit: str = 'longest'
    cls: str = 'mat'
    comp: Comp = DIRECT

    def name(self, vols):
        s = '%s view=%s order=%d %s' % (self.vol, ','.join('%.6g' % a for a in self.view),
                                         self.order, self.shading)
        if self.cls != 'mat':
            s += ' ' + self.cls
        if (self.size and self.size != vols[self.vol].face) or self.sampling != 'voxel':
            s += ' %dx%d %s' % (self.size + (self.sampling,))
        if self.fit != 'longest':
            s += ' fit=' + self.fit
        if self.comp.mode != 'direct':
            s += ' ' + self.comp.label()
        return s


# (The first of each is what --quick takes: 64x48 on 32^3 has an
# intermediate image of odd width, 45, so its rays lie off the voxel grid.)
SCALED = {'a': [(64, 48), (64, 64), (80, 80), (45, 45)], 'b': [(72, 72), (60, 50)]}
PIXEL = {'a': [(64, 64), (48, 48)], 'b': [(72, 60)]}


def cases(quick):
    out = []
    add = out.append
    # -- axis-aligned, orders 0 and 1 (the first check's cases)
    for v in ('a', 'b'):
        for view in (AXIS_VIEWS if not quick else AXIS_VIEWS[:3]):
            for order in (0, 1):
                for sh in (SHADINGS if not quick else ('noshade', 'phong')):
                    add(Case('axis', v, view, order, sh))
    for view in ((0, 0, 0), (0, 90, 0)):
        for sh in ('noshade', 'phong'):
            add(Case('brain', 'brain', view, 1, sh))
    add(Case('relative99', 'brain', (0, 0, 0), 1, 'phong', cls='mat99'))
    add(Case('relative99', 'b', (20, 35, 10), 1, 'noshade', cls='mat99'))
    for sampling, sizes in (('voxel', SCALED), ('pixel', PIXEL)):
        for v in ('a', 'b'):
            for size in sizes[v][:1 if quick else None]:
                for view in ((0, 0, 0), (0, 90, 0), (0, 180, 0))[:1 if quick else None]:
                    for order in (0, 1):
                        for sh in ('noshade', 'phong'):
                            add(Case('axis-' + sampling, v, view, order, sh, size, sampling))
    # -- orders 2 and 3 at axis-aligned views: the depth samples of 32^3 lie
    # half-way between slices (the order-2 stencil's tie), those of
    # 48 x 40 x 36 on them
    if quick:
        for c in (('a', (0, 0, 0), 2, 'phong'), ('a', (0, 90, 0), 2, 'noshade'),
                  ('a', (0, 0, 90), 3, 'phong'), ('b', (0, 0, 0), 3, 'phong'),
                  ('b', (0, 180, 0), 2, 'phong')):
            add(Case('axis-o23', *c))
    else:
        for v in ('a', 'b'):
            for view in AXIS_VIEWS[:3] + [(0, 0, 90), (90, 0, 0)]:
                for order in (2, 3):
                    for sh in ('noshade', 'phong'):
                        add(Case('axis-o23', v, view, order, sh))
    # -- oblique views, one pixel per voxel (voxel sampling: rays at voxel
    # spacing into an intermediate image 2 larger, then the 2-D scale)
    if quick:
        for c in (('a', (20, 35, 10), 0, 'phong'), ('a', (20, 35, 10), 1, 'phong'),
                  ('a', (20, 35, 10), 2, 'phong'), ('a', (20, 35, 10), 3, 'phong'),
                  ('a', (45, 45, 45), 2, 'noshade'), ('a', (30, 0, 0), 1, 'phong'),
                  ('b', (0, 45, 0), 3, 'phong'), ('b', (-73.4, 151.7, 12.9), 2, 'phong'),
                  ('b', (20, 35, 10), 1, 'noshade'), ('a', RATIONAL, 2, 'phong')):
            add(Case('oblique', *c))
    else:
        for v in ('a', 'b'):
            for view in OBLIQUE:
                for order in (0, 1, 2, 3):
                    for sh in ('noshade', 'phong'):
                        add(Case('oblique', v, view, order, sh))
        for v in ('a', 'b', 'c'):
            for view in (RATIONAL, (RATIONAL[1], 0, 0), (0, 0, RATIONAL[1])):
                for order in (0, 1, 2, 3):
                    add(Case('rational', v, view, order, 'phong'))
    # -- oblique, scaled voxel sampling and pixel sampling
    if quick:
        add(Case('oblique-voxel', 'a', (20, 35, 10), 3, 'phong', (64, 48)))
        add(Case('oblique-voxel', 'a', (45, 45, 45), 2, 'phong', (64, 48)))
        add(Case('oblique-voxel', 'b', (45, 45, 45), 1, 'phong2', (60, 50)))
        add(Case('oblique-pixel', 'a', (20, 35, 10), 2, 'phong', (64, 64), 'pixel'))
        add(Case('oblique-pixel', 'b', (-73.4, 151.7, 12.9), 1, 'phong', (72, 60), 'pixel'))
        # far wider than the volume: the intermediate image's 269 columns cut to 59
        add(Case('oblique-wide', 'a', (20, 35, 10), 1, 'phong', (200, 24)))
    else:
        for v, vs, ps in (('a', (64, 48), (64, 64)), ('b', (60, 50), (72, 60))):
            for view in ((20, 35, 10), (45, 45, 45), (-73.4, 151.7, 12.9)):
                for order in (1, 2, 3):
                    add(Case('oblique-voxel', v, view, order, 'phong', vs))
                    add(Case('oblique-pixel', v, view, order, 'phong2', ps, 'pixel'))
        for v, size in (('a', (48, 40)), ('b', (64, 64))):
            for view in ((20, 35, 10), (45, 45, 45)):
                for order in (1, 3):
                    add(Case('fit-diagonal', v, view, order, 'phong', size, 'voxel', 'diagonal'))
                add(Case('fit-diagonal', v, view, 2, 'phong', size, 'pixel', 'diagonal'))
        add(Case('rational', 'a', RATIONAL, 2, 'phong', (64, 48)))
        add(Case('rational', 'b', RATIONAL, 0, 'phong', (60, 50), 'pixel'))
    # -- non-unit spacing
    if quick:
        add(Case('spacing', 'c', (0, 0, 0), 1, 'phong'))
        add(Case('spacing', 'c', (20, 35, 10), 3, 'phong'))
        add(Case('spacing', 'c', (0, 90, 0), 1, 'phong', (56, 40), 'pixel'))
    else:
        for view in [(0, 0, 0), (0, 90, 0), (0, 0, 90)] + OBLIQUE[:1] + OBLIQUE[3:]:
            for order in (0, 1, 2, 3):
                for sh in ('noshade', 'phong'):
                    add(Case('spacing', 'c', view, order, sh))
        for view in ((0, 0, 0), (0, 90, 0), (20, 35, 10), (45, 45, 45)):
            for order in (1, 2):
                add(Case('spacing', 'c', view, order, 'phong2', (56, 40), 'pixel'))
                add(Case('spacing', 'c', view, order, 'phong', (60, 44), 'voxel'))
            add(Case('spacing', 'c2', view, 1, 'phong'))
            add(Case('spacing', 'c2', view, 3, 'phong', (50, 70), 'pixel'))
        add(Case('spacing', 'c', (20, 35, 10), 1, 'phong', (64, 48), 'voxel', 'diagonal'))
        add(Case('spacing', 'ct', (20, 35, 10), 1, 'phong', (64, 48)))
        add(Case('spacing', 'ct', (0, 90, 0), 1, 'phong2', (48, 64), 'pixel'))
        add(Case('spacing', 'ct', (45, 45, 45), 1, 'phong', (64, 64), 'voxel', 'diagonal'))
        add(Case('spacing', 'ct', (-73.4, 151.7, 12.9), 1, 'noshade', (64, 48),
                 comp=Comp('adaptive', threshold=0.8)))
    # -- density / gradient / colour ramps
    if quick:
        add(Case('ramps', 'a', (20, 35, 10), 1, 'phong', cls='tf'))
        add(Case('ramps', 'a', (0, 0, 0), 3, 'noshade', cls='tf'))
        add(Case('ramps', 'c', (45, 45, 45), 1, 'phong', cls='tf'))
    else:
        for view in ((0, 0, 0), (0, 90, 0), (20, 35, 10), (0, 45, 0), (-73.4, 151.7, 12.9)):
            for order in (0, 1, 3):
                for sh in ('noshade', 'phong'):
                    add(Case('ramps', 'a', view, order, sh, cls='tf'))
        for view in ((0, 0, 0), (20, 35, 10), (45, 45, 45)):
            add(Case('ramps', 'c', view, 1, 'phong', cls='tf'))
            add(Case('ramps', 'c', view, 2, 'noshade', (56, 40), 'pixel', cls='tf'))
        add(Case('ramps', 'brain', (20, 35, 10), 1, 'phong', cls='tf'))
        add(Case('ramps', 'brain', (0, 90, 0), 1, 'noshade', cls='tf'))
        add(Case('brain', 'brain', (20, 35, 10), 1, 'phong'))
    out += composite_cases(quick)
    return out


# a seed with both key words non-zero (the key is the 64-bit seed)
SEED_BIG = 0x9E3779B97F4A7C15


def composite_cases(quick):
    """--composite adaptive and mc."""
    out = []
    add = out.append
    ad = lambda t: Comp('adaptive', threshold=t)  # noqa: E731
    mc = lambda n, seed, **kw: Comp('mc', samples=n, seed=seed, **kw)  # noqa: E731
    # -- adaptive
    if quick:
        add(Case('adaptive', 'a', (20, 35, 10), 1, 'phong', (64, 48), comp=ad(0.5)))
        add(Case('adaptive', 'a', (0, 0, 0), 0, 'noshade', comp=ad(0.95)))
        add(Case('adaptive', 'b', (-73.4, 151.7, 12.9), 1, 'phong', (72, 60), 'pixel',
                 comp=ad(1.0)))
        add(Case('adaptive', 'c', (20, 35, 10), 3, 'phong', cls='tf', comp=ad(0.8)))
        # bone's opacity 0.3 reaches the threshold 0.3f exactly
        add(Case('adaptive', 'b', (0, 90, 0), 1, 'phong', comp=ad(0.3)))
    else:
        for v, vs, ps in (('a', (64, 48), (64, 64)), ('b', (60, 50), (72, 60))):
            for view in ((0, 0, 0), (0, 90, 0), (20, 35, 10), (-73.4, 151.7, 12.9)):
                for order in (0, 1, 2, 3):
                    for t in (0.3, 0.95):
                        add(Case('adaptive', v, view, order, 'phong', comp=ad(t)))
                add(Case('adaptive', v, view, 1, 'noshade', vs, comp=ad(0.5)))
                add(Case('adaptive', v, view, 2, 'phong2', ps, 'pixel', comp=ad(1.0)))
        for view in ((0, 0, 0), (20, 35, 10), (45, 45, 45)):
            for t in (0.5, 0.8, 1.0):
                add(Case('adaptive', 'c', view, 1, 'phong', cls='tf', comp=ad(t)))
                add(Case('adaptive', 'a', view, 3, 'phong', (64, 64), 'pixel', cls='tf',
                         comp=ad(t)))
        add(Case('adaptive', 'brain', (0, 90, 0), 1, 'phong', comp=ad(0.95)))
        add(Case('adaptive', 'brain', (20, 35, 10), 1, 'phong', cls='tf', comp=ad(0.5)))
    # -- whole-ray Monte Carlo: reproduced exactly and, where a pixel is one
    # ray (pixel sampling, or voxel sampling at 1:1) with per-ray streams,
    # the statistics
    if quick:
        add(Case('mc', 'a', (20, 35, 10), 1, 'phong', (64, 48), comp=mc(16, SEED_BIG)))
        add(Case('mc', 'a', (20, 35, 10), 1, 'phong', (64, 64), 'pixel', comp=mc(16, 5)))
        add(Case('mc', 'b', (0, 90, 0), 0, 'noshade', comp=mc(8, 3, streams='shared')))
        add(Case('mc', 'c', (0, 0, 0), 1, 'phong', (56, 40), 'pixel', cls='tf',
                 comp=mc(4, 13, exact=True)))
        add(Case('mc', 'a', (30, 0, 0), 1, 'phong', (64, 64), 'pixel', cls='tf',
                 comp=mc(16, 11, exact=True, strat=True)))
        add(Case('mc', 'b', (20, 35, 10), 1, 'phong', (72, 60), 'pixel',
                 comp=mc(8, 5, exact=True, strat=True)))
        add(Case('mc', 'a', (-73.4, 151.7, 12.9), 3, 'phong', (64, 48),
                 comp=mc(8, SEED_BIG, exact=True)))
        # ray j * width + i on the cut intermediate image (24 x 200: 59 rows of 269)
        add(Case('mc', 'a', (20, 35, 10), 1, 'phong', (24, 200), comp=mc(8, 7)))
    else:
        for v, vs, ps in (('a', (64, 48), (64, 64)), ('b', (60, 50), (72, 60))):
            for view in ((0, 0, 0), (20, 35, 10), (-73.4, 151.7, 12.9)):
                for order in (0, 1, 3):
                    add(Case('mc', v, view, order, 'phong', comp=mc(16, 2 + order)))
                    add(Case('mc', v, view, order, 'phong', ps, 'pixel', comp=mc(8, SEED_BIG)))
                    add(Case('mc', v, view, order, 'phong', comp=mc(4, 7, exact=True)))
                    add(Case('mc', v, view, order, 'phong', ps, 'pixel',
                             comp=mc(16, SEED_BIG, exact=True, strat=True)))
                add(Case('mc', v, view, 1, 'phong', vs, comp=mc(32, 9, streams='shared')))
                add(Case('mc', v, view, 2, 'noshade', ps, 'pixel',
                         comp=mc(4, 9, streams='shared')))
        for v, ps in (('a', (64, 64)), ('c', (56, 40))):
            for view in ((0, 0, 0), (0, 90, 0), (20, 35, 10), (-73.4, 151.7, 12.9)):
                for order in (0, 1, 2, 3):
                    add(Case('mc', v, view, order, 'phong', cls='tf', comp=mc(4, 7, exact=True)))
                    add(Case('mc', v, view, order, 'phong', cls='tf',
                             comp=mc(16, SEED_BIG, exact=True, strat=True)))
                add(Case('mc', v, view, 1, 'phong', ps, 'pixel', cls='tf',
                         comp=mc(2, 13, exact=True)))
                add(Case('mc', v, view, 1, 'phong', ps, 'pixel', cls='tf',
                         comp=mc(32, 13, exact=True, strat=True)))
                add(Case('mc', v, view, 1, 'phong', ps, 'pixel', cls='tf',
                         comp=mc(8, 13, exact=True, strat=True, streams='shared')))
        # walk counts not a multiple of 4 (a Philox block serves walks 4q .. 4q + 3)
        for n, kw in ((1, {}), (3, {}), (5, dict(exact=True)), (7, dict(exact=True, strat=True)),
                      (1, dict(exact=True, strat=True))):
            add(Case('mc', 'a', (20, 35, 10), 1, 'phong', (48, 48), 'pixel', comp=mc(n, 77, **kw)))
        add(Case('mc', 'brain', (0, 90, 0), 1, 'phong', cls='tf', comp=mc(16, 4)))
        add(Case('mc', 'brain', (20, 35, 10), 1, 'phong', comp=mc(8, 4, exact=True, strat=True)))
    # -- per sub-ray Monte Carlo: unbiased (two seeds), pixel sampling
    if quick:
        add(Case('mc-subray', 'a', (20, 35, 10), 1, 'phong', (64, 64), 'pixel',
                 comp=mc(8, 21, scope='subray')))
        add(Case('mc-subray', 'b', (20, 35, 10), 1, 'phong', (72, 60), 'pixel',
                 comp=mc(8, 23, exact=True, scope='subray', allocate=True)))
    else:
        for v, ps in (('a', (64, 64)), ('b', (72, 60))):
            for view in ((0, 0, 0), (20, 35, 10), (-73.4, 151.7, 12.9)):
                for kw in (dict(), dict(allocate=True), dict(exact=True),
                           dict(exact=True, allocate=True), dict(exact=True, strat=True),
                           dict(exact=True, strat=True, allocate=True)):
                    add(Case('mc-subray', v, view, 1, 'phong', ps, 'pixel',
                             comp=mc(8, 21, scope='subray', **kw)))
    return out


def metrics(a, b):
    d = np.abs(a.astype(np.float64) - b.astype(np.float64))
    mse = (d[..., :3] ** 2).mean()   # as `simdvol compare`: RGB, peak 1
    psnr = math.inf if mse == 0 else -10 * math.log10(mse)
    return d.max(), psnr


def run_simdvol(args, out, engine):
    cmd = [SIMDVOL, 'render'] + args + ['-o', out, '--engine', engine]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(' '.join(cmd) + '\n' + r.stderr)
    return read_tiff(out)


def main():
    global SIMDVOL, WORK, DATA
    ap = argparse.ArgumentParser()
    ap.add_argument('--simdvol', required=True, help='the simdvol program')
    ap.add_argument('--work', default='', help='directory for the inputs and images')
    ap.add_argument('--data', default=DATA, help='where brainsmall.den is')
    ap.add_argument('--quick', action='store_true')
    ap.add_argument('--engines', default='reference,opencl')
    ap.add_argument('--only', default='', help='cases whose name contains this')
    ap.add_argument('--tol', type=float, default=1e-4)
    ap.add_argument('--no-brain', action='store_true')
    ap.add_argument('--jobs', type=int, default=2, help='simdvol runs at once')
    ap.add_argument('--fragile', type=int, default=16,
                    help='most pixels of an image allowed over --tol, each explained by a nudge')
    ap.add_argument('--nudge', type=float, default=1e-6, help='voxels (0: no fragile pixels)')
    ap.add_argument('--list', action='store_true', help='list the cases and exit')
    # rival conventions
    ap.add_argument('--depth', default='sphere', choices=['faces', 'sphere'])
    ap.add_argument('--zphase', default='code', choices=['code', 'half', 'int'])
    ap.add_argument('--igrid', default='code', choices=['code', 'aligned'])
    ap.add_argument('--no-clamp', action='store_true')
    ap.add_argument('--at-mean', default='upper', choices=['upper', 'lower'])
    ap.add_argument('--rotation', default='eq5.2',
                    choices=['eq5.2', 'inverse', 'neg-angles', 'reversed'])
    ap.add_argument('--order2', default='centred',
                    choices=['centred', 'centred-strict', 'far', 'low', 'high'])
    ap.add_argument('--sample-clamp', default='premult',
                    choices=['premult', 'none', 'alpha', 'unit'])
    ap.add_argument('--spacing-unit', default='smallest', choices=['smallest', 'largest'])
    ap.add_argument('--grad-scale', default='physical', choices=['physical', 'index'])
    ap.add_argument('--ramp-ends', default='held', choices=['held', 'zero'])
    ap.add_argument('--positions', default='grid', choices=['grid', 'float'],
                    help='float: our samples in float64 instead of on the 32.32 grid')
    ap.add_argument('--tie-frac', default='float32', choices=['float32', 'exact'],
                    help='exact: decide the half-voxel ties on the exact fraction')
    # adaptive and Monte Carlo: tolerances
    ap.add_argument('--thr-nudge', type=float, default=1e-6,
                    help='adaptive: a pixel over --tol is fragile if the threshold +- this '
                    'explains it')
    ap.add_argument('--mc-tol', type=float, default=1e-5)
    ap.add_argument('--mc-eps', type=float, default=2e-6,
                    help='a walk\'s comparison within this is a near tie')
    ap.add_argument('--mc-fragile', type=int, default=8,
                    help='most pixels of an MC image over --mc-tol, each explained by a near tie')
    ap.add_argument('--zmax', type=float, default=4.0, help='statistics: largest |z| allowed')
    # adaptive and Monte Carlo: rival conventions
    ap.add_argument('--weight-frac', default='float32', choices=['float32', 'exact'],
                    help='adaptive, mc: the fraction in the interpolation weights')
    ap.add_argument('--tiny-alphas', default='float32', choices=['float32', 'plain'],
                    help='adaptive, mc: voxel alphas below 2^-126 and the opacity step')
    ap.add_argument('--adaptive-stop', default='levoy', choices=['levoy', 'early', 'late'])
    ap.add_argument('--adaptive-compare', default='float32', choices=['float32', 'float64'])
    ap.add_argument('--mc-u', default='top24', choices=['top24', 'low24'])
    ap.add_argument('--mc-counter', default='rqs', choices=['rqs', 'swap'])
    ap.add_argument('--mc-simd', default='0x73696d64', help='the counter\'s fourth word')
    ap.add_argument('--mc-key', default='lohi', choices=['lohi', 'swap'])
    ap.add_argument('--mc-ray', default='row', choices=['row', 'col'])
    ap.add_argument('--mc-shared-key', default='0xffffffff')
    ap.add_argument('--mc-depth', default='absolute', choices=['absolute', 'opaque'])
    ap.add_argument('--mc-exact-depth', default='opaque', choices=['opaque', 'zero'])
    ap.add_argument('--mc-colour', default='unpremult', choices=['unpremult', 'premult'])
    ap.add_argument('--mc-fallback', default='pick', choices=['pick', 'none'])
    ap.add_argument('--mc-strata', default='alpha', choices=['alpha', 'unscaled'])
    ap.add_argument('--mc-expect', default='over',
                    choices=['over', 'eq7.12', 'drop-last', 'premult', 'ge'])
    ap.add_argument('--mc-var', default='exact', choices=['exact', 'walks2x'])
    o = ap.parse_args()
    SIMDVOL, DATA = o.simdvol, o.data
    WORK = o.work or tempfile.mkdtemp(prefix='simdvol-indep.')
    try:
        return run(o)
    finally:
        if not o.work:
            shutil.rmtree(WORK, ignore_errors=True)


def render_mine(vol, case, conv, nudge=None, threshold=None):
    shade = SHADINGS[case.shading][0]
    mix = ir.load_classifier(vol.cls[case.cls])
    size = case.size or vol.face
    if case.comp.mode == 'direct':
        return ir.render(vol.data, mix, view=case.view, size=size, order=case.order,
                         shade=shade, conv=conv, sampling=case.sampling, spacing=vol.spacing,
                         fit=case.fit, nudge=nudge)
    g, smp = ir.render_samples(vol.data, mix, view=case.view, size=size, order=case.order,
                               shade=shade, conv=dataclasses.replace(conv, weight_frac=WEIGHT_FRAC,
                                                         tiny_alphas=TINY_ALPHAS),
                               sampling=case.sampling,
                               spacing=vol.spacing, fit=case.fit, nudge=nudge)
    if case.comp.mode == 'adaptive':
        t = case.comp.threshold if threshold is None else threshold
        return ir.finish(g, ir.composite_adaptive(smp, t, ADAPTIVE_STOP, ADAPTIVE_COMPARE), size)
    return g, smp


ADAPTIVE_STOP, ADAPTIVE_COMPARE = 'levoy', 'float32'
WEIGHT_FRAC, TINY_ALPHAS = 'float32', 'float32'


def judge(o, mine, img, vol, case, conv, nudged):
    """(max|diff|, PSNR, pixels over tol, of which fragile, ok)."""
    md, p = metrics(mine, img)
    over = np.abs(mine.astype(np.float64) - img).max(-1) > o.tol
    n_over = int(over.sum())
    if n_over == 0:
        return md, p, 0, 0, True
    if o.nudge > 0:
        if not nudged:
            for sx in (-1, 1):
                for sy in (-1, 1):
                    for sz in (-1, 1):
                        nudged.append(render_mine(vol, case, conv,
                                                  (sx * o.nudge, sy * o.nudge, sz * o.nudge)))
            if case.comp.mode == 'adaptive' and o.thr_nudge > 0:
                for d in (-o.thr_nudge, o.thr_nudge):
                    nudged.append(render_mine(vol, case, conv, threshold=case.comp.threshold + d))
        ok_px = np.zeros_like(over)
        for alt in nudged:
            ok_px |= np.abs(alt - img).max(-1) <= o.tol
        fragile = int((over & ok_px).sum())
    else:
        fragile = 0
    return md, p, n_over, fragile, fragile == n_over and n_over <= o.fragile


@dataclass
class McMine:
    """Our whole-ray Monte Carlo of a case: the geometry, the rays' samples
    [D, R, 4], the estimate (ir.McResult), its output image."""
    g: object
    smp: np.ndarray
    res: object
    img: np.ndarray
    size: tuple
    p: object


def mc_mine(vol, case, conv, mcc, eps):
    g, smp = render_mine(vol, case, conv)
    D, Hi, Wi = smp.shape[:3]
    p = case.comp.params()
    flat = smp.reshape(D, Hi * Wi, 4)
    size = case.size or vol.face
    if case.comp.scope != 'whole':
        return McMine(g, flat, None, None, size, p)
    res = ir.mc_composite(flat, p, ir.mc_keys((Hi, Wi), p, mcc), mcc, eps)
    img = ir.finish(g, res.est.reshape(Hi, Wi, 4).astype(np.float64), size)
    return McMine(g, flat, res, img, size, p)


def _footprint(mm, ys, xs):
    """The rays (flat intermediate indices) that the output pixels (ys, xs)
    are made of."""
    Hi, Wi = len(mm.g.cy), len(mm.g.cx)
    if mm.g.sampling == 'pixel':
        return set((ys * Wi + xs).tolist())
    W, H = mm.size
    fx = (ir.centred(W) / mm.g.scale - mm.g.xs[0]) / (mm.g.xs[1] - mm.g.xs[0])
    fy = (ir.centred(H) / mm.g.scale - mm.g.ys[0]) / (mm.g.ys[1] - mm.g.ys[0])
    out = set()
    for y, x in zip(ys, xs):
        x0, y0 = int(math.floor(fx[x])), int(math.floor(fy[y]))
        for j in (y0, y0 + 1):
            for i in (x0, x0 + 1):
                if 0 <= j < Hi and 0 <= i < Wi:
                    out.add(j * Wi + i)
    return out


def judge_mc(o, mm, img):
    """Exact reproduction of a whole-ray Monte Carlo image: (max|diff|,
    PSNR, pixels over --mc-tol, of which explained by near ties, ok).  A
    pixel over --mc-tol is explained if taking the other outcome of one or
    two of its rays' near ties (ir.mc_composite's alts) brings it within."""
    md, p = metrics(mm.img.astype(np.float32), img)
    over = np.abs(mm.img - img).max(-1) > o.mc_tol
    n_over = int(over.sum())
    if n_over == 0:
        return md, p, 0, 0, True
    ys, xs = np.nonzero(over)
    rays = _footprint(mm, ys, xs)
    res, Hi, Wi = mm.res, len(mm.g.cy), len(mm.g.cx)
    n = mm.p.samples
    deltas = []
    for r, m, other in res.alts:
        if r not in rays:
            continue
        picks, fb = res.picks[r].copy(), res.fallback[r]
        if m == n:
            fb = other
        else:
            picks[m] = other
        est = ir.mc_estimate(picks, fb, res.col[:, r], res.acc[r], mm.p)
        d = np.zeros((Hi * Wi, 4))
        d[r] = est.astype(np.float64) - res.est[r]
        deltas.append(ir.finish(mm.g, d.reshape(Hi, Wi, 4), mm.size))
    for r, est in res.ray_alts:
        if r in rays:
            d = np.zeros((Hi * Wi, 4))
            d[r] = est.astype(np.float64) - res.est[r]
            deltas.append(ir.finish(mm.g, d.reshape(Hi, Wi, 4), mm.size))
    fragile = 0
    for y, x in zip(ys, xs):
        cand = [d[y, x] for d in deltas if np.any(d[y, x] != 0)]
        tries = [[c] for c in cand] + [[a, b] for i, a in enumerate(cand) for b in cand[i + 1:]]
        if any(np.abs(mm.img[y, x] + sum(t) - img[y, x]).max() <= o.mc_tol for t in tries):
            fragile += 1
    return md, p, n_over, fragile, fragile == n_over and n_over <= o.mc_fragile


def stat_whole(o, mm, img):
    """z-scores of a whole-ray, per-ray-stream Monte Carlo image against its
    exact distribution (ir.mc_moments), per channel R, G, B, A: the summed
    error over the pixels against its standard deviation (mean), the summed
    squared error against its expectation and standard deviation (mse).
    None where a pixel is not one ray."""
    pick = ir.warp_is_pick(mm.g, mm.size)
    if pick is None or mm.p.streams != 'per-ray':
        return None
    Wi = len(mm.g.cx)
    mean, var, e4 = ir.mc_moments(mm.smp, mm.p, MC_EXPECT, MC_VAR)
    J, I = np.meshgrid(pick[0], pick[1], indexing='ij')
    idx = (J * Wi + I).reshape(-1)
    e = img.reshape(-1, 4).astype(np.float64) - mean[idx]
    v, f = var[idx], e4[idx]
    return zscores(e, v, f)


def zscores(e, v, f):
    zm, zs = [], []
    for c in range(4):
        V = v[:, c].sum()
        if V < 1e-12:
            # no randomness (exact opacity's alpha): the estimate is exact
            bad = np.abs(e[:, c]).max() > 1e-5
            zm.append(math.inf if bad else 0.0)
            zs.append(math.inf if bad else 0.0)
            continue
        zm.append(e[:, c].sum() / math.sqrt(V))
        VV = (f[:, c] - v[:, c] ** 2).sum()
        zs.append(((e[:, c] ** 2).sum() - V) / math.sqrt(max(VV, 1e-300)))
    return zm, zs


def stat_two_seeds(o, mm, x1, x2):
    """Per sub-ray Monte Carlo at pixel sampling: its expectation is the
    direct image (see the docstring); two images of independent seeds give
    per channel z = sum(x1 + x2 - 2 mu) / sqrt(sum (x1 - x2)^2)."""
    if mm.g.sampling != 'pixel':
        return None, None
    mean = ir.mc_moments(mm.smp, ir.McParams(mm.p.samples), MC_EXPECT)[0]
    a, b = (x.reshape(-1, 4).astype(np.float64) for x in (x1, x2))
    zm = []
    for c in range(4):
        Q = ((a[:, c] - b[:, c]) ** 2).sum()
        S = (a[:, c] + b[:, c] - 2 * mean[:, c]).sum()
        if Q < 1e-12:
            bad = max(np.abs(x[:, c] - mean[:, c]).max() for x in (a, b)) > 1e-5
            zm.append(math.inf if bad else 0.0)
        else:
            zm.append(S / math.sqrt(Q))
    return (zm, None), mean.reshape(x1.shape)


MC_EXPECT, MC_VAR = 'over', 'exact'


def fmt_z(z):
    return '[' + ' '.join('%+.2f' % x for x in z) + ']'


def run(o):
    global ADAPTIVE_STOP, ADAPTIVE_COMPARE, WEIGHT_FRAC, TINY_ALPHAS, MC_EXPECT, MC_VAR
    ir.AT_MEAN = o.at_mean
    ir.philox_selftest()
    conv = ir.Conventions(depth=o.depth, clamp_colour=not o.no_clamp, zphase=o.zphase,
                          igrid=o.igrid, rotation=o.rotation, order2=o.order2,
                          sample_clamp=o.sample_clamp, spacing_unit=o.spacing_unit,
                          grad_scale=o.grad_scale, positions=o.positions,
                          ramp_ends=o.ramp_ends, tie_frac=o.tie_frac)
    mcc = ir.McConventions(u=o.mc_u, counter=o.mc_counter, simd=int(o.mc_simd, 0),
                           key=o.mc_key, ray=o.mc_ray, shared_key=int(o.mc_shared_key, 0),
                           depth=o.mc_depth, exact_depth=o.mc_exact_depth,
                           colour=o.mc_colour, fallback=o.mc_fallback, strata=o.mc_strata)
    ADAPTIVE_STOP, MC_EXPECT, MC_VAR = o.adaptive_stop, o.mc_expect, o.mc_var
    ADAPTIVE_COMPARE = o.adaptive_compare
    WEIGHT_FRAC, TINY_ALPHAS = o.weight_frac, o.tiny_alphas
    engines = o.engines.split(',')
    vols = write_inputs()
    if o.no_brain:
        vols.pop('brain', None)
    todo = []
    for case in cases(o.quick):
        if case.vol not in vols:
            continue
        name = case.name(vols)
        if o.only and o.only not in name:
            continue
        todo.append((case, name))
    if o.list:
        for case, name in todo:
            print('%-14s %s' % (case.group, name))
        print('%d cases' % len(todo))
        return 0
    t0 = time.time()
    pool = ThreadPoolExecutor(max_workers=max(1, o.jobs))
    futures = []
    for n, (case, name) in enumerate(todo):
        vol = vols[case.vol]
        size = case.size or vol.face
        sargs = SHADINGS[case.shading][1]
        args = vol.args + ['--classify', vol.cls[case.cls],
                           '--view', ','.join(repr(float(a)) for a in case.view),
                           '--order', str(case.order), '--size', '%dx%d' % size,
                           '--sampling', case.sampling, '--fit', case.fit] + sargs
        # per sub-ray Monte Carlo: two seeds
        seeds = [None] if case.comp.scope == 'whole' else [case.comp.seed, case.comp.seed + 1]
        futures.append([[pool.submit(run_simdvol, args + case.comp.args(sd),
                                     os.path.join(WORK, 'c%03d_%s%s.tif' % (n, e, '' if sd is None
                                                                          else '_%d' % i)), e)
                         for i, sd in enumerate(seeds)] for e in engines])
    failed, groups = 0, {}
    print('%-60s %-9s %10s %8s %s' % ('case', 'engine', 'max|diff|', 'PSNR dB', 'over tol'))
    for (case, name), futs in zip(todo, futures):
        vol = vols[case.vol]
        mm = None
        if case.comp.mode == 'mc':
            mm = mc_mine(vol, case, conv, mcc, o.mc_eps)
        else:
            mine = render_mine(vol, case, conv).astype(np.float32)
        nudged = []
        for e, fs in zip(engines, futs):
            imgs = [f.result() for f in fs]
            img = imgs[0]
            g = groups.setdefault((case.group, e), [0.0, math.inf, 0, 0, 0.0, 0.0])
            note, ok, zs = '', True, None
            if mm is None or mm.res is not None:
                if mm is None:
                    md, p, n_over, fragile, ok = judge(o, mine, img, vol, case, conv, nudged)
                    tol = o.tol
                else:
                    md, p, n_over, fragile, ok = judge_mc(o, mm, img)
                    tol = o.mc_tol
                    zs = stat_whole(o, mm, img)
                g[0], g[1] = max(g[0], md), min(g[1], p)
                g[3] += fragile
                if n_over:
                    note = '%d px (%d fragile)' % (n_over, fragile)
                if not ok:
                    note += '  <-- FAIL (tol %g)' % tol
            else:
                # (the first seed's image against the expectation: its noise)
                zs, mu = stat_two_seeds(o, mm, imgs[0], imgs[1])
                md, p = metrics(mu.astype(np.float32), img)
            g[2] += 1
            if zs is not None:
                zm, zq = zs
                note += ' z ' + fmt_z(zm)
                g[4] = max(g[4], max(abs(z) for z in zm))
                if zq is not None:
                    note += ' zsq ' + fmt_z(zq)
                    g[5] = max(g[5], max(abs(z) for z in zq))
                if max(abs(z) for z in zm + (zq or [])) > o.zmax:
                    ok = False
                    note += '  <-- FAIL (|z| > %g)' % o.zmax
            if not ok:
                failed += 1
            print('%-60s %-9s %10.3g %8.2f %s' % (name, e, md, p, note.strip()), flush=True)
    pool.shutdown()
    print()
    print('%-15s %-9s %5s %10s %9s %s' % ('group', 'engine', 'cases', 'max|diff|', 'min PSNR',
                                         'fragile px'))
    for (grp, e), (md, p, n, fr, zm, zq) in groups.items():
        if grp == 'mc-subray':     # statistics alone
            line = '%-15s %-9s %5d %10s %9s %s' % (grp, e, n, '-', '-', '-')
        else:
            line = '%-15s %-9s %5d %10.3g %9.2f %d' % (grp, e, n, md, p, fr)
        if zm or zq:
            line += '   max |z| mean %.2f, mse %.2f' % (zm, zq)
        print(line)
    nimg = sum(len(f) for fs in futures for f in fs)
    print('%d images, %d failed; %.1f s' % (nimg, failed, time.time() - t0))
    return 0 if failed == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
