#!/usr/bin/python3
"""Independent check of simdvol's images against indep_render.py.

usage: python3 run_cases.py --simdvol PATH [--work DIR] [--data DIR] [--quick]
       [--engines reference,opencl] [--depth faces|sphere]
       [--zphase code|half|int] [--igrid code|aligned] [--no-clamp]
       [--at-mean upper|lower] [--only SUBSTRING] [--tol 1e-4] [--no-brain]
Writes volumes, classifier files and images under --work (default: a
temporary directory, removed after); uses brainsmall.den from --data
(default $SIMDVOL_DATA_DIR, else the repository's data/) where it is there,
and fails without it when SIMDVOL_REQUIRE_DATA=1. Exit 1 if a case is over
--tol. The test simdvol_independent_check runs --quick (about 30 s).
"""
import argparse
import math
import os
import shutil
import subprocess
import sys
import tempfile

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

MAT_BRAIN = """relative
material background 0.0  0.05  0 0 0       0
material csf        0.15 0.05  0.3 0.4 0.8 0.004
material grey       0.45 0.07  0.8 0.6 0.55 0.02
material white      0.6  0.06  0.95 0.9 0.85 0.04
material skin       0.85 0.1   1 0.8 0.65  0.2
"""


def load_den(path):
    b = open(path, 'rb').read()
    nx, ny, nz = np.frombuffer(b[50:56], '<i2')
    return np.frombuffer(b[62:], np.uint8).reshape(nz, ny, nx)


# --------------------------------------------------------------- cases
def write_inputs():
    os.makedirs(WORK, exist_ok=True)
    a, b = vol_a(), vol_b()
    a.tofile(os.path.join(WORK, 'a.raw'))
    b.astype('<i2').tofile(os.path.join(WORK, 'b.raw'))
    for name, text in (('a.mat', MAT_A), ('b.mat', MAT_B), ('brain.mat', MAT_BRAIN)):
        open(os.path.join(WORK, name), 'w').write(text)
    vols = {
        'a': (a, [os.path.join(WORK, 'a.raw'), '--raw-dims', '32,32,32', '--raw-type', 'u8'],
              os.path.join(WORK, 'a.mat'), (32, 32)),
        'b': (b, [os.path.join(WORK, 'b.raw'), '--raw-dims', '48,40,36', '--raw-type', 'i16'],
              os.path.join(WORK, 'b.mat'), (48, 48)),
    }
    den = os.path.join(DATA, 'brainsmall.den')
    if os.path.exists(den):
        vols['brain'] = (load_den(den), [den], os.path.join(WORK, 'brain.mat'), (128, 128))
    elif os.environ.get('SIMDVOL_REQUIRE_DATA') == '1':
        raise SystemExit('run_cases.py: %s missing (scripts/fetch-data) and SIMDVOL_REQUIRE_DATA=1'
                         % den)
    return vols


AXIS_VIEWS = [(0, 0, 0), (0, 90, 0), (0, 180, 0), (0, -90, 0), (0, 0, 90), (0, 0, -90),
              (90, 0, 0), (0, 90, 90)]

SHADINGS = {
    'noshade': (ir.Shade(enabled=False), ['--no-shade']),
    'phong': (ir.Shade(), []),
    'phong2': (ir.Shade(light=(0.3, -0.2, -1.0), ka=0.1, kd=0.6, ks=0.5, n=8, k1=1.0, k2=1.5),
               ['--light', '0.3,-0.2,-1', '--phong', '0.1,0.6,0.5,8', '--depth-cue', '1,1.5']),
    'phong-nocue': (ir.Shade(k1=1.0, k2=0.0), ['--depth-cue', '1,0']),
}


# (The first of each is what --quick takes: 64x48 on 32^3 has an
# intermediate image of odd width, 45, so its rays lie off the voxel grid.)
SCALED = {'a': [(64, 48), (64, 64), (80, 80), (45, 45)], 'b': [(72, 72), (60, 50)]}
PIXEL = {'a': [(64, 64), (48, 48)], 'b': [(72, 60)]}


def cases(quick):
    """(volume, view, order, shading, size or None, sampling)"""
    for v in ('a', 'b'):
        views = AXIS_VIEWS if not quick else AXIS_VIEWS[:3]
        for view in views:
            for order in (0, 1):
                for sh in (SHADINGS if not quick else ('noshade', 'phong')):
                    yield v, view, order, sh, None, 'voxel'
    for view in ((0, 0, 0), (0, 90, 0)):
        for sh in ('noshade', 'phong'):
            yield 'brain', view, 1, sh, None, 'voxel'
    for sampling, sizes in (('voxel', SCALED), ('pixel', PIXEL)):
        for v in ('a', 'b'):
            for size in sizes[v][:1 if quick else None]:
                for view in ((0, 0, 0), (0, 90, 0), (0, 180, 0))[:1 if quick else None]:
                    for order in (0, 1):
                        for sh in ('noshade', 'phong'):
                            yield v, view, order, sh, size, sampling


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
    ap.add_argument('--depth', default='sphere', choices=['faces', 'sphere'])
    ap.add_argument('--zphase', default='code', choices=['code', 'half', 'int'])
    ap.add_argument('--igrid', default='code', choices=['code', 'aligned'])
    ap.add_argument('--no-clamp', action='store_true')
    ap.add_argument('--at-mean', default='upper', choices=['upper', 'lower'])
    ap.add_argument('--only', default='')
    ap.add_argument('--tol', type=float, default=1e-4)
    ap.add_argument('--no-brain', action='store_true')
    o = ap.parse_args()
    SIMDVOL, DATA = o.simdvol, o.data
    WORK = o.work or tempfile.mkdtemp(prefix='simdvol-indep.')
    try:
        return run(o)
    finally:
        if not o.work:
            shutil.rmtree(WORK, ignore_errors=True)


def run(o):
    ir.AT_MEAN = o.at_mean
    conv = ir.Conventions(depth=o.depth, clamp_colour=not o.no_clamp, zphase=o.zphase, igrid=o.igrid)
    engines = o.engines.split(',')
    vols = write_inputs()
    if o.no_brain:
        vols.pop('brain', None)
    worst = 0.0
    print('%-52s %-9s %12s %8s' % ('case', 'engine', 'max|diff|', 'PSNR dB'))
    for v, view, order, sh, size, sampling in cases(o.quick):
        if v not in vols:
            continue
        vol, vargs, mat, face = vols[v]
        size = size or face
        name = '%s view=%s order=%d %s' % (v, ','.join(map(str, view)), order, sh)
        if size != face or sampling != 'voxel':
            name += ' %dx%d %s' % (size + (sampling,))
        if o.only and o.only not in name:
            continue
        shade, sargs = SHADINGS[sh]
        mine = ir.render(vol, ir.load_materials(mat), view=view, size=size, order=order,
                         shade=shade, conv=conv, sampling=sampling).astype(np.float32)
        args = vargs + ['--classify', mat, '--view', '%d,%d,%d' % view, '--order', str(order),
                        '--size', '%dx%d' % size, '--sampling', sampling] + sargs
        for e in engines:
            out = os.path.join(WORK, '%s_%s_o%d_%s_%dx%d_%s_%s.tif' % (
                v, '_'.join(map(str, view)), order, sh, size[0], size[1], sampling, e))
            img = run_simdvol(args, out, e)
            md, p = metrics(mine, img)
            worst = max(worst, md)
            flag = '' if md <= o.tol else '  <-- over %g' % o.tol
            print('%-52s %-9s %12.3g %8.2f%s' % (name, e, md, p, flag), flush=True)
    print('worst max|diff| %.3g' % worst)
    return 0 if worst <= o.tol else 1


if __name__ == '__main__':
    sys.exit(main())
