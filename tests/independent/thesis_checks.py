#!/usr/bin/python3
"""Two computations apart from simdvol behind docs/HARDENING.md's "The
mathematics against the thesis (2026-12-07, thirtieth session)"; run by hand, not by
ctest (minutes on a busy machine).

usage: python3 thesis_checks.py section
       python3 thesis_checks.py mc --simdvol PATH [--seeds 200] [--engine reference|opencl]
       python3 thesis_checks.py walks --simdvol PATH [--seeds 8] [--walks 65536] [--engine ...]

section: thesis ch. 6.2 says a box a x b x c has no plane section larger
than S = (a^2 + b^2 + c^2) / 2 and takes S for what a PE holds. The
largest section found by a random search over planes (then refined) is
printed against S, and so is the box's largest orthographic projection,
sqrt(a^2 b^2 + b^2 c^2 + c^2 a^2), which is what a PE's footprint is.

mc: the Monte Carlo estimators (eq 7.3 / 7.12 / 7.13, exact opacity and
stratified picks, ch. 7.5) are unbiased: the mean over --seeds images of a
32^3 phantom (24 x 24, pixel sampling, view 20,35,10, 4 walks) against
direct compositing, per pixel and channel z = (mean - direct) / (sd /
sqrt(seeds)) where sd > 1e-6 * sqrt(seeds) (elsewhere the estimate is
deterministic up to float rounding, or, plain walks, a pixel so faint
that no walk of any seed stopped in it: its difference is printed
instead), and the z of the image's RGB sum.

walks: the same images with many walks per ray (--walks) from a few seeds
(--seeds): e_s = image_s - direct. Without bias the seeds' errors are
independent with mean 0, so per channel the cross product z = sum_{s<t}
sum_px e_s e_t / sqrt(sum (e_s e_t)^2) has mean 0; a bias b per pixel
adds sum b^2 to its numerator. Printed with the rms bias it excludes
(z + 2 of its standard errors) and the z of the sum sum_s sum_px e_s.
Per-ray streams only: with --streams shared every ray draws the same
numbers, so the pixels' errors are not independent (mc covers it).
"""
import argparse
import itertools
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tiffread import read_tiff  # noqa: E402


def section_area(dims, n, d):
    box = np.array(list(itertools.product(*[(0.0, x) for x in dims])))
    s = box @ n - d
    pts = []
    for i in range(8):
        for j in range(i + 1, 8):
            if np.sum(box[i] != box[j]) == 1 and s[i] * s[j] < 0:
                pts.append(box[i] + s[i] / (s[i] - s[j]) * (box[j] - box[i]))
    if len(pts) < 3:
        return 0.0
    p = np.array(pts) - np.mean(pts, 0)
    u = np.cross(n, [1, 0, 0] if abs(n[0]) < 0.9 else [0, 1, 0])
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    x, y = p @ u, p @ w
    o = np.argsort(np.arctan2(y, x))
    x, y = x[o], y[o]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def largest_section(dims, rng, tries=1500, refine=1500):
    a = np.array(dims, float)
    best = (0.0, None, None)
    for _ in range(tries):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        lo, hi = (a * (n < 0)) @ n, (a * (n > 0)) @ n
        for d in np.linspace(lo, hi, 9)[1:-1]:
            ar = section_area(a, n, d)
            if ar > best[0]:
                best = (ar, n, d)
    ar, bn, bd = best
    step = 0.05
    for _ in range(refine):
        n = bn + step * rng.normal(size=3)
        n /= np.linalg.norm(n)
        d = bd + step * a.max() * rng.normal()
        t = section_area(a, n, d)
        if t > ar:
            ar, bn, bd = t, n, d
        else:
            step *= 0.998
    return ar


def section():
    rng = np.random.default_rng(1)
    for dims in [(1, 1, 1), (8, 16, 16), (4, 8, 6), (1, 2, 3), (2, 3, 3), (1, 1, 1.2)]:
        a, b, c = dims
        s = 0.5 * (a * a + b * b + c * c)
        shadow = np.sqrt(a * a * b * b + b * b * c * c + c * c * a * a)
        m = largest_section(dims, rng)
        print(f"box {dims}: largest section {m:.4f} = {m / s:.4f} S; largest projection "
              f"{shadow:.4f} = {shadow / s:.4f} S")


VARIANTS = {
    'whole, plain': [],
    'whole, shared streams': ['--streams', 'shared'],
    'whole, exact opacity': ['--exact-opacity'],
    'whole, exact + stratified': ['--exact-opacity', '--mc-stratified'],
    'sub-ray, plain': ['--mc-scope', 'subray'],
    'sub-ray, exact + allocate': ['--mc-scope', 'subray', '--exact-opacity', '--allocate'],
}


def renderer(args, tmp):
    """render(extra): the 32^3 phantom to 24x24 at (20, 35, 10) with args.engine (64 PEs
    for opencl, and for the reference's per sub-ray Monte Carlo) and the options extra, as
    float64 RGBA."""
    base = ['render', '--phantom-size', '32', '--size', '24x24', '--sampling', 'pixel',
            '--view', '20,35,10', '--engine', args.engine]
    if args.engine == 'opencl':
        base += ['--pe', '64']
    out = os.path.join(tmp, 'v.tif')

    def render(extra):
        if '--mc-scope' in extra and args.engine == 'reference':
            extra = extra + ['--pe', '64']  # the reference cuts the rays at 64 PE cells too
        subprocess.run([args.simdvol] + base + extra + ['-o', out], check=True,
                       stdout=subprocess.DEVNULL)
        return read_tiff(out).astype(np.float64)

    return render


def mc(args):
    with tempfile.TemporaryDirectory() as tmp:
        render = renderer(args, tmp)
        direct = render(['--composite', 'direct'])
        for name, extra in VARIANTS.items():
            imgs = np.stack([render(['--composite', 'mc', '--samples', '4', '--seed',
                                     str(9000 + s)] + extra) for s in range(args.seeds)])
            n = args.seeds
            mean, sd = imgs.mean(0), imgs.std(0, ddof=1)
            big = sd > 1e-6 * np.sqrt(n)
            z = (mean[big] - direct[big]) / (sd[big] / np.sqrt(n))
            sums = imgs[..., :3].reshape(n, -1).sum(1)
            zs = (sums.mean() - direct[..., :3].sum()) / (sums.std(ddof=1) / np.sqrt(n))
            rest = np.abs(mean[~big] - direct[~big]).max() if (~big).any() else 0.0
            print(f"{name:28s} {n} seeds: RGB-sum z {zs:+.2f}; {big.sum()} pixel-channels: "
                  f"mean z^2 {np.mean(z ** 2):.3f}, max |z| {np.abs(z).max():.2f}; "
                  f"the others' largest |mean - direct| {rest:.1e}", flush=True)


def walks(args):
    with tempfile.TemporaryDirectory() as tmp:
        render = renderer(args, tmp)
        direct = render(['--composite', 'direct'])
        for name, extra in VARIANTS.items():
            if '--streams' in extra:
                continue  # one stream for every ray: the pixels' errors are not independent
            e = np.stack([render(['--composite', 'mc', '--samples', str(args.walks), '--seed',
                                  str(777 + s)] + extra) - direct for s in range(args.seeds)])
            k = args.seeds
            line = []
            for c in range(4):
                num = den = q = 0.0
                for s in range(k):
                    for t in range(s + 1, k):
                        p = e[s, ..., c] * e[t, ..., c]
                        num, den = num + p.sum(), den + (p ** 2).sum()
                        q += ((e[s, ..., c] - e[t, ..., c]) ** 2).sum()
                if np.ptp(e[..., c], axis=0).max() < 1e-6:  # the same in every seed
                    line.append(f"{'RGBA'[c]}: no randomness, |error| <= "
                                f"{np.abs(e[..., c]).max():.1e}")
                    continue
                pairs, npx = k * (k - 1) / 2, e[0, ..., c].size
                bound = np.sqrt(max(num + 2 * np.sqrt(den), 0.0) / (pairs * npx))
                zsum = e[..., c].sum() / np.sqrt(q / (k - 1))
                line.append(f"{'RGBA'[c]}: cross z {num / np.sqrt(den):+.2f}, sum z {zsum:+.2f}, "
                            f"rms bias < {bound:.1e}")
            print(f"{name:28s} {k} x {args.walks} walks: " + '; '.join(line), flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('what', choices=['section', 'mc', 'walks'])
    ap.add_argument('--simdvol')
    ap.add_argument('--seeds', type=int)
    ap.add_argument('--walks', type=int, default=65536)
    ap.add_argument('--engine', default='reference', choices=['reference', 'opencl'])
    args = ap.parse_args()
    if args.what == 'section':
        section()
    else:
        if not args.simdvol:
            ap.error(args.what + ' needs --simdvol PATH')
        if args.seeds is None:
            args.seeds = 200 if args.what == 'mc' else 8
        (mc if args.what == 'mc' else walks)(args)


if __name__ == '__main__':
    main()
