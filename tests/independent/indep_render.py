"""Independent renderer for simdvol's axis-aligned views, written from the
documented mathematics (README render table, ../shared/DESIGN.md, thesis
eq 4.1-4.4, 5.2, 5.10, 5.11, 7.2).  numpy only, float64 throughout.

Scope: axis-aligned views (every entry of T(theta, phi, varphi) in
{-1, 0, 1}), --sampling voxel, unit voxel spacing, --order 0 or 1,
--composite direct, material-mixture classifiers, output size chosen so that
one output pixel is one voxel (min(W, H) == the volume's longest side).

Conventions and where each comes from are marked DOC (README / DESIGN /
thesis) or CODE (found first in host/core/*.cpp; README.md's "Where the
samples lie" and the material paragraph now say them).  Each can be
switched to a rival reading (see Conventions): every switch makes cases
fail, so the check tells them apart.
"""
import math
from dataclasses import dataclass

import numpy as np


# ----------------------------------------------------------------- rotation
def rotation(theta, phi, varphi):
    """DOC thesis eq 5.2: T = A(varphi) B(phi) C(theta), degrees."""
    t, p, v = (math.radians(a) for a in (theta, phi, varphi))
    A = np.array([[0, 0, 1], [-math.sin(v), math.cos(v), 0], [math.cos(v), math.sin(v), 0]])
    B = np.array([[math.sin(p), 0, math.cos(p)], [0, 1, 0], [math.cos(p), 0, -math.sin(p)]])
    C = np.array([[math.cos(t), math.sin(t), 0], [-math.sin(t), math.cos(t), 0], [0, 0, 1]])
    T = A @ B @ C
    Ti = np.rint(T)
    if np.abs(T - Ti).max() > 1e-9:
        raise ValueError("not an axis-aligned view: %s" % T)
    assert abs(np.linalg.det(Ti) - 1) < 1e-12
    return Ti.astype(int)


# --------------------------------------------------------------- classifier
@dataclass
class Material:
    name: str
    mean: float
    sigma: float
    rgb: tuple
    opacity: float


@dataclass
class Mixture:
    materials: list
    relative: bool = False


def load_materials(path):
    """DOC README 'material NAME MEAN SIGMA R G B OPACITY', 'relative', '#'."""
    mats, rel = [], False
    for line in open(path):
        line = line.split('#', 1)[0].split()
        if not line:
            continue
        if line[0] == 'material':
            n, m, s, r, g, b, a = line[1:]
            mats.append(Material(n, float(m), float(s), (float(r), float(g), float(b)), float(a)))
        elif line[0] == 'relative':
            rel = True
        else:
            raise ValueError(line)
    mats.sort(key=lambda m: m.mean)
    return Mixture(mats, rel)


AT_MEAN = 'upper'


def classify(vol, mix):
    """DOC thesis eq 4.4 + README: a voxel mixes the two materials whose means
    bracket its value, fractions in proportion to their Gaussian likelihoods
    P_m(I) = N(I; mean_m, sigma_m) (normalised densities, 1/sigma included),
    pure first/last material outside the means.  DOC classify.hpp comment:
    alpha = sum p a, premultiplied colour = sum p a c.
    Returns alpha, premultiplied rgb (float64)."""
    v = vol.astype(np.float64)
    if mix.relative:
        lo, hi = v.min(), v.max()
        I = (v - lo) / (hi - lo) if hi > lo else np.zeros_like(v)
    else:
        I = v
    M = mix.materials
    alpha = np.zeros_like(I)
    col = np.zeros(I.shape + (3,))

    def add(mask, p, m):
        alpha[mask] += p * m.opacity
        col[mask] += (p * m.opacity)[:, None] * np.array(m.rgb)[None, :]

    first, last = I <= M[0].mean, I >= M[-1].mean
    add(first, np.ones(first.sum()), M[0])
    add(last & ~first, np.ones((last & ~first).sum()), M[-1])
    for i in range(len(M) - 1):
        a, b = M[i], M[i + 1]
        # A value exactly at an inner material's mean is bracketed by two
        # pairs; 'upper' (CODE classify.cpp: i = last material with
        # mean_i <= I) mixes it with the next material, 'lower' with the one
        # before.  The docs do not say.
        if AT_MEAN == 'upper':
            mask = (I >= a.mean) & (I < b.mean)
        else:
            mask = (I > a.mean) & (I <= b.mean)
        mask &= ~first & ~last
        x = I[mask]
        la = -0.5 * ((x - a.mean) / a.sigma) ** 2 - math.log(a.sigma)
        lb = -0.5 * ((x - b.mean) / b.sigma) ** 2 - math.log(b.sigma)
        pa = 1.0 / (1.0 + np.exp(lb - la))
        add(mask, pa, a)
        add(mask, 1.0 - pa, b)
    return alpha, col


# ------------------------------------------------------------------ shading
@dataclass
class Shade:
    enabled: bool = True
    light: tuple = (-0.4, -0.5, -1.0)      # DOC README defaults
    ka: float = 0.25
    kd: float = 0.75
    ks: float = 0.35
    n: float = 24.0
    k1: float = 1.0
    k2: float = 0.6


@dataclass
class Conventions:
    # depth cue d per voxel:
    #   'faces' : d = (voxel centre's depth from the front face) / (extent),
    #             what README.md said before (0 at the volume's front, 1 at
    #             its back)
    #   'sphere': README --depth-cue (CODE shade.cpp): d = (z + R) / 2R over
    #             the bounding sphere, z the voxel centre (i + 0.5 - n/2)
    #             along the view
    depth: str = 'sphere'
    # CODE classify.cpp: C = min(1, c * Id + Is) (undocumented clamp)
    clamp_colour: bool = True
    # z phase of the samples along a ray:
    #   'code': CODE view.cpp: D = ceil(diagonal) samples centred on the
    #           volume's centre: z_k = k + 1/2 - D/2 (phase depends on D's parity)
    #   'half': samples at voxel 'centres' i + 1/2 (as x, y are)
    #   'int' : samples at the voxel values' positions i
    zphase: str = 'code'
    # intermediate image grid for voxel sampling with a 2-D scale:
    #   'code'   : CODE view.cpp: ceil(W / scale) + 2 pixels, centred
    #   'aligned': at the 1:1 image's pixel positions
    igrid: str = 'code'


def gradient(v):
    """DOC thesis eq 4.3 operator; DOC README/DESIGN 'neighbours beyond the
    volume are edge-replicated' -> one-sided half differences at the edge.
    Array order is [z, y, x]; returns g as (..., 3) in (x, y, z)."""
    f = v.astype(np.float64)
    p = np.pad(f, 1, mode='edge')
    gx = 0.5 * (p[1:-1, 1:-1, 2:] - p[1:-1, 1:-1, :-2])
    gy = 0.5 * (p[1:-1, 2:, 1:-1] - p[1:-1, :-2, 1:-1])
    gz = 0.5 * (p[2:, 1:-1, 1:-1] - p[:-2, 1:-1, 1:-1])
    return np.stack([gx, gy, gz], axis=-1)


def lit_voxels(vol, mix, T, shade, conv, step=1.0):
    """Premultiplied RGBA per voxel (array [z, y, x, 4]) for view T."""
    alpha, pcol = classify(vol, mix)
    with np.errstate(invalid='ignore', divide='ignore'):
        c = np.where(alpha[..., None] > 0, pcol / alpha[..., None], 0.0)
    if shade.enabled:
        g = gradient(vol)
        gl = np.sqrt((g * g).sum(-1))
        L = np.array(shade.light, float)
        L /= np.linalg.norm(L)
        V = np.array([0.0, 0.0, -1.0])          # DOC: z into the scene, observer in -z
        H = (V + L) / np.linalg.norm(V + L)     # DOC thesis eq 4.2
        Lo, Ho = T.T @ L, T.T @ H               # viewing -> object (T orthonormal)
        with np.errstate(invalid='ignore', divide='ignore'):
            N = np.where(gl[..., None] > 0, g / gl[..., None], 0.0)
        nl = np.abs(N @ Lo)                      # DOC: two-sided |N.L|, |N.H|
        nh = np.abs(N @ Ho)
        nz, ny, nx = vol.shape
        zz, yy, xx = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing='ij')
        pos = np.stack([xx, yy, zz], -1) + 0.5   # voxel centres, index space
        dims = np.array([nx, ny, nz], float)
        depth = (pos - dims / 2) @ T[2]          # viewing z of the voxel centre
        if conv.depth == 'faces':
            ext = np.abs(T[2]) @ dims            # extent of the volume along the view
            d = (depth + ext / 2) / ext
        else:
            R = 0.5 * np.linalg.norm(dims)
            d = (depth + R) / (2 * R)
        cue = 1.0 / (shade.k1 + shade.k2 * d)
        Id = shade.ka + cue * shade.kd * nl      # DOC eq 4.1: ambient + cued diffuse
        Is = cue * shade.ks * nh ** shade.n      #             + cued specular (white)
        C = c * Id[..., None] + Is[..., None]
    else:
        C = c
    if conv.clamp_colour:
        C = np.minimum(C, 1.0)
    # DOC: opacity corrected for the step, alpha' = 1 - (1 - alpha)^step
    a1 = alpha if step == 1.0 else 1.0 - (1.0 - alpha) ** step
    return np.concatenate([a1[..., None] * C, a1[..., None]], axis=-1)


# ---------------------------------------------------------- ray casting
def cast(rgba, dims, T, xs, ys, zs, order):
    """Composite rays through viewing positions xs (columns) x ys (rows),
    samples at depths zs (ascending = front to back).  Image [len(ys), len(xs), 4]."""
    acc = np.zeros((len(ys), len(xs), 4))
    Y, X = np.meshgrid(ys, xs, indexing='ij')
    flat = rgba.reshape(-1, 4)
    n_i = dims.astype(int)
    for z in zs:                                  # DOC: front to back = increasing z
        p = np.stack([X, Y, np.full_like(X, z)], -1)
        obj = p @ T + dims / 2                    # T^T p + n/2 (row vectors)
        fl = np.floor(obj)
        # DOC: voxel i owns [i, i+1) for matching -> inside iff floor in [0, n)
        inside = np.all((fl >= 0) & (fl < n_i), axis=-1)
        if not inside.any():
            continue
        s = sample(flat, n_i, obj[inside], order)
        a = acc[inside]
        acc[inside] = a + (1.0 - a[:, 3:4]) * s   # DOC: over(front, back), premultiplied
    return acc


def centred(n, step=1.0):
    return (np.arange(n) + 0.5 - n / 2) * step


def render(vol, mix, view=(0, 0, 0), size=None, order=1, shade=Shade(), conv=Conventions(),
           sampling='voxel'):
    """vol: numpy [z, y, x].  Returns premultiplied RGBA image [H, W, 4].
    DOC: the volume's longest side spans min(W, H), centred; 0,0,0 looks along
    +z, x right, y down; viewing space centred on the volume's centre.  DOC
    'voxel i owns [i, i+1) for matching while its value sits at i for
    interpolation' -> the centre is at n/2 in the interpolation's index
    space.  Output pixel centres at x + 1/2 - W/2 (in pixels)."""
    T = rotation(*view)
    nz, ny, nx = vol.shape
    dims = np.array([nx, ny, nz], float)
    longest = dims.max()
    W, H = size if size else (int(longest), int(longest))
    scale = min(W, H) / longest                   # output pixels per voxel
    step = 1.0 if sampling == 'voxel' else 1.0 / scale
    rgba = lit_voxels(vol, mix, T, shade, conv, step)
    diag = np.linalg.norm(dims)
    if conv.zphase == 'code':
        D = max(1, math.ceil(diag / step))        # CODE: ceil(diagonal / step) samples
        zs = centred(D, step)
    else:
        ext = np.abs(T[2]) @ dims
        m = math.ceil(ext / 2 / step) + 2
        zs = (np.arange(-m, m) + (0.5 if conv.zphase == 'half' else 0.0)) * step
    if sampling == 'pixel':                       # DOC: affine map, one sample per pixel
        return cast(rgba, dims, T, centred(W, step), centred(H, step), zs, order)
    if scale == 1.0 and conv.igrid == 'code' and W % 2 == 0 and H % 2 == 0:
        # one pixel per voxel: no warp needed (the intermediate grid's centres
        # coincide with the output's; checked against the warp path below)
        return cast(rgba, dims, T, centred(W), centred(H), zs, order)
    # DOC: voxel sampling at voxel spacing, then a bilinear 2-D scale.
    if conv.igrid == 'code':
        # CODE view.cpp: ceil(out / scale) + 2 intermediate pixels, centred
        Wi, Hi = math.ceil(W / scale) + 2, math.ceil(H / scale) + 2
        xi, yi = centred(Wi), centred(Hi)
    else:
        # 'aligned': the intermediate pixels at the 1:1 image's positions
        # (half-integers for an even face), one transparent pixel beyond.
        m = math.ceil(W / scale / 2) + 1
        xi = np.arange(-m, m) + 0.5
        m = math.ceil(H / scale / 2) + 1
        yi = np.arange(-m, m) + 0.5
    inter = cast(rgba, dims, T, xi, yi, zs, order)
    u = centred(W) / scale                        # output pixel centres, voxel units
    v = centred(H) / scale
    return warp(inter, xi, yi, u, v)


def warp(im, xi, yi, u, v):
    """Bilinear, premultiplied RGBA; outside the intermediate image: 0."""
    fx = (u - xi[0]) / (xi[1] - xi[0])
    fy = (v - yi[0]) / (yi[1] - yi[0])
    Hi, Wi = im.shape[:2]
    pad = np.zeros((Hi + 2, Wi + 2, 4))
    pad[1:-1, 1:-1] = im
    x0 = np.floor(fx).astype(int)
    y0 = np.floor(fy).astype(int)
    tx = (fx - x0)[None, :, None]
    ty = (fy - y0)[:, None, None]
    cx0 = np.clip(x0 + 1, 0, Wi + 1)
    cx1 = np.clip(x0 + 2, 0, Wi + 1)
    cy0 = np.clip(y0 + 1, 0, Hi + 1)
    cy1 = np.clip(y0 + 2, 0, Hi + 1)
    a = pad[cy0][:, cx0]
    b = pad[cy0][:, cx1]
    c = pad[cy1][:, cx0]
    d = pad[cy1][:, cx1]
    top = a + tx * (b - a)
    bot = c + tx * (d - c)
    return top + ty * (bot - top)


def sample(flat, n_i, pos, order):
    nx, ny, nz = n_i

    def idx(ix, iy, iz):
        ix = np.clip(ix, 0, nx - 1)               # DOC: edge-replicated neighbours
        iy = np.clip(iy, 0, ny - 1)
        iz = np.clip(iz, 0, nz - 1)
        return (iz * ny + iy) * nx + ix

    if order == 0:
        # DOC eq 5.10: nearest, a tie (x = k + 1/2) goes to the lower voxel
        k = np.ceil(pos - 0.5).astype(np.int64)
        return flat[idx(k[:, 0], k[:, 1], k[:, 2])]
    if order == 1:
        f = np.floor(pos)
        t = pos - f
        f = f.astype(np.int64)
        out = np.zeros((pos.shape[0], 4))
        for dx in (0, 1):
            wx = t[:, 0] if dx else 1 - t[:, 0]
            for dy in (0, 1):
                wy = t[:, 1] if dy else 1 - t[:, 1]
                for dz in (0, 1):
                    wz = t[:, 2] if dz else 1 - t[:, 2]
                    out += (wx * wy * wz)[:, None] * flat[idx(f[:, 0] + dx, f[:, 1] + dy, f[:, 2] + dz)]
        return out
    raise ValueError("order 0 or 1 only")
