"""Independent renderer for simdvol, written from the documented mathematics
(README render table, "Transfer-function files", "Where the samples lie";
../shared/DESIGN.md; thesis eq 4.1-4.4, 5.2, 5.10-5.17, 7.2;
docs/KERNELS.md's sv_view and opacity_step; the public headers' comments).
numpy only, float64 throughout.

Scope: any view T(theta, phi, varphi) (eq 5.2), --sampling voxel (rays at
voxel spacing into an intermediate image, then a bilinear 2-D scale) and
pixel, --fit longest and diagonal, --order 0..3 (Aitken / Lagrange on
nested stencils, samples of orders 2 and 3 clamped to valid opacities),
any voxel spacing, --composite direct, material-mixture and
density / gradient / color ramp classifiers, shaded or not.

Conventions and where each comes from are marked DOC (README / DESIGN /
KERNELS / HARDENING / thesis), HDR (a public header's comment,
host/include/simdvol/*.hpp) or CODE (found only in host/core/*.cpp).  Each
can be switched to a rival reading (see Conventions): every switch makes
cases fail (run_cases.py), so the check tells them apart.
"""
import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Conventions:
    # depth cue d per voxel:
    #   'faces' : d = (voxel centre's depth from the front face) / (extent)
    #   'sphere': DOC README --depth-cue: d = (z + R) / 2R over the bounding
    #             sphere, z the voxel centre's depth (i + 0.5 - n/2) * s
    depth: str = 'sphere'
    # DOC README (material paragraph): C = min(1, c * Id + Is)
    clamp_colour: bool = True
    # z phase of the samples along a ray:
    #   'code': DOC README "Where the samples lie": D = ceil(diagonal / step)
    #           samples centred on the volume's centre, (k + 1/2 - D/2) step
    #   'half': samples at (i + 1/2) step;  'int': at i step
    zphase: str = 'code'
    # intermediate image grid for voxel sampling:
    #   'code'   : DOC README: ceil(W / scale) + 2 pixels, centred
    #   'aligned': at the 1:1 image's pixel positions
    igrid: str = 'code'
    # the rotation:
    #   'eq5.2'     : DOC thesis eq 5.2 / README: T = A(varphi) B(phi) C(theta)
    #                 maps object to viewing space; a sample p lands at T^T p
    #   'inverse'   : the sample lands at T p (the rotation's sign flipped)
    #   'neg-angles': T(-theta, -phi, -varphi)
    #   'reversed'  : T = C(theta) B(phi) A(varphi)
    rotation: str = 'eq5.2'
    # the third point of an order-2 stencil (f = floor x, t = x - f):
    #   'centred'       : HDR resample.hpp: f - 1 if t <= 1/2, else f + 2
    #   'centred-strict': f - 1 if t < 1/2, else f + 2 (the tie the other way)
    #   'far'           : f + 2 if t <= 1/2, else f - 1
    #   'low' / 'high'  : always f - 1 / always f + 2
    order2: str = 'centred'
    # samples of orders 2 and 3 before compositing:
    #   'premult': DOC README --order: alpha in [0, 1], colour in [0, alpha]
    #   'none', 'alpha' (alpha only), 'unit' (alpha and colour in [0, 1])
    sample_clamp: str = 'premult'
    # the unit of length for non-unit spacing (viewing grid step, opacity
    # step, depth cue, gradient):
    #   'smallest': DOC KERNELS.md opacity_step, view.hpp, HARDENING:
    #               the smallest voxel spacing
    #   'largest' : the largest
    spacing_unit: str = 'smallest'
    # gradient (thesis eq 4.3's operator):
    #   'physical': HDR shade.hpp / CODE shade.cpp: central differences over
    #               the physical distance, value units per unit length
    #   'index'   : per voxel index, the spacing ignored
    grad_scale: str = 'physical'
    # sample positions:
    #   'grid' : DOC README "Conventions", KERNELS.md sv_view: the first
    #            sample's position and the grid's three steps rounded to
    #            32.32 fixed point (see Geometry.grid)
    #   'float': float64 throughout (within about 1e-8 voxel of 'grid';
    #            samples on a voxel boundary or half-way may fall the other way)
    positions: str = 'grid'
    # a ramp beyond its first and last points:
    #   'held': HDR classify.hpp Ramp: "constant beyond the ends"
    #   'zero': 0 there
    ramp_ends: str = 'held'
    # the fraction t = x - floor(x) that decides the order-0 and order-2
    # ties at t = 1/2:
    #   'float32': HDR view.hpp fixed_frac: the 32-bit fraction as a float
    #              (24 bits: a t within 2^-25 of 1/2 is 1/2)
    #   'exact'  : the fraction itself
    tie_frac: str = 'float32'


# ----------------------------------------------------------------- rotation
def _snap(v):
    """sin and cos of a multiple of 30 degrees are 0, +-1/2 or +-1 exactly;
    the double's values are an ulp off.  simdvol's viewing grid is 32.32
    fixed point (DOC README "Conventions", KERNELS.md sv_view), whose
    2^-32 cannot hold that ulp, so its grid holds the exact values.  Ours
    (Geometry.grid) rounds the same way; this keeps --positions float's
    axis-aligned views exact too (a sample half-way between two voxels is
    then half-way, as there)."""
    for e in (0.0, 0.5, -0.5, 1.0, -1.0):
        if abs(v - e) < 1e-15:
            return e
    return v


def _factors(theta, phi, varphi):
    t, p, v = (math.radians(a) for a in (theta, phi, varphi))
    ct, st = _snap(math.cos(t)), _snap(math.sin(t))
    cp, sp = _snap(math.cos(p)), _snap(math.sin(p))
    cv, sv = _snap(math.cos(v)), _snap(math.sin(v))
    A = np.array([[0, 0, 1], [-sv, cv, 0], [cv, sv, 0]], float)
    B = np.array([[sp, 0, cp], [0, 1, 0], [cp, 0, -sp]], float)
    C = np.array([[ct, st, 0], [-st, ct, 0], [0, 0, 1]], float)
    return A, B, C


def rotation(theta, phi, varphi, conv=None):
    """DOC thesis eq 5.2: T = A(varphi) B(phi) C(theta), degrees; object ->
    viewing space.  Returns the matrix M with which a viewing position p
    lands in object space at p @ M (= T^T p)."""
    rule = conv.rotation if conv else 'eq5.2'
    if rule == 'neg-angles':
        A, B, C = _factors(-theta, -phi, -varphi)
    else:
        A, B, C = _factors(theta, phi, varphi)
    T = C @ B @ A if rule == 'reversed' else A @ B @ C
    assert np.abs(T @ T.T - np.eye(3)).max() < 1e-12 and abs(np.linalg.det(T) - 1) < 1e-12
    return T.T if rule == 'inverse' else T


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


@dataclass
class Ramps:
    """DOC README "Transfer-function files": opacity = density ramp x
    gradient ramp (of |grad|), colour = the colour ramp (white without one).
    A ramp: points (x, y), linear between them; beyond the first and last
    point its end values (the README's example ends each ramp with a point
    at the largest value, VolPack's convention; CODE classify.cpp Ramp says
    the ends are held)."""
    density: list = field(default_factory=list)
    gradient: list = field(default_factory=list)
    colour: list = field(default_factory=list)     # (x, r, g, b)


def load_classifier(path):
    """DOC README: 'material NAME MEAN SIGMA R G B OPACITY', 'relative', or
    'density x y ...', 'gradient x y ...', 'color x r g b ...'; '#'."""
    mats, rel, ramps = [], False, Ramps()
    for line in open(path):
        line = line.split('#', 1)[0].split()
        if not line:
            continue
        if line[0] == 'material':
            n, m, s, r, g, b, a = line[1:]
            mats.append(Material(n, float(m), float(s), (float(r), float(g), float(b)), float(a)))
        elif line[0] == 'relative':
            rel = True
        elif line[0] in ('density', 'gradient'):
            v = [float(x) for x in line[1:]]
            getattr(ramps, line[0]).extend(zip(v[0::2], v[1::2]))
        elif line[0] in ('color', 'colour'):
            v = [float(x) for x in line[1:]]
            ramps.colour.extend(zip(v[0::4], v[1::4], v[2::4], v[3::4]))
        else:
            raise ValueError(line)
    if mats:
        mats.sort(key=lambda m: m.mean)
        return Mixture(mats, rel)
    return ramps


load_materials = load_classifier


def ramp(points, v, col=1, ends='held'):
    if not points:
        return np.ones_like(v)            # DOC README: no colour ramp: white
    xs = np.array([p[0] for p in points])
    ys = np.array([p[col] for p in points])
    if ends == 'zero':
        return np.interp(v, xs, ys, left=0.0, right=0.0)
    return np.interp(v, xs, ys)           # linear, ends held


AT_MEAN = 'upper'


def classify(vol, mix, gmag=None, ends='held'):
    """Returns alpha and the unlit colour C (not premultiplied), float64.
    Mixture: DOC thesis eq 4.4 + README: a voxel mixes the two materials
    whose means bracket its value, fractions in proportion to their Gaussian
    likelihoods N(I; mean, sigma), pure first / last material outside the
    means; alpha = sum p a, premultiplied colour = sum p a c.
    Ramps: alpha = density(v) gradient(|g|), C = colour(v)."""
    v = vol.astype(np.float64)
    if isinstance(mix, Ramps):
        alpha = ramp(mix.density, v, 1, ends) * ramp(mix.gradient, gmag, 1, ends)
        C = np.stack([ramp(mix.colour, v, c, ends) for c in (1, 2, 3)], -1)
        return alpha, C
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
        # DOC README: a value exactly at an inner material's mean belongs to
        # the pair above it ('upper'); 'lower' is the rival.
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
    with np.errstate(invalid='ignore', divide='ignore'):
        C = np.where(alpha[..., None] > 0, col / alpha[..., None], 0.0)
    return alpha, C


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


def gradient(v, scale=(1.0, 1.0, 1.0)):
    """DOC thesis eq 4.3 operator (central differences); DOC README/DESIGN
    'neighbours beyond the volume are edge-replicated' -> one-sided half
    differences at the edge.  scale[a] = unit / spacing[a]: the derivative
    over physical distance (HDR shade.hpp: 'value units per smallest voxel
    spacing').  Array order [z, y, x]; returns g as (..., 3) in (x, y, z)."""
    f = v.astype(np.float64)
    p = np.pad(f, 1, mode='edge')
    gx = 0.5 * (p[1:-1, 1:-1, 2:] - p[1:-1, 1:-1, :-2]) * scale[0]
    gy = 0.5 * (p[1:-1, 2:, 1:-1] - p[1:-1, :-2, 1:-1]) * scale[1]
    gz = 0.5 * (p[2:, 1:-1, 1:-1] - p[:-2, 1:-1, 1:-1]) * scale[2]
    return np.stack([gx, gy, gz], axis=-1)


def lit_voxels(vol, cls, M, shade, conv, s, step=1.0):
    """Premultiplied RGBA per voxel (array [z, y, x, 4]).  M: viewing ->
    object (p @ M); s: spacing in units of the unit length (x, y, z)."""
    gs = 1.0 / s if conv.grad_scale == 'physical' else np.ones(3)
    g = gradient(vol, gs)
    gl = np.sqrt((g * g).sum(-1))
    alpha, c = classify(vol, cls, gl, conv.ramp_ends)
    if shade.enabled:
        L = np.array(shade.light, float)
        L /= np.linalg.norm(L)
        V = np.array([0.0, 0.0, -1.0])          # DOC: z into the scene, observer in -z
        H = (V + L) / np.linalg.norm(V + L)     # DOC thesis eq 4.2
        Lo, Ho = L @ M, H @ M                    # viewing -> object (physical)
        with np.errstate(invalid='ignore', divide='ignore'):
            N = np.where(gl[..., None] > 0, g / gl[..., None], 0.0)
        nl = np.abs(N @ Lo)                      # DOC: two-sided |N.L|, |N.H|
        nh = np.abs(N @ Ho)
        nz, ny, nx = vol.shape
        dims = np.array([nx, ny, nz], float)
        zz, yy, xx = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing='ij')
        pos = (np.stack([xx, yy, zz], -1) + 0.5 - dims / 2) * s   # voxel centre, physical
        vdir = M[2]                              # viewing +z in object space
        depth = pos @ vdir
        ext = dims * s
        if conv.depth == 'faces':
            e = np.abs(vdir) @ ext
            d = (depth + e / 2) / e
        else:
            R = 0.5 * math.sqrt(float((ext * ext).sum()))
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
    a1 = np.where(alpha > 0, a1, 0.0)
    return np.concatenate([a1[..., None] * C, a1[..., None]], axis=-1)


# --------------------------------------------------------------- geometry
def centred(n, step=1.0):
    return (np.arange(n) + 0.5 - n / 2) * step


@dataclass
class Geometry:
    M: np.ndarray          # viewing -> object rotation, p @ M
    s: np.ndarray          # spacing / unit, (x, y, z)
    dims: np.ndarray       # (nx, ny, nz)
    step: float            # viewing-grid spacing, unit lengths
    scale: float           # output pixels per unit length
    cx: np.ndarray         # grid coordinates of the traced image's rays
    cy: np.ndarray         #   (viewing position / step), x and y,
    cz: np.ndarray         #   and of the samples' depths, front to back
    sampling: str
    positions: str

    @property
    def xs(self):
        return self.cx * self.step

    @property
    def ys(self):
        return self.cy * self.step

    def steps(self):
        """S[b]: the object index-space move of one grid step along viewing
        axis b.  DOC README: viewing space centred on the volume's centre,
        which sits at n/2 in index space (voxel i's value at i, it owns
        [i, i+1)); lengths in unit lengths: X = (T^T p) / s + n/2."""
        return self.step * self.M / self.s[None, :]

    def grid(self):
        """(X0, S): sample (i, j, k) lies at X0 + i S[0] + j S[1] + k S[2].
        'grid': DOC README "Conventions" / KERNELS.md sv_view: the viewing
        grid maps (i, j, k) to volume coordinates in 32.32 fixed point,
        X = origin + i step0 + j step1 + k step2: the first sample's position
        and the three steps, each rounded to 2^-32 (then every position is
        exact in float64 here).  'float': unrounded float64."""
        S = self.steps()
        c0 = np.array([self.cx[0], self.cy[0], self.cz[0]])
        X0 = self.dims / 2 + c0 @ S
        if self.positions == 'grid':
            X0 = np.rint(np.ldexp(X0, 32)) / 2.0 ** 32
            S = np.rint(np.ldexp(S, 32)) / 2.0 ** 32
        return X0, S


def geometry(shape, spacing, view, size, sampling, fit, conv):
    nz, ny, nx = shape
    dims = np.array([nx, ny, nz], float)
    M = rotation(*view, conv)
    sp = np.array(spacing, float)
    unit = sp.min() if conv.spacing_unit == 'smallest' else sp.max()
    s = sp / unit
    ext = dims * sp / unit                       # extents in unit lengths
    longest = ext.max()
    R = 0.5 * math.sqrt(float((ext * ext).sum()))
    # DOC README --size / --fit: the longest side (or the diagonal) spans min(W, H)
    span = longest if fit == 'longest' else 2 * R
    W, H = size
    scale = min(W, H) / span
    # DOC README --sampling: voxel: steps of one (unit) voxel; pixel: of a pixel
    step = 1.0 if sampling == 'voxel' else span / min(W, H)
    if conv.zphase == 'code':
        D = max(1, math.ceil(2 * R / step))       # DOC README: ceil(diagonal / step)
        cz = centred(D)
    else:
        e = np.abs(M[2]) @ ext
        m = math.ceil(e / 2 / step) + 2
        cz = np.arange(-m, m) + (0.5 if conv.zphase == 'half' else 0.0)
    if sampling == 'pixel':                      # DOC: the output's pixel centres
        cx, cy = centred(W), centred(H)
    elif conv.igrid == 'code':                   # DOC README: ceil(W / scale) + 2, centred
        cx, cy = centred(math.ceil(W / scale) + 2), centred(math.ceil(H / scale) + 2)
    else:
        m = math.ceil(W / scale / 2) + 1
        cx = np.arange(-m, m) + 0.5
        m = math.ceil(H / scale / 2) + 1
        cy = np.arange(-m, m) + 0.5
    return Geometry(M, s, dims, step, scale, cx, cy, cz, sampling, conv.positions)


# ---------------------------------------------------------- ray casting
def cast(rgba, g, order, conv, nudge=None):
    """Composite the rays of the grid g (rows g.cy, columns g.cx), samples
    at g.cz, front to back.  Image [len(cy), len(cx), 4].
    nudge: a constant offset added to every sample's object position."""
    acc = np.zeros((len(g.cy), len(g.cx), 4))
    J, I = np.meshgrid(np.arange(len(g.cy)), np.arange(len(g.cx)), indexing='ij')
    flat = rgba.reshape(-1, 4)
    n_i = g.dims.astype(np.int64)
    X0, S = g.grid()
    base = X0 + I[..., None] * S[0] + J[..., None] * S[1]
    if nudge is not None:
        base = base + np.asarray(nudge, float)
    for k in range(len(g.cz)):                   # DOC: front to back = increasing z
        obj = base + k * S[2]
        fl = np.floor(obj)
        # DOC: voxel i owns [i, i+1) for matching -> inside iff floor in [0, n)
        inside = np.all((fl >= 0) & (fl < n_i), axis=-1)
        if not inside.any():
            continue
        s = sample(flat, n_i, obj[inside], order, conv)
        if order >= 2:
            s = clamp_sample(s, conv.sample_clamp)
        a = acc[inside]
        acc[inside] = a + (1.0 - a[:, 3:4]) * s   # DOC: over(front, back), premultiplied
    return acc


def clamp_sample(s, rule):
    """DOC README --order: orders 2 and 3 overshoot, so their samples are
    clamped to valid opacities: alpha in [0, 1], each premultiplied colour
    in [0, alpha], before compositing."""
    if rule == 'none':
        return s
    a = np.clip(s[:, 3:4], 0.0, 1.0)
    if rule == 'alpha':
        c = s[:, :3]
    elif rule == 'unit':
        c = np.clip(s[:, :3], 0.0, 1.0)
    else:
        c = np.clip(s[:, :3], 0.0, None)
        c = np.minimum(c, a)
    return np.concatenate([c, a], -1)


def render(vol, mix, view=(0, 0, 0), size=None, order=1, shade=Shade(), conv=Conventions(),
           sampling='voxel', spacing=(1.0, 1.0, 1.0), fit='longest', nudge=None):
    """vol: numpy [z, y, x].  Returns premultiplied RGBA image [H, W, 4]."""
    nz, ny, nx = vol.shape
    if size is None:
        m = int(max(nx, ny, nz))
        size = (m, m)
    W, H = size
    g = geometry(vol.shape, spacing, view, size, sampling, fit, conv)
    rgba = lit_voxels(vol, mix, g.M, shade, conv, g.s, g.step)
    im = cast(rgba, g, order, conv, nudge)
    if sampling == 'pixel':
        return im
    # DOC: voxel sampling at voxel spacing, then a bilinear 2-D scale; the
    # output pixel centres (x + 1/2 - W/2) / scale in viewing units.
    u = centred(W) / g.scale
    v = centred(H) / g.scale
    return warp(im, g.xs, g.ys, u, v)


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


# ------------------------------------------------------------ resampling
def stencil(x, order, conv):
    """Nodes and Lagrange weights along one axis for positions x (array).
    DOC README --order / thesis eq 5.13-5.16: the order-k estimate is the
    Lagrange polynomial through k + 1 nodes (Aitken's scheme builds it
    progressively; the value does not depend on how); nested stencils.
    Nodes (HDR resample.hpp), f = floor(x), t = x - f:
      order 0: ceil(x - 1/2)            (DOC eq 5.10: a tie goes down)
      order 1: f, f + 1                 (eq 5.11)
      order 2: f, f + 1, and f - 1 if t <= 1/2 else f + 2
      order 3: f - 1, f, f + 1, f + 2
    The ties are decided on t as Conventions.tie_frac says."""
    f = np.floor(x)
    t = x - f
    td = t.astype(np.float32).astype(np.float64) if conv.tie_frac == 'float32' else t
    if order == 0:
        return [np.where(td <= 0.5, f, f + 1)], [np.ones_like(x)]
    if order == 1:
        return [f, f + 1], [1 - t, t]
    if order == 2:
        rule = conv.order2
        if rule == 'centred':
            low = td <= 0.5
        elif rule == 'centred-strict':
            low = td < 0.5
        elif rule == 'far':
            low = td > 0.5
        else:
            low = np.full(t.shape, rule == 'low')
        offs = [np.zeros_like(t), np.ones_like(t), np.where(low, -1.0, 2.0)]
    else:
        offs = [np.full_like(t, o) for o in (-1.0, 0.0, 1.0, 2.0)]
    ws = []
    for i, oi in enumerate(offs):
        w = np.ones_like(t)
        for j, oj in enumerate(offs):
            if j != i:
                w = w * (t - oj) / (oi - oj)      # eq 5.13
        ws.append(w)
    return [f + o for o in offs], ws


def sample(flat, n_i, pos, order, conv):
    nx, ny, nz = n_i
    (nxs, wxs), (nys, wys), (nzs, wzs) = (stencil(pos[:, a], order, conv) for a in range(3))
    # DOC: neighbours beyond the volume are edge-replicated
    ixs = [np.clip(n, 0, nx - 1).astype(np.int64) for n in nxs]
    iys = [np.clip(n, 0, ny - 1).astype(np.int64) for n in nys]
    izs = [np.clip(n, 0, nz - 1).astype(np.int64) for n in nzs]
    out = np.zeros((pos.shape[0], 4))
    for iz, wz in zip(izs, wzs):
        for iy, wy in zip(iys, wys):
            row = (iz * ny + iy) * nx
            wyz = wy * wz
            for ix, wx in zip(ixs, wxs):
                out += (wx * wyz)[:, None] * flat[row + ix]
    return out
