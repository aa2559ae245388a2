"""Independent renderer for simdvol, written from the documented mathematics
(README render table, "Transfer-function files", "Where the samples lie";
../shared/DESIGN.md; thesis eq 4.1-4.4, 5.2, 5.10-5.17, 7.2;
docs/KERNELS.md's sv_view, opacity_step and mc.cl; thesis ch. 7; the
public headers' comments).
numpy only, float64 throughout but for Monte Carlo's walks (float32, as
simdvol's).

Scope: any view T(theta, phi, varphi) (eq 5.2), --sampling voxel (rays at
voxel spacing into an intermediate image, then a bilinear 2-D scale) and
pixel, --fit longest and diagonal, --order 0..3 (Aitken / Lagrange on
nested stencils, samples of orders 2 and 3 clamped to valid opacities),
any voxel spacing, --composite direct, adaptive and mc (whole ray,
reproduced draw for draw: Philox4x32-10; and the estimate's exact
distribution, for the statistics), material-mixture and density / gradient
/ color ramp classifiers, shaded or not.

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
    #   'code'   : DOC README: ceil(W / scale) + 2 pixels, centred, cut to
    #              ceil(diagonal) + 3 or + 4 (its parity) where larger
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
    # the fraction t in the interpolation weights:
    #   'exact'  : t itself (the direct cases: within 2^-25 of 'float32')
    #   'float32': DOC README "Where the samples lie": 'a sample's fraction
    #              within its voxel is a float' (HDR view.hpp fixed_frac): a
    #              t within 2^-25 of 1 is 1, so the weight 1 - t of a voxel
    #              is 0 where 'exact' gives it 1e-9.  The adaptive and Monte
    #              Carlo cases take this: the exact-opacity draws are keyed by
    #              the first sample with alpha > 0, which such a weight decides.
    weight_frac: str = 'exact'
    # voxel alphas near 0 (no matter to direct compositing; they decide the
    # first sample with alpha > 0, which keys the exact-opacity draws):
    #   'plain'  : alpha as computed, 1 - (1 - alpha)^step in float64 (0 for
    #              alpha below 1e-16)
    #   'float32': CODE classify.cpp:313-324: an alpha below 2^-126
    #              (FLT_MIN, where the device's float exp stops) is 0, and
    #              the correction without the cancellation of 1 - alpha,
    #              -expm1(step log1p(-alpha)), the step as a float
    tiny_alphas: str = 'plain'


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
    percentile: float = 100.0   # 'relative P': the top, a percentile of the foreground


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
    mats, rel, pct, ramps = [], False, 100.0, Ramps()
    for line in open(path):
        line = line.split('#', 1)[0].split()
        if not line:
            continue
        if line[0] == 'material':
            n, m, s, r, g, b, a = line[1:]
            mats.append(Material(n, float(m), float(s), (float(r), float(g), float(b)), float(a)))
        elif line[0] == 'relative':
            rel = True
            if len(line) > 1:
                pct = float(line[1])
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
        return Mixture(mats, rel, pct)
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
        if mix.percentile < 100:
            # DOC README "Transfer-function files": 'relative P' takes the
            # range from the minimum to the P-th percentile (the lower rank)
            # of the foreground, the finite voxels above min + (max - min) / 10
            fg = np.sort(v[np.isfinite(v) & (v > lo + (hi - lo) / 10.0)])
            if fg.size:
                top = fg[int(mix.percentile / 100.0 * (fg.size - 1))]
                hi = top if top > lo else hi
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
        # each fraction on its own: 1 - pa would lose the upper material's
        # share below 1e-16, which float32 keeps (tiny alphas decide which
        # sample is the first with alpha > 0: Monte Carlo's exact opacity)
        add(mask, 1.0 / (1.0 + np.exp(lb - la)), a)
        add(mask, 1.0 / (1.0 + np.exp(la - lb)), b)
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
    if conv.tiny_alphas == 'float32':
        alpha = np.where(alpha >= 2.0 ** -126, alpha, 0.0)
        st = float(np.float32(step))
        with np.errstate(divide='ignore'):
            a1 = alpha if step == 1.0 else -np.expm1(st * np.log1p(-alpha))
    else:
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
    ext = dims * s                               # extents in unit lengths
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
    elif conv.igrid == 'code':                   # DOC README: ceil(W / scale) + 2, centred,
        # cut alike on both sides to ceil(diagonal) + 3, or + 4 where that
        # keeps the count's parity
        cut = math.ceil(2 * R) + 3

        def cut_to(n):
            return n if n <= cut else cut + (n - cut) % 2
        cx = centred(cut_to(math.ceil(W / scale) + 2))
        cy = centred(cut_to(math.ceil(H / scale) + 2))
    else:
        m = math.ceil(W / scale / 2) + 1
        cx = np.arange(-m, m) + 0.5
        m = math.ceil(H / scale / 2) + 1
        cy = np.arange(-m, m) + 0.5
    return Geometry(M, s, dims, step, scale, cx, cy, cz, sampling, conv.positions)


# ---------------------------------------------------------- ray casting
def ray_steps(rgba, g, order, conv, nudge=None):
    """The grid g's samples depth by depth: yields (k, inside, samples) for
    k = 0 .. D - 1 front to back, inside the mask [len(cy), len(cx)] of the
    rays whose sample k lies in the volume, samples their premultiplied
    values there.  nudge: a constant offset added to every sample's object
    position."""
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
        yield k, inside, s


def cast(rgba, g, order, conv, nudge=None):
    """Composite the rays of the grid g (rows g.cy, columns g.cx), samples
    at g.cz, front to back.  Image [len(cy), len(cx), 4].
    nudge: a constant offset added to every sample's object position."""
    acc = np.zeros((len(g.cy), len(g.cx), 4))
    for _, inside, s in ray_steps(rgba, g, order, conv, nudge):
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
    if conv.weight_frac == 'float32':
        t = t.astype(np.float32).astype(np.float64)
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


# ------------------------------------------------------ samples per ray
def ray_samples(rgba, g, order, conv, nudge=None):
    """The samples of every ray of the grid g, as cast() composites them:
    array [D, len(cy), len(cx), 4] (k = 0 .. D - 1 front to back, the depth
    index of DOC README "Where the samples lie"), premultiplied, 0 outside
    the volume (DOC: such a sample is transparent, so it changes no
    compositing mode)."""
    out = np.zeros((len(g.cz), len(g.cy), len(g.cx), 4))
    for k, inside, s in ray_steps(rgba, g, order, conv, nudge):
        out[k][inside] = s
    return out


def composite_adaptive(smp, threshold, stop='levoy', compare='float32'):
    """DOC README --composite adaptive: front-to-back over as direct,
    stopping at --threshold (Levoy); HDR composite.hpp: 'stopping once
    accumulated alpha >= threshold', i.e. before each sample the ray stops if
    its alpha has reached the threshold (so the sample that reaches it is
    composited).  The threshold and the accumulated alpha are floats (HDR
    CompositeParams, Rgba; the CLI's FLOAT): compared as float32 (a ray
    into bone of opacity 0.3 reaches 0.3f exactly, at --threshold 0.3,
    where float64's 0.3 lies below 0.3f; rival compare='float64': the
    threshold's float against our float64 alpha).  Rivals (stop=):
      'early': the sample whose over would reach the threshold is left out
      'late' : one more sample after the one that reaches it."""
    thr = np.float32(threshold)
    if compare == 'float32':
        reached = lambda acc: acc[..., 3].astype(np.float32) >= thr  # noqa: E731
    else:
        reached = lambda acc: acc[..., 3] >= float(thr)  # noqa: E731
    acc = np.zeros(smp.shape[1:])
    done = np.zeros(smp.shape[1:-1], bool)
    extra = np.zeros(smp.shape[1:-1], bool)
    for s in smp:
        nxt = acc + (1.0 - acc[..., 3:4]) * s
        if stop == 'early':
            done |= reached(nxt)
        take = ~done
        acc = np.where(take[..., None], nxt, acc)
        if stop == 'late':
            done |= extra
            extra |= reached(acc)
        elif stop == 'levoy':
            done |= reached(acc)
    return acc


def render_samples(vol, mix, view=(0, 0, 0), size=None, order=1, shade=Shade(),
                   conv=Conventions(), sampling='voxel', spacing=(1.0, 1.0, 1.0),
                   fit='longest', nudge=None):
    """(geometry, samples [D, Hi, Wi, 4]) of render()'s rays."""
    nz, ny, nx = vol.shape
    if size is None:
        m = int(max(nx, ny, nz))
        size = (m, m)
    g = geometry(vol.shape, spacing, view, size, sampling, fit, conv)
    rgba = lit_voxels(vol, mix, g.M, shade, conv, g.s, g.step)
    return g, ray_samples(rgba, g, order, conv, nudge)


def finish(g, im, size):
    """The intermediate image to the output: pixel sampling as it is, voxel
    sampling through render()'s bilinear warp (DOC KERNELS.md section 4:
    adaptive and Monte Carlo leave an intermediate image, then the warp)."""
    if g.sampling == 'pixel':
        return im
    W, H = size
    return warp(im, g.xs, g.ys, centred(W) / g.scale, centred(H) / g.scale)


def warp_is_pick(g, size):
    """Where voxel sampling's warp takes every output pixel from exactly one
    intermediate pixel (1:1, the output's pixel centres on the rays), the
    intermediate (row, column) of each output row and column, else None.
    Pixel sampling: the identity."""
    W, H = size
    if g.sampling == 'pixel':
        return np.arange(H), np.arange(W)
    fx = (centred(W) / g.scale - g.xs[0]) / (g.xs[1] - g.xs[0])
    fy = (centred(H) / g.scale - g.ys[0]) / (g.ys[1] - g.ys[0])
    if np.any(fx != np.floor(fx)) or np.any(fy != np.floor(fy)):
        return None
    return fy.astype(int), fx.astype(int)


# --------------------------------------------------------------- Philox
# DOC README --streams: Philox4x32-10 (Salmon et al., SC'11; Random123)
# keyed by --seed.  Vectorised: uint64 holds every 32 x 32 product.
_MASK = np.uint64(0xFFFFFFFF)
_PHILOX_M = (np.uint64(0xD2511F53), np.uint64(0xCD9E8D57))
_PHILOX_W = (0x9E3779B9, 0xBB67AE85)


def philox4x32_10(c, k):
    """c: four arrays (broadcast together) of 32-bit counter words, k: the
    two key words (ints).  Returns the four output words (uint64 arrays)."""
    c0, c1, c2, c3 = (np.asarray(x, np.uint64) & _MASK for x in c)
    c0, c1, c2, c3 = np.broadcast_arrays(c0, c1, c2, c3)
    k0, k1 = int(k[0]) & 0xFFFFFFFF, int(k[1]) & 0xFFFFFFFF
    for _ in range(10):
        p0 = _PHILOX_M[0] * c0
        p1 = _PHILOX_M[1] * c2
        c0, c1, c2, c3 = ((p1 >> np.uint64(32)) ^ c1 ^ np.uint64(k0), p1 & _MASK,
                          (p0 >> np.uint64(32)) ^ c3 ^ np.uint64(k1), p0 & _MASK)
        k0 = (k0 + _PHILOX_W[0]) & 0xFFFFFFFF
        k1 = (k1 + _PHILOX_W[1]) & 0xFFFFFFFF
    return c0, c1, c2, c3


# Random123's known answers (kat_vectors: philox4x32 10 rounds)
PHILOX_KAT = [
    ((0, 0, 0, 0), (0, 0), (0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8)),
    ((0xffffffff,) * 4, (0xffffffff,) * 2, (0x408f276d, 0x41c83b0e, 0xa20bc7c6, 0x6d5451fd)),
    ((0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344), (0xa4093822, 0x299f31d0),
     (0xd16cfe09, 0x94fdcceb, 0x5001e420, 0x24126ea1)),
]


def philox_selftest():
    for c, k, want in PHILOX_KAT:
        got = tuple(int(w) for w in philox4x32_10(c, k))
        assert got == want, ('Philox4x32-10 known answer', c, k, [hex(w) for w in got])


@dataclass
class McConventions:
    """How simdvol draws a walk's random numbers; DOC = README --streams /
    KERNELS.md (simdvol_shared.h's section), HDR = a public header's comment
    (host/include/simdvol/mc.hpp, composite.hpp), CODE = found only in code
    (each is a doc gap; run_cases.py's docstring lists them)."""
    # the 32-bit word to u in [0, 1):
    #   'top24': CODE simdvol_shared.h sv_uniform4: (w >> 8) * 2^-24, a float
    #            with 24 random bits (HDR-ish: its comment says '24 random bits')
    #   'low24': (w & 0xFFFFFF) * 2^-24
    u: str = 'top24'
    # counter words: DOC README 'counter (ray, walk / 4, depth)', KERNELS.md
    # '(ray, sample >> 2, step, "simd")'; "simd" as the word 0x73696d64
    # (CODE: ASCII, first letter in the high byte).  'swap': (ray, depth,
    # walk / 4)
    counter: str = 'rqs'
    simd: int = 0x73696d64
    # key words: CODE (seed mod 2^32, seed >> 32); 'swap': the other way
    key: str = 'lohi'
    # the ray word: HDR mc.hpp: j * width + i on the viewing grid (the
    # intermediate image with voxel sampling, the output with pixel
    # sampling); DOC KERNELS.md: SV_SHARED_RAY = 0xFFFFFFFF for every ray
    # with --streams shared.  Rival 'col': i * height + j.
    ray: str = 'row'
    shared_key: int = 0xFFFFFFFF
    # the depth word: HDR mc.hpp: the ABSOLUTE depth index k of the viewing
    # grid (0 .. D - 1); rival 'opaque': counted from the ray's first sample
    # with alpha > 0
    depth: str = 'absolute'
    # the exact-opacity draws (stratified walks, the no-stop fallback): HDR
    # composite.hpp: at the depth of the ray's first sample with alpha > 0;
    # rival 'zero': at depth 0
    exact_depth: str = 'opaque'
    # the colour a walk picks: DOC DESIGN.md / HDR composite.hpp: C'_s /
    # alpha_s (unpremultiplied); rival 'premult': C'_s
    colour: str = 'unpremult'
    # exact opacity when no walk stops: HDR composite.hpp: one pick from the
    # conditional distribution (walk n's draw); rival 'none': colour 0
    fallback: str = 'pick'
    # stratified targets: HDR composite.hpp: t_m = ((m + u_m) / n) * alpha;
    # rival 'unscaled': (m + u_m) / n
    strata: str = 'alpha'


MC_CONV = McConventions()


def uniforms(seed, keys, walks, steps, mc=MC_CONV):
    """u[..., m] for walks m = 0 .. walks - 1 of rays keys[...] at depth
    steps[...] (arrays broadcast together): DOC README 'counter (ray,
    walk / 4, depth), word walk mod 4'."""
    keys = np.asarray(keys, np.uint64)
    steps = np.asarray(steps, np.uint64)
    keys, steps = np.broadcast_arrays(keys, steps)
    nq = (walks + 3) // 4
    q = np.arange(nq, dtype=np.uint64)
    kw = (seed & 0xFFFFFFFF, seed >> 32)
    if mc.key == 'swap':
        kw = kw[::-1]
    r, s = keys[..., None], steps[..., None]
    ctr = (r, q, s, mc.simd) if mc.counter == 'rqs' else (r, s, q, mc.simd)
    words = np.stack(philox4x32_10(ctr, kw), -1)           # [..., nq, 4]
    words = words.reshape(keys.shape + (4 * nq,))[..., :walks]
    if mc.u == 'low24':
        words = words & np.uint64(0xFFFFFF)
    else:
        words = words >> np.uint64(8)
    return (words.astype(np.float64) * 2.0 ** -24).astype(np.float32)


# --------------------------------------------------------------- Monte Carlo
@dataclass
class McParams:
    samples: int = 32
    seed: int = 1
    streams: str = 'per-ray'
    exact: bool = False
    stratified: bool = False


@dataclass
class McResult:
    est: np.ndarray          # [R, 4] float32: the rays' estimates
    picks: np.ndarray        # [R, n] int: each walk's sample (-1: none)
    fallback: np.ndarray     # [R] int: exact opacity's conditional pick (-1)
    alts: list               # (ray, walk, other pick): the near ties
    col: np.ndarray          # [D, R, 3] float32 picked colours
    acc: np.ndarray          # [R] float32 exact opacity
    ray_alts: list = field(default_factory=list)   # (ray, other estimate [4])


def mc_keys(shape, p, mc=MC_CONV):
    Hi, Wi = shape
    J, I = np.meshgrid(np.arange(Hi), np.arange(Wi), indexing='ij')
    if p.streams == 'shared':
        return np.full(Hi * Wi, mc.shared_key, np.uint64)
    ids = J * Wi + I if mc.ray == 'row' else I * Hi + J
    return ids.reshape(-1).astype(np.uint64)


def _invert(cum, alpha, t):
    """The conditional pick by inversion (HDR composite.hpp): per ray r and
    target t[r, m], the first sample s with alpha_s > 0 whose cumulative
    opacity cum_s exceeds t, else the last sample with alpha_s > 0 (-1: none).
    cum, alpha: [D, R]."""
    opq = alpha > 0
    hit = opq[:, :, None] & (cum[:, :, None] > t[None])
    first = np.argmax(hit, 0)
    D = alpha.shape[0]
    last = np.where(opq.any(0), D - 1 - np.argmax(opq[::-1], 0), -1)
    return np.where(hit.any(0), first, last[:, None])


def _near_invert(cum, alpha, t, pick, eps):
    """Near ties of _invert: (ray, walk, other pick) where t lies within eps
    of the boundary below or above the picked sample's interval."""
    out = []
    D, R = alpha.shape
    opq = alpha > 0
    for r, m in zip(*np.nonzero(pick >= 0)):
        s = pick[r, m]
        tt = float(t[r, m])
        ks = np.nonzero(opq[:, r])[0]
        i = np.searchsorted(ks, s)
        below = float(cum[ks[i - 1], r]) if i > 0 else 0.0
        if i > 0 and abs(tt - below) < eps:
            out.append((r, m, int(ks[i - 1])))
        if i + 1 < len(ks) and abs(float(cum[s, r]) - tt) < eps:
            out.append((r, m, int(ks[i + 1])))
    return out


FLT_MIN = 2.0 ** -126


def mc_composite(smp, p, keys, mc=MC_CONV, eps=1e-5, k0=None):
    """Whole-ray Monte Carlo (DOC README --composite mc, thesis eq 7.3,
    7.12, 7.13; DESIGN.md; HDR composite.hpp composite_mc_walks) on the
    samples smp [D, R, 4], in float32 as simdvol stores its samples.
    Walk m visits the samples front to back and stops at the first s with
    u(m, s) < alpha_s (thesis 7.2's step (2); u drawn at the ray's key, walk
    m, depth s), picking C_s = C'_s / alpha_s; a walk that passes every
    sample picks black.  Plain: colour = mean of the picks, alpha = the
    fraction of walks that stopped (eq 7.13).  --exact-opacity (ch. 7.5 (a),
    HDR): alpha = over's recurrence in float, colour = alpha * mean of the
    stopped walks' picks, or with none stopped (alpha > 0) alpha * C of one
    pick by inverting the cumulative opacity at t = u * alpha (u: walk n's
    draw at the depth of the first sample with alpha > 0).  --mc-stratified
    (README; HDR): walk m draws u_m at that depth and picks by inversion at
    t_m = ((m + u_m) / n) * alpha; colour = alpha * mean of the picks.
    eps: a comparison within eps (u against alpha_s, t against a cumulative
    opacity) is a near tie, whose other outcome goes to alts.  The depth
    of the exact-opacity draws has near ties too: a sample alpha below
    FLT_MIN (2^-126) is subnormal or 0 in float32 as the arithmetic's order
    and rounding make it, so where a ray's first samples with alpha > 0 lie
    below it, the estimates with the draws keyed at each of them and at the
    first sample above it go to ray_alts.  k0: the depth of those draws
    per ray (default: the first sample with float32 alpha > 0)."""
    n = p.samples
    s32 = smp.astype(np.float32)
    D, R = s32.shape[:2]
    alpha = s32[..., 3]
    with np.errstate(invalid='ignore', divide='ignore'):
        col = np.where(alpha[..., None] > 0, s32[..., :3] / alpha[..., None], np.float32(0))
    if mc.colour == 'premult':
        col = s32[..., :3].copy()
    cum = np.zeros((D, R), np.float32)
    c = np.zeros(R, np.float32)
    one = np.float32(1)
    for k in range(D):
        c = c + (one - c) * alpha[k]
        cum[k] = c
    acc = c
    opq = alpha > 0
    first_opq = np.where(opq.any(0), np.argmax(opq, 0), 0)
    given = k0 is not None
    if not given:
        k0 = first_opq if mc.exact_depth == 'opaque' else np.zeros(R, int)
    picks = np.full((R, n), -1)
    fallback = np.full(R, -1)
    alts = []
    if not p.stratified:
        chase = np.zeros((R, n), bool)
        for k in range(D):
            need = (picks == -1).any(1) | chase.any(1)
            rows = np.nonzero(opq[k] & need)[0]
            if len(rows) == 0:
                continue
            step = k - first_opq[rows] if mc.depth == 'opaque' else np.full(len(rows), k)
            u = uniforms(p.seed, keys[rows], n, step, mc)
            a = alpha[k, rows][:, None]
            stop = u < a
            near = np.abs(u.astype(np.float64) - a) < eps
            pr = picks[rows]
            free = pr == -1
            for r, m in zip(*np.nonzero(free & ~stop & near)):
                alts.append((rows[r], m, k))
            cr = chase[rows]
            for r, m in zip(*np.nonzero(cr & stop)):
                alts.append((rows[r], m, k))
            cr &= ~stop
            cr |= free & stop & near
            chase[rows] = cr
            pr[free & stop] = k
            picks[rows] = pr
        for r, m in zip(*np.nonzero(chase)):
            alts.append((r, m, -1))
    if p.exact or p.stratified:
        if p.stratified:
            u = uniforms(p.seed, keys, n, k0, mc)                      # [R, n]
            inv_n = np.float32(1) / np.float32(n)
            t = (np.arange(n, dtype=np.float32)[None] + u) * inv_n
            t = t * acc[:, None] if mc.strata == 'alpha' else t
            t = t.astype(np.float32)
            picks = np.where(acc[:, None] > 0, _invert(cum, alpha, t), -1)
            alts += _near_invert(cum, alpha, t, picks, eps)
        else:
            u = uniforms(p.seed, keys, n + 1, k0, mc)[:, n]
            t = (u * acc)[:, None].astype(np.float32)
            fb = np.where(acc > 0, _invert(cum, alpha, t)[:, 0], -1)
            none = (picks == -1).all(1) & (acc > 0)
            fallback = np.where(none, fb, -1)
            if mc.fallback == 'none':
                fallback[:] = -1
            alts += [(r, n, o) for r, m, o in _near_invert(cum, alpha, t, fb[:, None], eps)
                     if none[r]]
    est = np.stack([mc_estimate(picks[r], fallback[r], col[:, r], acc[r], p)
                    for r in range(R)]) if R else np.zeros((0, 4), np.float32)
    ray_alts = []
    if (p.exact or p.stratified) and mc.exact_depth == 'opaque' and R and not given:
        a64 = smp[..., 3]
        pos = a64 > 0
        tiny = pos & (a64 < FLT_MIN)
        # the candidates: samples with alpha > 0 up to the first >= FLT_MIN
        normal = pos & ~tiny
        first_normal = np.where(normal.any(0), np.argmax(normal, 0), D)
        cand = pos & (np.arange(D)[:, None] <= first_normal[None])
        for j in range(1, 4):
            rank = np.cumsum(cand, 0)
            sel = cand & (rank == j)
            rows = np.nonzero(sel.any(0) & tiny.any(0))[0]
            if len(rows) == 0:
                break
            kj = np.argmax(sel[:, rows], 0)
            rows, kj = rows[kj != k0[rows]], kj[kj != k0[rows]]
            if len(rows):
                alt = mc_composite(smp[:, rows], p, keys[rows], mc, eps, kj)
                ray_alts += [(r, alt.est[i]) for i, r in enumerate(rows)]
    return McResult(est, picks, fallback, alts, col, acc, ray_alts)


def mc_estimate(picks, fallback, col, acc, p):
    """One ray's estimate from its walks' picks (-1: none) and, for exact
    opacity, the fallback pick; colour sums in double, as HDR McStats' and
    KERNELS.md's 'doubles for the Monte Carlo colour sums' say."""
    n = len(picks)
    hit = picks >= 0
    sums = col[picks[hit]].astype(np.float64).sum(0) if hit.any() else np.zeros(3)
    if not (p.exact or p.stratified):
        return np.array(list(sums * (1.0 / n)) + [hit.sum() * (1.0 / n)], np.float32)
    a = float(acc)
    if p.stratified:
        rgb = a * (sums * (1.0 / n)) if a > 0 else np.zeros(3)
    elif hit.any():
        rgb = a * (sums / hit.sum())
    elif fallback >= 0:
        rgb = a * col[fallback].astype(np.float64)
    else:
        rgb = np.zeros(3)
    return np.array(list(rgb) + [a], np.float32)


# ------------------------------------------------- Monte Carlo's moments
def mc_moments(smp, p, expect='over', var='exact'):
    """The exact distribution of a whole-ray Monte Carlo estimate, per ray
    (independent of how the random numbers are made: the walks are taken
    as independent and uniform, DOC README 'per-ray streams').  smp
    [D, R, 4] float64.  Returns (mean, var, e4), each [R, 4]: the
    expectation, the variance and the fourth central moment of the
    estimate with p.samples walks.
    p_k = alpha_k prod_{j<k} (1 - alpha_j) (eq 7.3), c_k = C'_k / alpha_k,
    A = sum p_k.  Plain: a walk's colour X = c_k w.p. p_k, 0 w.p. 1 - A
    (alpha: 1 w.p. A); the mean of n independent walks has variance v1 / n
    and E e^4 = (mu4 + 3 (n - 1) v1^2) / n^3.  Exact opacity: alpha exact;
    colour = A * mean of max(H, 1) independent picks from q_k = p_k / A, H ~
    Binomial(n, A) the walks that stop (the fallback pick when H = 0 is
    independent of them).  Stratified: colour = (A / n) sum_m Y_m, Y_m the
    colour at t uniform in stratum [m A / n, (m + 1) A / n) of the cumulative
    opacity, independent over m.
    Rivals (a biased expectation): expect='eq7.12' (the thesis's printed
    index: prod_{j<=i}), 'drop-last' (each ray's last sample with alpha > 0
    left out), 'premult' (colour premultiplied twice: c_k alpha_k), 'ge'
    (a walk stops where u >= alpha_k);
    var='walks2x': the variance of 2n walks."""
    n = p.samples
    if var == 'walks2x':
        n = 2 * n
    a = smp[..., 3]
    D, R = a.shape
    trans = np.cumprod(np.vstack([np.ones((1, R)), 1.0 - a[:-1]]), 0)   # prod_{j<k}
    pk = a * trans
    with np.errstate(invalid='ignore', divide='ignore'):
        c = np.where(a[..., None] > 0, smp[..., :3] / a[..., None], 0.0)
    A = np.cumsum(pk, 0)[-1]
    pe = pk
    ce = c
    if expect == 'eq7.12':
        pe = a * trans * (1.0 - a)
    elif expect == 'drop-last':
        last = D - 1 - np.argmax((a > 0)[::-1], 0)
        pe = np.where(np.arange(D)[:, None] == last[None], 0.0, pk)
    elif expect == 'premult':
        ce = c * a[..., None]
    elif expect == 'ge':
        # the pick comparison the wrong way round, u >= alpha_k, over the
        # samples that draw (alpha > 0)
        opq = a > 0
        pa = np.where(opq, a, 1.0)
        keep = np.cumprod(np.vstack([np.ones((1, R)), pa[:-1]]), 0)
        pe = np.where(opq, (1.0 - a) * keep, 0.0)
    mean = np.zeros((R, 4))
    mean[:, :3] = (pe[..., None] * ce).sum(0)
    mean[:, 3] = pe.sum(0) if expect == 'drop-last' else A
    v = np.zeros((R, 4))
    e4 = np.zeros((R, 4))
    if not (p.exact or p.stratified):
        # raw moments of one walk's X (0 outside the picks)
        m1 = (pk[..., None] * c).sum(0)
        m2 = (pk[..., None] * c ** 2).sum(0)
        m3 = (pk[..., None] * c ** 3).sum(0)
        m4 = (pk[..., None] * c ** 4).sum(0)
        v1 = m2 - m1 ** 2
        c4 = m4 - 4 * m1 * m3 + 6 * m1 ** 2 * m2 - 3 * m1 ** 4
        va = A * (1 - A)
        c4a = A * (1 - A) * (1 - 3 * A + 3 * A * A)          # Bernoulli's mu4
        v[:, :3] = v1 / n
        v[:, 3] = va / n
        e4[:, :3] = (c4 + 3 * (n - 1) * v1 ** 2) / n ** 3
        e4[:, 3] = (c4a + 3 * (n - 1) * va ** 2) / n ** 3
        return mean, np.maximum(v, 0), np.maximum(e4, 0)
    with np.errstate(invalid='ignore', divide='ignore'):
        q = np.where(A > 0, pk / A, 0.0)
    if not p.stratified:
        m1 = (q[..., None] * c).sum(0)
        m2 = (q[..., None] * c ** 2).sum(0)
        m3 = (q[..., None] * c ** 3).sum(0)
        m4 = (q[..., None] * c ** 4).sum(0)
        vq = m2 - m1 ** 2
        c4q = m4 - 4 * m1 * m3 + 6 * m1 ** 2 * m2 - 3 * m1 ** 4
        h = np.arange(n + 1)
        lc = np.array([math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1)
                       for i in h])
        # Binomial(n, A) probabilities, A = 0 and 1 included
        A1 = A[:, None]
        la = np.where(A1 > 0, np.log(np.maximum(A1, 1e-300)) * h, np.where(h == 0, 0.0, -np.inf))
        lb = np.where(A1 < 1, np.log(np.maximum(1 - A1, 1e-300)) * (n - h),
                      np.where(h == n, 0.0, -np.inf))
        pmf = np.exp(lc[None] + la + lb)                      # [R, n + 1]
        hp = np.maximum(h, 1).astype(float)
        E1 = (pmf / hp).sum(1)
        E3 = (pmf / hp ** 3).sum(1)
        E3b = (pmf * (hp - 1) / hp ** 3).sum(1)
        v[:, :3] = (A ** 2 * E1)[:, None] * vq
        e4[:, :3] = (A ** 4)[:, None] * (c4q * E3[:, None] + 3 * vq ** 2 * E3b[:, None])
        return mean, np.maximum(v, 0), np.maximum(e4, 0)
    # stratified: the colour c(t) is piecewise constant over the cumulative
    # opacity; G_j(t) = int_0^t c^j, linear between the breakpoints cum_k
    cum = np.cumsum(pk, 0)                                     # [D, R]
    b = A[None] * (np.arange(n + 1)[:, None] / n)              # [n + 1, R]
    G = []
    for j in range(5):
        cj = c ** j if j else np.ones_like(c)
        Gk = np.cumsum(pk[..., None] * cj, 0)                   # [D, R, 3]
        # index of the sample whose interval holds b: first k with cum_k > b
        idx = (cum[:, None, :] <= b[None] + 0.0).sum(0)         # [n + 1, R]
        idx = np.minimum(idx, D - 1)
        prev_cum = np.where(idx > 0, np.take_along_axis(cum, np.maximum(idx - 1, 0), 0), 0.0)
        prev_G = np.where((idx > 0)[..., None],
                          np.take_along_axis(Gk, np.maximum(idx - 1, 0)[..., None], 0), 0.0)
        cv = np.take_along_axis(cj, idx[..., None], 0)
        G.append(prev_G + (b - prev_cum)[..., None] * cv)
    w = A / n
    with np.errstate(invalid='ignore', divide='ignore'):
        M = [np.where((w > 0)[:, None], (Gj[1:] - Gj[:-1]) / w[None, :, None], 0.0) for Gj in G]
    m1, m2, m3, m4 = M[1], M[2], M[3], M[4]                     # [n, R, 3]
    vm = np.maximum(m2 - m1 ** 2, 0)
    c4m = np.maximum(m4 - 4 * m1 * m3 + 6 * m1 ** 2 * m2 - 3 * m1 ** 4, 0)
    sv = vm.sum(0)
    v[:, :3] = (w ** 2)[:, None] * sv
    e4[:, :3] = (w ** 4)[:, None] * (c4m.sum(0) + 3 * (sv ** 2 - (vm ** 2).sum(0)))
    return mean, v, e4
