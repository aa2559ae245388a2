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
Writes volumes, classifier files and images under --work (default: a
temporary directory, removed after); uses brainsmall.den from --data
(default $SIMDVOL_DATA_DIR, else the repository's data/) where it is there,
and fails without it when SIMDVOL_REQUIRE_DATA=1.  Exit 1 if a case fails.

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
"""
import argparse
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

# README "Transfer-function files": VolPack's example, verbatim
TF_BRAIN = """# VolPack's example: opacity = density ramp x gradient ramp, white
density  0 0   24 1   255 1
gradient 0 0   5 0   20 1   221 1
color    0 1 1 1
"""

SPACING_C = (0.8, 1.0, 1.6)


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
                       ('c.tf', TF_C), ('brain.mat', MAT_BRAIN), ('brain.tf', TF_BRAIN)):
        open(os.path.join(WORK, name), 'w').write(text)
    w = lambda n: os.path.join(WORK, n)  # noqa: E731
    raw = lambda n, d, t: [w(n), '--raw-dims', d, '--raw-type', t]  # noqa: E731
    vols = {
        'a': Vol(a, raw('a.raw', '32,32,32', 'u8'), {'mat': w('a.mat'), 'tf': w('a.tf')}, (32, 32)),
        'b': Vol(b, raw('b.raw', '48,40,36', 'i16'), {'mat': w('b.mat')}, (48, 48)),
        'c': Vol(c, raw('c.raw', '40,30,24', 'u16') + ['--raw-spacing', '%g,%g,%g' % SPACING_C],
                 {'mat': w('c.mat'), 'tf': w('c.tf')}, (48, 48), SPACING_C),
        # the same voxels, spacing the other way round (largest along x)
        'c2': Vol(c, raw('c.raw', '40,30,24', 'u16') + ['--raw-spacing', '2,1,1.25'],
                  {'mat': w('c.mat')}, (64, 64), (2.0, 1.0, 1.25)),
    }
    den = os.path.join(DATA, 'brainsmall.den')
    if os.path.exists(den):
        vols['brain'] = Vol(load_den(den), [den], {'mat': w('brain.mat'), 'tf': w('brain.tf')},
                            (128, 128))
    elif os.environ.get('SIMDVOL_REQUIRE_DATA') == '1':
        raise SystemExit('run_cases.py: %s missing (scripts/fetch-data) and SIMDVOL_REQUIRE_DATA=1'
                         % den)
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

    def name(self, vols):
        s = '%s view=%s order=%d %s' % (self.vol, ','.join('%.6g' % a for a in self.view),
                                         self.order, self.shading)
        if self.cls != 'mat':
            s += ' ' + self.cls
        if (self.size and self.size != vols[self.vol].face) or self.sampling != 'voxel':
            s += ' %dx%d %s' % (self.size + (self.sampling,))
        if self.fit != 'longest':
            s += ' fit=' + self.fit
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
    o = ap.parse_args()
    SIMDVOL, DATA = o.simdvol, o.data
    WORK = o.work or tempfile.mkdtemp(prefix='simdvol-indep.')
    try:
        return run(o)
    finally:
        if not o.work:
            shutil.rmtree(WORK, ignore_errors=True)


def render_mine(vol, case, conv, nudge=None):
    shade = SHADINGS[case.shading][0]
    return ir.render(vol.data, ir.load_classifier(vol.cls[case.cls]), view=case.view,
                     size=case.size or vol.face, order=case.order, shade=shade, conv=conv,
                     sampling=case.sampling, spacing=vol.spacing, fit=case.fit, nudge=nudge)


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
        ok_px = np.zeros_like(over)
        for alt in nudged:
            ok_px |= np.abs(alt - img).max(-1) <= o.tol
        fragile = int((over & ok_px).sum())
    else:
        fragile = 0
    return md, p, n_over, fragile, fragile == n_over and n_over <= o.fragile


def run(o):
    ir.AT_MEAN = o.at_mean
    conv = ir.Conventions(depth=o.depth, clamp_colour=not o.no_clamp, zphase=o.zphase,
                          igrid=o.igrid, rotation=o.rotation, order2=o.order2,
                          sample_clamp=o.sample_clamp, spacing_unit=o.spacing_unit,
                          grad_scale=o.grad_scale, positions=o.positions,
                          ramp_ends=o.ramp_ends, tie_frac=o.tie_frac)
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
        futures.append([pool.submit(run_simdvol, args,
                                    os.path.join(WORK, 'c%03d_%s.tif' % (n, e)), e)
                        for e in engines])
    failed, groups = 0, {}
    print('%-60s %-9s %10s %8s %s' % ('case', 'engine', 'max|diff|', 'PSNR dB', 'over tol'))
    for (case, name), futs in zip(todo, futures):
        vol = vols[case.vol]
        mine = render_mine(vol, case, conv).astype(np.float32)
        nudged = []
        for e, fut in zip(engines, futs):
            img = fut.result()
            md, p, n_over, fragile, ok = judge(o, mine, img, vol, case, conv, nudged)
            g = groups.setdefault((case.group, e), [0.0, math.inf, 0, 0])
            g[0], g[1], g[2] = max(g[0], md), min(g[1], p), g[2] + 1
            g[3] += fragile
            note = ''
            if n_over:
                note = '%d px (%d fragile)' % (n_over, fragile)
            if not ok:
                failed += 1
                note += '  <-- FAIL (tol %g)' % o.tol
            print('%-60s %-9s %10.3g %8.2f %s' % (name, e, md, p, note), flush=True)
    pool.shutdown()
    print()
    print('%-15s %-9s %5s %10s %9s %s' % ('group', 'engine', 'cases', 'max|diff|', 'min PSNR',
                                         'fragile px'))
    for (grp, e), (md, p, n, fr) in groups.items():
        print('%-15s %-9s %5d %10.3g %9.2f %d' % (grp, e, n, md, p, fr))
    print('%d images, %d failed; %.1f s' % (len(todo) * len(engines), failed, time.time() - t0))
    return 0 if failed == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
