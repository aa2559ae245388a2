#!/usr/bin/python3
"""A frame's kernels (match, balance, ... warp), Monte Carlo and adaptive from KERNELS.md alone.

Keeps KERNELS.md honest for a host in another language (its section 7).
Builds the programs from the INSTALLED kernel sources as section 1 assembles
them, plans what the page says a host plans itself, runs the kernels with
the argument lists and work sizes of section 5, and compares every result
bit for bit with the serial references that `kernel-abi-ref DIR`
(tests/kernel_abi/kernel_abi_ref.cpp, linked with the installed library)
wrote for the same inputs:
  swap plan   the pixel bits, front bits (the k-d split's rule and the view),
              level rectangles, offsets and display tables of section 3 "The
              swap plan", both layouts: equal plan_swap's;
  swap        simdvol_swap_stage stage by stage, and simdvol_swap_stages in
              runs of up to 7 stages, on that plan: swap_reference's level N;
  display     simdvol_display: display_reference's image;
  mc lists    sample offsets (adaptive.cl), ray lists (mc.cl):
              sample_offsets(), ray_segments();
  mc whole    simdvol_mc_whole, plain / exact / stratified x per-ray / shared
              keys, and its work counters: mc_whole_reference;
  allocation  simdvol_mc_alpha, then simdvol_mc_allocate: segment_alphas(),
              allocation_reference();
  mc sub      simdvol_mc_local with and without allocation into zeroed
              footprints: mc_sub_reference's footprints and counters;
  adaptive    simdvol_adaptive_whole at two thresholds: composite_adaptive;
  warp        the warp tables from section 5's formula (equal the library's,
              from output_to_intermediate), simdvol_warp: warp_to_output.
and the direct frame's stages before the swap (section 4, 1-6), the host's
share computed here from sections 3 and 5 and compared with the library's:
  layout      cell, block, strides, origins, pe_of_cell and the cells with
              halo; simdvol_layout, _layout_voxel (bit for bit
              layout_reference's), simdvol_gather (the volume);
  params      sv_shade_params' ka .. k2, spec_floor, grad_over, surface_g2,
              the struct sizes, shade_defines and classify_defines;
  shade       simdvol_shade16 (SV_RW from cx): shade() within section 8's
              1e-5 (|g| 1e-6 relative), channel 3 the value, zero tails;
              simdvol_shade_rows and simdvol_shade within 1e-6 of it;
  shade+cls   simdvol_classify16(_in_place) on it; simdvol_shade_classify16
              equal to shade16 + classify16, within 1e-5 of classify(), its
              _il form bit for bit the planar cells, both brick marks;
  tables      the reference's voxels in planar and interleaved voxel cells
              (voxels_to_cells), the resample address, pair and cell-bit
              tables, rect_off, sample_off;
  occupancy   simdvol_occupancy(_il) and simdvol_occupancy_reach (orders
              0-3) against the page's rule;
  lanes       simdvol_segment_order (kb, with_pe) against the page's rule;
  resample    per order 0-3 simdvol_resample_v8 within 1e-5 of
              resample_reference; _v8_il (lanes' order, skip) equal to it;
  local       simdvol_local on those samples within 1e-5 of
              footprints_reference(local_reference);
  fused       simdvol_resample_local_v8 within 1e-5 of it; _il with the
              matching's segments and the balanced bounds (kb), footprints
              zeroed by simdvol_zero_uncovered alone (on the rows of
              simdvol_match_rows_nolinks, geo and stepc made here), the
              lanes' order with PEs and skipping, and _ilc (order 1, cell
              bits): bit for bit the plain one;
and the match and balance stages (section 4, 4-5; section 5 match.cl, balance.cl), the host's
tables (geo, stepc, koff, the pair list, capacity, H) made here:
  match       simdvol_match_active from a brick reach: match_active_reference; rows, pe,
              scan, fill with and without links (_nolinks: --balance-sweeps 0), saved
              columns and stepped, wide and narrow link lists, 16-bit bounds or none, on
              row tables of junk (the rows of inactive PEs are not written), every
              placeholder a guarded 16-byte buffer: match_reference's seg_offset,
              segments, rects, loads (and counts, petot), the link lists, lofs and lbase
              of balance_links(); simdvol_zero_uncovered on NaN footprints: the page's
              rule;
  balance     simdvol_balance_round(16)(n) per sweep, axis and parity (the pairs in order
              and shuffled) on the fill's 16-bit bounds or 32-bit ones packed, then the
              unpack: balance_reference's bounds (before the unpack: the direct frame's
              deferred one), segments and loads, and the moves flags: the sweeps after
              which balance_reference changed.
Work-group sizes as section 1 says: the reqd_work_group_size kernels
(layout, match, balance) built and launched with WGS = 64 or the device's
smaller limit, simdvol_swap_stages in runs of no more stages than 2^m
work-items fit, the others in smaller groups (fit_work_group) where the
device or the kernel takes fewer than section 5 asks for; scripts/embed-check
runs it again under POCL_MAX_WORK_GROUP_SIZE=16.
Prints one line per stage (with the largest difference where a tolerance
applies); a disagreement names the case, the check and the first differing
value.

Usage: /usr/bin/python3 tests/kernel_abi/kernel_abi_check.py
         --kernels PREFIX/share/simdvol/kernels --cases DIR [-v]
(the system python: Debian's python3-pyopencl and python3-numpy).
Exit status 0 when everything agrees, 1 when something differs, 2 on an error.
"""
import argparse
import os
import pathlib
import sys

os.environ.setdefault("PYOPENCL_COMPILER_OUTPUT", "0")
import numpy as np  # noqa: E402
import pyopencl as cl  # noqa: E402
import pyopencl.cltypes  # noqa: E402,F401

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from cl_program import (WorkGroupLimits, fit_work_group, fixed_group_size,  # noqa: E402
                        pick_device, program_source, round_up)

LAYOUTS = ("cut-and-stack", "hierarchical")
# Section 1's local size of the reqd_work_group_size kernels (layout, match,
# balance), exactly: 64, or the largest power of two the device takes
# (Host.wgs). Host.run takes it as a local size (and a global one).
WGS = "WGS"
FUSED_MAX = 7  # simdvol_swap_stages: 1 <= m <= 7 stages a launch
FUSED_FIXED_LOCAL = 7168  # section 5: the host budgets la + lb + 7,168 bytes of local memory
SEG = np.dtype([("i", "<i4"), ("j", "<i4"), ("k0", "<i4"), ("k1", "<i4")])  # sv_segment
MC_OPTIONS = ("-cl-fp32-correctly-rounded-divide-sqrt",)  # section 1: every mc program
# (name, SHARED, EXACT, STRAT); kernel_abi_ref.cpp writes the sub_* of some of them
MC_VARIANTS = (("plain_ray", 0, 0, 0), ("plain_shared", 1, 0, 0), ("exact_ray", 0, 1, 0),
               ("exact_shared", 1, 1, 0), ("strat_ray", 0, 1, 1), ("strat_shared", 1, 1, 1))
THRESHOLDS = (0.95, 0.5)  # kernel_abi_ref.cpp's kThresholds
DTYPES = {"f32": np.float32, "i32": np.int32, "i64": np.int64, "stats": np.int64}


def i32(*xs):
    return tuple(np.int32(x) for x in xs)


def load(d, name, dtype=None):
    return np.fromfile(d / name, dtype or DTYPES[name.rsplit(".", 1)[1]])


def read_meta(d):
    return dict(line.split(" ", 1) for line in (d / "meta.txt").read_text().splitlines())


# ---------------------------------------------------------------- comparison
class Tally:
    """Per stage the checks that agreed; each disagreement printed at once."""

    def __init__(self, verbose):
        self.ok, self.failed, self.verbose, self.largest = {}, [], verbose, {}

    def same(self, stage, case, what, got, want, channels=1, zeros_alike=False):
        """Bit for bit: floats by their bits (+0 and -0 differ unless zeros_alike: section 8's
        "equal"), ints by value."""
        self.close(stage, case, what, got, want, None, channels=channels, zeros_alike=zeros_alike)

    def close(self, stage, case, what, got, want, tol, rel=False, channels=1, zeros_alike=False):
        """With tol: |got - want| <= tol (times max(1, |want|) where rel), NaN only with NaN."""
        g, w = np.ascontiguousarray(got).ravel(), np.ascontiguousarray(want).ravel()
        diff = None
        if g.size != w.size:
            diff = f"{g.size} values, the reference has {w.size}"
        else:
            if tol is not None:
                g64, w64 = g.astype(np.float64), w.astype(np.float64)
                lim = tol * (np.maximum(1.0, np.abs(w64)) if rel else 1.0)
                ok = (np.abs(g64 - w64) <= lim) | (np.isnan(g64) & np.isnan(w64))
                self.largest[stage] = max(self.largest.get(stage, 0.0),  # in tol's measure
                                          float(np.nanmax(np.abs(g64 - w64) * tol / lim,
                                                          initial=0.0)))
            elif zeros_alike and g.dtype == np.float32:
                ok = (bits(g) == bits(w)) | ((g == 0) & (w == 0))
            else:
                ok = bits(g) == bits(w)
            bad = np.flatnonzero(~ok)
            if bad.size:
                i = int(bad[0])
                at = f"[{i // channels}].{'rgba'[i % channels]}" if channels > 1 else f"[{i}]"
                diff = (f"{bad.size} of {g.size} values differ"
                        + (f" by more than {tol:g}{' x max(1, |ref|)' * rel}" if tol else "")
                        + f", the first {at}: {show(g[i])}, the reference {show(w[i])}")
        self.record(stage, case, what, diff)

    def text(self, stage, case, what, got, want):
        """Lists of tuples of strings, equal as text."""
        got, want = [tuple(map(str, x)) for x in got], [tuple(map(str, x)) for x in want]
        self.record(stage, case, what, None if got == want else f"{got}, the reference {want}")

    def record(self, stage, case, what, diff):
        if diff:
            self.failed.append(f"{case}: {what}: {diff}")
            print(f"kernel-abi-check: FAILED {case}: {what}: {diff}", flush=True)
        else:
            self.ok[stage] = self.ok.get(stage, 0) + 1
            if self.verbose:
                print(f"  {case}: {what}: equal", flush=True)


def bits(a):
    return a.view(np.uint32) if a.dtype == np.float32 else a.astype(np.int64)


def show(v):
    if isinstance(v, np.floating):
        return f"{float(v):.9g} (0x{int(np.float32(v).view(np.uint32)):08x})"
    return str(int(v))


# ---------------------------------------------------------------- programs, buffers, launches
class Host:
    def __init__(self, kdir):
        self.kdir = kdir
        self.dev = pick_device()
        self.ctx = cl.Context([self.dev])
        self.q = cl.CommandQueue(self.ctx)
        self.local_mem = self.dev.local_mem_size
        self.wgs = fixed_group_size(self.dev)
        self.fitted = {}  # kernel name -> (local size asked, local size launched)
        self.programs = {}

    def program(self, stage, defines=(), more=(), options=()):
        key = (stage, tuple(defines), tuple(more), tuple(options))
        if key not in self.programs:
            src = program_source(self.kdir, stage, defines, more)
            self.programs[key] = cl.Program(self.ctx, src).build(options=list(options))
        return self.programs[key]

    def layout_group(self):
        """Section 1's third program (layout, match, balance, swap; WGS = 64,
        or the device's smaller limit): the swap, display and warp kernels."""
        return self.program("layout", [("WGS", self.wgs)], ("match", "balance", "swap"))

    def mc(self, shared=0, exact=0, strat=0, alloc=0, lists=False):
        """mc.cl, always with its option; with no defines for the ray-list,
        alpha and allocate kernels (the host builds theirs with none)."""
        d = [] if lists else [("SHARED", shared), ("EXACT", exact), ("STRAT", strat),
                              ("DROP", 1), ("ALLOC", alloc), ("STATS", 1)]
        return self.program("mc", d, options=MC_OPTIONS)

    def adaptive(self):
        return self.program("adaptive")  # a program of its own: no defines, no options

    def buf(self, a):
        a = np.ascontiguousarray(a)
        if a.nbytes == 0:
            a = np.zeros(16, np.uint8)  # no empty buffers
        return cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=a)

    def zeros(self, nbytes):
        return self.buf(np.zeros(max(int(nbytes), 16), np.uint8))

    def empty(self, nbytes):
        return cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, max(int(nbytes), 16))

    def limits(self, kernel):
        return WorkGroupLimits(self.dev, kernel)

    def run(self, kernel, g, l, *args, exact=False):
        """Section 1: an explicit local size, each global size rounded up to
        it. A kernel declared with reqd_work_group_size takes exactly WGS (the
        local size WGS, asked for by name); with `exact` (simdvol_swap_stages'
        2^m) the local size must fit, else this refuses it as the library
        does; any other kernel takes a smaller group where the device or the
        kernel takes fewer work-items (fit_work_group)."""
        g, l = (g, l) if isinstance(g, tuple) else ((g,), (l,))
        reqd = tuple(kernel.get_work_group_info(
            cl.kernel_work_group_info.COMPILE_WORK_GROUP_SIZE, self.dev))
        name = kernel.function_name
        if any(reqd) != (l == (WGS,)):
            raise RuntimeError(f"{name}: reqd_work_group_size {reqd}, launched with local size "
                               f"{l} (the WGS kernels take WGS, the others a number)")
        if l == (WGS,):
            if reqd[0] != self.wgs:
                raise RuntimeError(f"{name}: built with WGS {reqd[0]}, not the device's {self.wgs}")
            g, l = tuple(self.wgs if a == WGS else a for a in g), (self.wgs,)
        limits = self.limits(kernel)
        if not limits.fits(l):
            if exact or any(reqd):
                raise RuntimeError(f"{name}: needs work-groups of {' x '.join(map(str, l))} "
                                   f"work-items, more than this device takes for it "
                                   f"({limits.describe()})")
            asked = l
            l = fit_work_group(l, limits)
            # (the global size rounded up to the size asked for first: section 1)
            g = tuple(round_up(max(a, 1), b) for a, b in zip(g, asked))
            self.fitted[name] = (asked, l)
        kernel.set_args(*args)
        rounded = tuple(round_up(max(a, 1), b) for a, b in zip(g, l))
        cl.enqueue_nd_range_kernel(self.q, kernel, rounded, l)

    def read(self, b, dtype, n):
        out = np.empty(n, dtype)
        if n:
            cl.enqueue_copy(self.q, out, b)
        self.q.finish()
        return out


# ---------------------------------------------------------------- the swap plan (section 3)
def log2_exact(n):
    b = n.bit_length() - 1
    if 1 << b != n:
        raise RuntimeError(f"{n} is not a power of two")
    return b


def kd_bit_axis(dims, P):
    """kd_split's bit_axis (pe_array.hpp, which section 3 names): bit N-1 the
    first split; each split halves the axis of largest extent
    ceil(n_a / splits_a), ties x, then y, then z."""
    N = log2_exact(P)
    axis, splits = [0] * N, [1, 1, 1]
    for b in range(N - 1, -1, -1):
        ext = [-(-dims[a] // splits[a]) for a in range(3)]
        axis[b] = max(range(3), key=lambda a: (ext[a], -a))
        splits[axis[b]] *= 2
    return axis


def swap_front(view, dims, P):
    """front[k] = 0 where sv_view.step[a][2] >= 0, else 1, a = bit_axis[k]."""
    step2 = [int(view[4 + 4 * a + 2]) for a in range(3)]  # sv_view: origin[4], step[3][4], ...
    return [0 if step2[a] >= 0 else 1 for a in kd_bit_axis(dims, P)]


def pixel_bits(P, width, height, layout):
    """The PE grid is 2^bx x 2^by, bx = ceil(N/2), by = floor(N/2); the stages
    alternate x, y, ... from x while both axes have bits left, then take the
    rest of the other; the j-th stage of axis a has level j (cut-and-stack)
    or B_a - 1 - j (hierarchical), B_a = max(ceil(log2 extent_a), bits of a)."""
    N = log2_exact(P)
    nb = [(N + 1) // 2, N // 2]
    B = [max((width - 1).bit_length(), nb[0]), max((height - 1).bit_length(), nb[1])]
    used, stages, nxt = [0, 0], [], 0
    while len(stages) < N:
        a = nxt if used[nxt] < nb[nxt] else 1 - nxt
        stages.append((a, used[a] if layout == "cut-and-stack" else B[a] - 1 - used[a]))
        used[a] += 1
        nxt = 1 - a
    return stages, B


def plan_swap(rects, width, height, layout):
    """Per level L = 0 .. N the rectangles int8 (x0, y0, nx, ny, sx, sy, lx,
    ly) of the P PEs and the offsets (P + 1); the display tables xpe, ype."""
    P = len(rects)
    stages, B = pixel_bits(P, width, height, layout)
    r = rects.astype(np.int64)
    some = (r[:, 2] > 0) & (r[:, 3] > 0)
    big = np.int64(1) << 40  # an empty box: lo = big, hi = -big
    lo = np.where(some[:, None], r[:, :2], big)
    hi = np.where(some[:, None], r[:, :2] + r[:, 2:], -big)
    pe = np.arange(P, dtype=np.int64)
    # Level 0 is the footprint buffer itself: (i0, j0, w, h, 1, 1, 0, 0).
    held = [np.concatenate([r, np.tile([1, 1, 0, 0], (P, 1))], axis=1)]
    for L in range(1, len(stages) + 1):
        # G = the bounding box of the non-empty footprints of the PEs p' with p' >> L == p >> L
        glo = np.repeat(lo.reshape(-1, 1 << L, 2).min(1), 1 << L, axis=0)
        ghi = np.repeat(hi.reshape(-1, 1 << L, 2).max(1), 1 << L, axis=0)
        h8, first, count = np.zeros((P, 8), np.int64), [], []
        for a in range(2):
            # j = the stages k < L on axis a; v = the sum over them of ((p >> k) & 1) << level_k
            ks = [k for k in range(L) if stages[k][0] == a]
            v = sum((((pe >> k) & 1) << stages[k][1]) for k in ks) + np.zeros(P, np.int64)
            j = len(ks)
            if layout == "cut-and-stack":  # s = 2^j: the x >= G.x0, x = v (mod s), below G.x1
                s, l = 1 << j, j
                f = glo[:, a] + (v - glo[:, a]) % s
                n = np.where(f < ghi[:, a], (ghi[:, a] - 1 - f) // s + 1, 0)
            else:  # s = 1: [v, v + 2^(B - j)) clipped to [G.x0, G.x1)
                s, l = 1, 0
                f = np.maximum(glo[:, a], v)
                n = np.maximum(np.minimum(ghi[:, a], v + (1 << (B[a] - j))) - f, 0)
            first.append(f)
            count.append(n)
            h8[:, 4 + a], h8[:, 6 + a] = s, l
        full = count[0] * count[1] > 0  # else empty: (0, 0, 0, 0, sx, sy, lx, ly)
        for c, vals in enumerate(first + count):
            h8[:, c] = np.where(full, vals, 0)
        held.append(h8)
    off = [np.concatenate([[0], np.cumsum(h[:, 2] * h[:, 3])]) for h in held]  # exclusive prefix
    # Display: xpe[x] = the sum over the x stages k of ((x >> level_k) & 1) << k; ype likewise.
    xpe, ype = np.zeros(width, np.int64), np.zeros(height, np.int64)
    for k, (a, level) in enumerate(stages):
        t = xpe if a == 0 else ype
        t |= ((np.arange(t.size) >> level) & 1) << k
    return stages, [h.astype(np.int32) for h in held], [o.astype(np.int32) for o in off], xpe, ype


# ---------------------------------------------------------------- swap and display (section 5)
def local_bytes(off, P, k0, m):
    """simdvol_swap_stages' la: 16 bytes x the most pixels, over its work-groups
    (PEs base | (lid << k0)) and the odd s, 0 < s < m, that a group holds at
    level k0 + s; lb the same over the even s."""
    p = np.arange(P)
    group = (p & ((1 << k0) - 1)) | ((p >> (k0 + m)) << k0)
    la = lb = 0
    for s in range(1, m):
        sizes = np.diff(off[k0 + s].astype(np.int64))
        b = 16 * int(np.bincount(group, weights=sizes, minlength=P >> m).max())
        la, lb = (max(la, b), lb) if s & 1 else (la, max(lb, b))
    return la, lb


def run_swap(host, held, off, front, foot, fused):
    """Levels 0 .. N on the device: simdvol_swap_stage per stage, or (fused)
    simdvol_swap_stages in runs of up to 7 stages, fewer where local memory
    is short or the device takes fewer than 2^m work-items in a group for it
    (section 1: its local size is its contract). Returns level N's buffer,
    rectangles, offsets and pixels."""
    prog = host.layout_group()
    most = FUSED_MAX  # (0 where the device takes no 2 work-items: stage by stage then)
    while most > 0 and not host.limits(prog.simdvol_swap_stages).fits((1 << most,)):
        most -= 1
    P, N = held[0].shape[0], len(front)
    R, O = [host.buf(h) for h in held], [host.buf(o) for o in off]
    lv = [host.buf(foot)] + [host.empty(16 * int(o[-1])) for o in off[1:]]
    k = 0
    while k < N:
        m = min(most, N - k) if fused and most else 1
        while m > 1 and sum(local_bytes(off, P, k, m)) + FUSED_FIXED_LOCAL > host.local_mem:
            m -= 1
        # simdvol_swap_stage (in, in_rect, in_off, out, out_rect, out_off, pes, k, front): P / 64
        if not fused or not most:
            host.run(prog.simdvol_swap_stage, P, 64, lv[k], R[k], O[k], lv[k + 1], R[k + 1],
                     O[k + 1], *i32(P, k, front[k]))
        else:  # P / 2^m; r_s, o_s past m repeat level k + m; bit s of fronts = front[k + s]
            la, lb = local_bytes(off, P, k, m)
            host.run(prog.simdvol_swap_stages, P, 1 << m, lv[k], lv[k + m],
                     cl.LocalMemory(max(la, 16)), cl.LocalMemory(max(lb, 16)),
                     *[R[k + min(s, m)] for s in range(8)], *[O[k + min(s, m)] for s in range(8)],
                     *i32(k, m, sum(front[k + s] << s for s in range(m))), exact=True)
        k += m
    return lv[N], R[N], O[N], host.read(lv[N], np.float32, 4 * int(off[N][-1]))


def check_swap(host, tally, d):
    M = read_meta(d)
    P, width, height = int(M["pes"]), int(M["width"]), int(M["height"])
    dims = [int(x) for x in M["dims"].split()]
    rects = load(d, "rects.bin", np.int32).reshape(P, 4)
    front = swap_front(load(d, "view.bin", np.int64), dims, P)
    tally.same("plan", d.name, "k-d split bit_axis", np.array(kd_bit_axis(dims, P)),
               load(d, "bit_axis.i32"))
    for layout in LAYOUTS:
        stages, held, off, xpe, ype = plan_swap(rects, width, height, layout)
        case, N = f"{d.name} {layout}", len(stages)
        lib_held = load(d, f"{layout}.held.i32").reshape(N + 1, P, 8)
        lib_off = load(d, f"{layout}.off.i64").reshape(N + 1, P + 1)
        tally.same("plan", case, "front", np.array(front), load(d, f"{layout}.front.i32"))
        tally.same("plan", case, "pixel bits (axis, level)", np.array(stages, np.int64),
                   load(d, f"{layout}.bits.i32"))
        for L in range(N + 1):
            tally.same("plan", case, f"level {L} rectangles", held[L], lib_held[L])
            tally.same("plan", case, f"level {L} offsets", off[L], lib_off[L])
        tally.same("plan", case, "xpe", xpe, load(d, f"{layout}.xpe.i64"))
        tally.same("plan", case, "ype", ype, load(d, f"{layout}.ype.i64"))
        for fused in (False, True):
            last, rect, offs, pixels = run_swap(host, held, off, front, load(d, "foot.f32"), fused)
            how = "simdvol_swap_stages runs" if fused else "simdvol_swap_stage per stage"
            tally.same("swap", case, f"level {N} ({how})", pixels, load(d, f"{layout}.last.f32"), 4)
        # (last, rect, off, xpe, ype, width, height, image): (width, height) / (64, 4)
        img = host.empty(16 * width * height)
        host.run(host.layout_group().simdvol_display, (width, height), (64, 4), last, rect, offs,
                 host.buf(xpe.astype(np.int32)), host.buf(ype.astype(np.int32)),
                 *i32(width, height), img)
        tally.same("display", case, "image", host.read(img, np.float32, 4 * width * height),
                   load(d, f"{layout}.image.f32"), 4)


# ---------------------------------------------------------------- Monte Carlo, adaptive (4, 5)
def check_mc(host, tally, d):
    M, case = read_meta(d), d.name
    W, H, P, nseg = int(M["width"]), int(M["height"]), int(M["pes"]), int(M["nseg"])
    npx, walks, seed = W * H, int(M["walks"]), np.uint64(int(M["seed"]))
    samples = load(d, "samples.f32")
    segs, seg_off = host.buf(load(d, "segs.bin", SEG)), host.buf(load(d, "seg_offset.i32"))
    smp, A, mc = host.buf(samples), host.adaptive(), host.mc(lists=True)

    # Sample offsets: per-PE totals, their exclusive scan (1 / 1), per PE its segments' offsets.
    pe_total, total, soff = host.empty(8 * P), host.empty(8), host.empty(4 * (nseg + 1))
    host.run(A.simdvol_sample_pe_count, P, 64, segs, seg_off, np.int32(P), pe_total)
    host.run(A.simdvol_sample_pe_scan, 1, 1, pe_total, np.int32(P), total)
    host.run(A.simdvol_sample_offsets, P, 64, segs, seg_off, np.int32(P), pe_total, soff)
    tally.same("lists", case, "sample offsets", host.read(soff, np.int32, nseg + 1),
               load(d, "sample_off.i32"))
    tally.same("lists", case, "sample total", host.read(total, np.int64, 1), [samples.size // 4])

    # Ray lists: count (counts zeroed), scan (n = npx; zeroes counts), fill (cursor = counts), sort.
    counts, ray_off, items = host.zeros(4 * npx), host.empty(4 * (npx + 1)), host.empty(4 * nseg)
    host.run(mc.simdvol_mc_ray_count, nseg, 64, segs, *i32(nseg, W, H), counts)
    host.run(mc.simdvol_mc_ray_scan, 1, 1, counts, np.int32(npx), ray_off)
    host.run(mc.simdvol_mc_ray_fill, nseg, 64, segs, *i32(nseg, W, H), ray_off, counts, items)
    host.run(mc.simdvol_mc_ray_sort, npx, 64, segs, np.int32(npx), ray_off, items)
    roff = host.read(ray_off, np.int32, npx + 1)
    tally.same("lists", case, "ray offsets", roff, load(d, "ray_off.i32"))
    tally.same("lists", case, "ray items", host.read(items, np.int32, int(roff[-1])),
               load(d, "ray_items.i32"))

    def counters(b, n):  # an int4 (walks, draws, skipped, fallback) per work-item, summed
        return host.read(b, np.int32, 4 * n).reshape(n, 4).astype(np.int64).sum(0)

    # Whole ray: every pixel written (no zero fill), keys q = j * width + i, the seed as it is.
    img = host.empty(16 * npx)
    for name, shared, exact, strat in MC_VARIANTS:
        st = host.empty(16 * npx)
        host.run(host.mc(shared, exact, strat).simdvol_mc_whole, npx, 64, segs, soff, smp, ray_off,
                 items, *i32(W, npx, walks), seed, img, st)
        tally.same("whole", case, f"mc whole {name} image", host.read(img, np.float32, 4 * npx),
                   load(d, f"whole_{name}.f32"), 4)
        tally.same("whole", case, f"mc whole {name} counters", counters(st, npx),
                   load(d, f"whole_{name}.stats"))

    # Allocation: simdvol_mc_alpha (it zeroes walks) first, then simdvol_mc_allocate (budget =
    # walks per ray), which writes only the rays with some alpha > 0.
    alpha, alloc = host.empty(4 * nseg), host.empty(4 * nseg)
    host.run(mc.simdvol_mc_alpha, nseg, 64, segs, np.int32(nseg), soff, smp, alpha, alloc)
    host.run(mc.simdvol_mc_allocate, npx, 64, ray_off, items, np.int32(npx), alpha,
             np.int32(walks), alloc)
    tally.same("alloc", case, "segment alphas", host.read(alpha, np.float32, nseg),
               load(d, "seg_alpha.f32"))
    tally.same("alloc", case, "walks per segment", host.read(alloc, np.int32, nseg),
               load(d, "alloc.i32"))

    # Per sub-ray: footprints zeroed beforehand, rect_off int[P], keys j * width + i of the grid;
    # with ALLOC 1 the walks from alloc, with 0 alloc not read (any buffer).
    rect_off = load(d, "rect_off.i32")
    rects, b_rect_off = host.buf(load(d, "rects.bin", np.int32)), host.buf(rect_off[:P])
    for name, shared, exact, strat in MC_VARIANTS:
        for with_alloc in (0, 1):
            base = f"sub_{name}" + ("_alloc" if with_alloc else "")
            if not (d / f"{base}.stats").exists():
                continue
            foot, st = host.zeros(16 * rect_off[P]), host.empty(16 * nseg)
            host.run(host.mc(shared, exact, strat, with_alloc).simdvol_mc_local, nseg, 64, segs,
                     np.int32(nseg), seg_off, np.int32(log2_exact(P)), soff, smp, *i32(W, walks),
                     alloc if with_alloc else host.empty(16), seed, rects, b_rect_off, foot, st)
            tally.same("sub", case, f"mc {base} footprints",
                       host.read(foot, np.float32, 4 * rect_off[P]), load(d, f"{base}.foot.f32"), 4)
            tally.same("sub", case, f"mc {base} counters", counters(st, nseg),
                       load(d, f"{base}.stats"))

    # Adaptive: on the mc program's ray lists; every pixel written; the threshold as a float.
    for t in THRESHOLDS:
        host.run(A.simdvol_adaptive_whole, npx, 64, segs, soff, smp, ray_off, items,
                 np.int32(npx), np.float32(t), img)
        tally.same("adaptive", case, f"adaptive {t:g}", host.read(img, np.float32, 4 * npx),
                   load(d, f"adaptive_{t:g}.f32"), 4)

    if M["sampling"] == "voxel":
        check_warp(host, tally, d, M)


# ---------------------------------------------------------------- warp (section 5, simdvol_warp)
def warp_table(n_out, n_min, span, n_in, step=1.0):
    """f = ((x + 0.5 - 0.5 n_out) / s) / step + 0.5 n_in - 0.5, s = min(ow, oh) / span,
    in double: floor(f) and (float)(f - floor(f)), rounded once."""
    f = ((np.arange(n_out, dtype=np.float64) + 0.5 - 0.5 * n_out) / (n_min / span)) / step
    f += 0.5 * n_in - 0.5
    fl = np.floor(f)
    return fl.astype(np.int32), (f - fl).astype(np.float32)


def check_warp(host, tally, d, M):
    W, H, ow, oh = (int(M[k]) for k in ("width", "height", "ow", "oh"))
    # span: the longest side, or with --fit diagonal the diagonal, in units of the smallest
    # spacing; step 1 with voxel sampling
    ext = np.array([float(x) for x in M["dims"].split()]) * [float(x) for x in M["spacing"].split()]
    ext /= min(float(x) for x in M["spacing"].split())
    span = float(np.sqrt((ext * ext).sum())) if M["framing"] == "diagonal" else float(ext.max())
    tabs = warp_table(ow, min(ow, oh), span, W) + warp_table(oh, min(ow, oh), span, H)
    for name, t in zip(("ix.i32", "tx.f32", "iy.i32", "ty.f32"), tabs):
        tally.same("warp", d.name, f"warp table {name[:2]}", t, load(d, "warp_" + name))
    out = host.empty(16 * ow * oh)
    host.run(host.layout_group().simdvol_warp, (ow, oh), (64, 4), host.buf(load(d, "warp_in.f32")),
             *i32(W, H), *[host.buf(t) for t in tabs], *i32(ow, oh), out)
    tally.same("warp", d.name, f"warp {W}x{H} -> {ow}x{oh}",
               host.read(out, np.float32, 4 * ow * oh), load(d, "warp_ref.f32"), 4)


# ---------------------------------------------------------------- direct frame (sections 3-5)
ORDERS = (0, 1, 2, 3)
CHUNK = 64  # shade16 / classify16: L0 = min(64, 2^k >= chunks), L1 = max(1, min(64 / L0, P))
NAN = np.float32(np.nan)


def int4(x, y=0, z=0, w=0):
    return cl.cltypes.make_int4(*(int(v) for v in (x, y, z, w)))


def pow2_at_least(n):
    return 1 << max(int(n) - 1, 0).bit_length()


def shared_define(kdir, name):
    """A constant of simdvol_shared.h (SV_ORDER_BLOCK, SV_BRICK_LOG2)."""
    for line in (kdir / "simdvol_shared.h").read_text().splitlines():
        w = line.split()
        if w[:2] == ["#define", name]:
            return int(w[2])
    raise RuntimeError(f"simdvol_shared.h: no {name}")


class Cells:
    """Section 3 "Cells with halo" / "Voxel cells" and the per-PE tables, from
    kd_split's rule: c_a = ceil(n_a / splits_a), origin index_a * c_a, and
    (pe_array.hpp, which the page names) the PE bits of an axis, read from the
    highest to the lowest, spell the cell's index along it."""

    def __init__(self, dims, P, halo=1):
        N = log2_exact(P)
        self.dims, self.P, self.h = np.array(dims), P, halo
        self.bit_axis = kd_bit_axis(dims, P)
        self.pos = [[b for b in range(N) if self.bit_axis[b] == a] for a in range(3)]  # low first
        self.splits = np.array([1 << len(p) for p in self.pos])
        self.cell = -(-self.dims // self.splits)
        self.block = self.cell + 2 * halo
        self.stride = round_up(np.prod(self.block), 16)  # bx by bz rounded up to 16
        self.vstride = round_up(np.prod(self.cell), 16)  # cx cy cz rounded up to 16
        pe = np.arange(P)
        self.cidx = np.stack([self.pe_bits(a, pe, inverse=True) for a in range(3)], 1)
        self.origins = self.cidx * self.cell
        self.origins4, self.cidx4 = (np.c_[t, 0 * t[:, :1]].astype(np.int32)  # int4, w = 0
                                     for t in (self.origins, self.cidx))
        self.pe_of_cell = np.zeros(P, np.int32)  # (iz sy + iy) sx + ix
        s = self.splits
        self.pe_of_cell[(self.cidx[:, 2] * s[1] + self.cidx[:, 1]) * s[0] + self.cidx[:, 0]] = pe

    def pe_bits(self, a, ci, inverse=False):
        """The PE index bits that cell index ci along axis a stands for (inverse: the cell index
        along a of PE ci)."""
        pairs = [(b, k) if inverse else (k, b) for k, b in enumerate(self.pos[a])]
        return sum(((ci >> src) & 1) << dst for src, dst in pairs) + 0 * ci

    def args(self, stage):
        """common.cl's geometry arguments (section 2): dims, cell (w = halo), block (w = stride),
        splits; cell0 = (cx, cy, cz, 0) (match.cl's `cell`, the voxel cells')."""
        d, c, b = self.dims, self.cell, self.block
        return {"dims": int4(*d), "cell": int4(*c, self.h), "block": int4(*b, self.stride),
                "splits": int4(*self.splits), "cell0": int4(*c)}[stage]

    def layout(self, vol):
        """float[P * stride]: position l in [-h, c + h) at ((lz+h) by + ly+h) bx + lx+h of PE p's
        block, the volume value at clamp(origin + l, 0, n - 1); the tail zero."""
        out = np.zeros((self.P, self.stride), np.float32)
        r = [np.arange(-self.h, c + self.h) for c in self.cell]
        for p, o in enumerate(self.origins):
            x, y, z = (np.clip(o[a] + r[a], 0, self.dims[a] - 1) for a in range(3))
            out[p, :np.prod(self.block)] = vol[np.ix_(z, y, x)].ravel()
        return out.ravel()

    def voxel_index(self):
        """Per (PE, position e = (lz cy + ly) cx + lx) of the cells' interiors: the flat voxel
        at the clamped position (padding edge-replicated) and whether it is inside."""
        c, n = self.cell, self.dims
        lz, ly, lx = np.meshgrid(*(np.arange(c[a]) for a in (2, 1, 0)), indexing="ij")
        g = [self.origins[:, a, None] + l.ravel()[None] for a, l in enumerate((lx, ly, lz))]
        inside = (g[0] < n[0]) & (g[1] < n[1]) & (g[2] < n[2])
        g = [np.minimum(g[a], n[a] - 1) for a in range(3)]
        return (g[2] * n[1] + g[1]) * n[0] + g[0], inside

    def to_cells(self, flat4, interleaved):
        """Voxel cells: float[P * 4 * vstride], planar (c vstride + e) or interleaved (4 e + c)
        within PE p's block from p 4 vstride; tails zero."""
        idx, _ = self.voxel_index()
        out = np.zeros((self.P, self.vstride, 4), np.float32)
        out[:, :idx.shape[1]] = flat4.reshape(-1, 4)[idx]
        return (out if interleaved else out.transpose(0, 2, 1)).ravel()

    def planes(self, cells, interleaved=False):
        """(P, vstride, 4) from voxel cells."""
        v = cells.reshape(self.P, self.vstride, 4) if interleaved else \
            cells.reshape(self.P, 4, self.vstride).transpose(0, 2, 1)
        return np.ascontiguousarray(v)

    def gather(self, cells, interleaved=False):
        """The in-volume voxels of voxel cells, flat (nz ny nx, 4)."""
        idx, inside = self.voxel_index()
        out = np.zeros((int(np.prod(self.dims)), 4), np.float32)
        out[idx[inside]] = self.planes(cells, interleaved)[:, :idx.shape[1]][inside]
        return out

    def table(self, interleaved):
        """Section 3 "Resample address table": table[g] of axis a = the PE bits of g's cell times
        the PE block (4 vstride floats) + the local coordinate times its stride (1, cx, cx cy;
        4 times that interleaved); cs = vstride planar, 1 interleaved."""
        t, unit = [], 4 if interleaved else 1
        st = [unit, unit * self.cell[0], unit * self.cell[0] * self.cell[1]]
        for a in range(3):
            g = np.arange(self.dims[a])
            t.append(self.pe_bits(a, g // self.cell[a]) * 4 * self.vstride
                     + (g % self.cell[a]) * st[a])
        return np.concatenate(t).astype(np.int32), (1 if interleaved else self.vstride), st


def pair_table(t, dims):
    """Section 3 "Resample pair table": per axis n + 2 longs, entry f + 1 (f = -1 .. n) = table at
    clamp(f) in the low 32 bits, at clamp(f + 1) in the high 32 bits."""
    out, base = [], 0
    for n in dims:
        f = np.arange(-1, n + 1)
        lo = t[base + np.clip(f, 0, n - 1)].astype(np.uint32).astype(np.uint64)
        hi = t[base + np.clip(f + 1, 0, n - 1)].astype(np.uint32).astype(np.uint64)
        out.append((lo | (hi << np.uint64(32))).view(np.int64))
        base += n
    return np.concatenate(out)


def cell_bits(t, dims):
    """Section 3 "Cell bits": per axis a shift s with at most 32 cells ((n - 1) >> s < 32) and
    t[g] = bits[g >> s] + (g & (2^s - 1)) stride. Which s and stride the page does not say; the
    library's (host/cl/local.cpp, resample_cell_bits): the largest s <= min(30, bit length of n)
    that holds, stride = t[1] - t[0] (0 where n = 1 or s = 0). 104 ints: bits x, y, z (32 each,
    0 past the last cell), s x y z, strides x y z, 0, 0; none where an axis has no such s."""
    bits, shifts, strides, base = [], [], [], 0
    for n in dims:
        ta, g = t[base:base + n].astype(np.int64), np.arange(n)
        for s in range(min(30, n.bit_length()), -1, -1):
            if (n - 1) >> s >= 32:
                return np.zeros(0, np.int32)
            st = int(ta[1] - ta[0]) if n >= 2 and s > 0 else 0
            if (ta == ta[(g >> s) << s] + (g & ((1 << s) - 1)) * st).all():
                bits.append(np.pad(ta[::1 << s], (0, 32 - len(ta[::1 << s]))))
                shifts.append(s)
                strides.append(st)
                break
        base += n
    return np.concatenate(bits + [shifts, strides, [0, 0]]).astype(np.int32)


def shade_params_check(tally, case, sp, M):
    """Section 2's sv_shade_params fields that the page or shade.hpp give rules for, against
    the library's struct: grad_scale (min spacing / spacing, ShadeFrame), ka .. k2, enabled,
    spec_floor (specular_floor: 2^(-100/n), at least FLT_MIN, 0 for n = 0), grad_over (range
    spans 1e19 or more), surface_g2 (surface_threshold). light, halfway, depth_dir and
    depth_offset have no rule on the page: the struct is make_shade_frame's."""
    f, i = sp.view(np.float32), sp.view(np.int32)
    s = np.array([float(x) for x in M["spacing"].split()])
    tally.same("params", case, "sv_shade_params grad_scale", f[12:15], np.float32(s.min() / s))
    lo, hi = (float(x) for x in M["range"].split())
    n = float(M["shininess"])
    floor = 0.0 if n == 0 else max(2.0 ** (-100.0 / n), float(np.finfo(np.float32).tiny))
    span = min(max(hi - lo, 1e-10), 1.0) if np.isfinite(hi - lo) else 1.0
    want = [float(x) for x in M["ka_kd_ks"].split()] + [n] + [float(x) for x in M["k1_k2"].split()]
    tally.same("params", case, "sv_shade_params ka kd ks shininess k1 k2", f[17:23],
               np.float32(want))
    tally.same("params", case, "sv_shade_params enabled, grad_over", i[[23, 25]],
               [1, int(hi - lo >= 1e19)])
    tally.same("params", case, "sv_shade_params spec_floor", f[24:25], [np.float32(floor)])
    tally.same("params", case, "sv_shade_params surface_g2", f[26:27],
               [np.float32((1e-6 * span) ** 2)])


def classify_defines(cp):
    """Section 5 classify.cl: SV_KIND, SV_STEP_ONE, then SV_NMAT (mixture) or the
    five ramps' counts SV_NK_* (transfer), from the sv_classify_params bytes."""
    i = cp.view(np.int32)
    # SV_STEP_ONE: defined (1) only where step_is_one; classify.cl tests it with #ifdef, so a
    # "SV_STEP_ONE 0" would take every step as 1 (the page: "= 1 when opacity_step == 1").
    d = [("SV_KIND", i[0])] + ([("SV_STEP_ONE", 1)] if i[3] else [])
    if i[0] == 0:
        return d + [("SV_NMAT", i[2])]
    ramps = ("DENSITY", "GRADIENT", "RED", "GREEN", "BLUE")
    return d + [(f"SV_NK_{r}", i[(672 + 272 * k) // 4]) for k, r in enumerate(ramps)]


def sv_rw(cx):
    """shade16's SV_RW from cx: 16 (a multiple of 16), 8, 4, else 1."""
    return 16 if cx % 16 == 0 else cx if cx in (8, 4) else 1


def chunk_run(host, kernel, P, vstride, *args):
    """2-D (vstride/16, P) / (L0, L1), L0 = min(64, 2^k >= vstride/16),
    L1 = max(1, min(64/L0, P))."""
    l0 = min(CHUNK, pow2_at_least(vstride // 16))
    host.run(kernel, (vstride // 16, P), (l0, max(1, min(CHUNK // l0, P))), *args)


def occupancy(flat4, dims, brick):
    """uint per 4^3 brick (x fastest): 1 where a voxel of it has a channel that is not +-0."""
    nb = -(-np.array(dims) // brick)
    v = (flat4.reshape(dims[2], dims[1], dims[0], 4) != 0).any(3)
    occ = np.zeros(nb[::-1], np.uint32)
    z, y, x = np.nonzero(v)
    occ[z // brick, y // brick, x // brick] = 1
    return occ.ravel(), nb


def reach(occ, nb, order):
    """simdvol_occupancy_reach: OR of occ over bricks b - lo .. b + hi per axis (lo = 1 for
    orders 2, 3, else 0; hi = 1), bricks past the edges none."""
    lo, r = (1 if order >= 2 else 0), occ.reshape(nb[::-1]).astype(bool)
    for ax in range(3):
        p = np.pad(r, [(lo, 1) if k == ax else (0, 0) for k in range(3)])
        r = np.logical_or.reduce([np.take(p, np.arange(r.shape[ax]) + k, axis=ax)
                                  for k in range(lo + 2)])
    return r.ravel().astype(np.uint8)


def match_geo(view, cell):
    """Section 5 match.cl `geo` (20 floats, double then rounded) and `stepc` (9 longs)."""
    o = view[0:3].astype(np.float64) / 2.0 ** 32
    Mv = view[4:16].reshape(3, 4)[:, :3]
    N = np.linalg.inv(Mv.astype(np.float64) / 2.0 ** 32)
    c = np.array(cell, np.float64)
    geo = np.zeros(20)
    geo[0:2] = (N @ (c / 2 - o))[:2]
    u = np.stack([N[0] * c, N[1] * c], 1)  # u_a = (u_a.i, u_a.j)
    geo[2:5], geo[5:8] = u[:, 0], u[:, 1]
    for a in range(3):
        L = np.hypot(*u[a])
        if L <= 1e-9:
            continue
        n = np.array([-u[a, 1], u[a, 0]]) / L
        if abs(n[0]) < 1e-6:
            continue
        geo[8 + a], geo[11 + a] = n
        geo[14 + a] = 0.05 + 0.5 * sum(abs(n @ u[b]) for b in range(3) if b != a)
    stepc = []
    for a in range(3):
        s, d = int(Mv[a, 0]), int(Mv[a, 2])
        if d == 0:
            stepc += [1, 0, 0]
        else:
            m, delta = abs(d), (-s if d > 0 else s)
            stepc += [m, delta // m, delta % m]  # floor division: 0 <= dr < m
    return geo.astype(np.float32), np.array(stepc, np.int64)


def segment_order(segs, seg_off, kb, block, with_pe):
    """simdvol_segment_order: per block of SV_ORDER_BLOCK positions, cut at the PEs' boundaries,
    a stable sort by min(k1 - k0, 63), longest first; with_pe: then the PE of position 8 w."""
    n = len(segs)
    length = np.minimum((kb[:, 1] - kb[:, 0]) if kb is not None else segs["k1"] - segs["k0"], 63)
    pe = np.searchsorted(seg_off, np.arange(n), side="right") - 1
    order = []
    for b0 in range(0, n, block):
        pos = np.arange(b0, min(b0 + block, n))
        for p in np.unique(pe[pos]):
            q = pos[pe[pos] == p]
            order.append(q[np.argsort(-length[q], kind="stable")])
    order = np.concatenate(order) if order else np.zeros(0, np.int64)
    if with_pe:
        order = np.concatenate([order, pe[np.arange(0, n, 8)]])
    return order.astype(np.int32)


def check_direct(host, tally, d):
    """Layout, shade, shade + classify (planar, interleaved, marks), the brick occupancy and reach,
    the resample tables, zero_uncovered (on the rows of simdvol_match_rows_nolinks), the lanes'
    order, and per order the resample, local and fused resample + local kernels."""
    M, case, kd = read_meta(d), d.name, host.kdir
    P, dims, nseg = int(M["pes"]), [int(x) for x in M["dims"].split()], int(M["nseg"])
    g, log2p = Cells(dims, P), np.int32(log2_exact(P))
    view, vol = load(d, "view.bin", np.int64), load(d, "volume.f32")
    # Section 3: the cell geometry and the per-PE tables against the library's.
    tally.same("layout", case, "cell, block, halo, stride, vstride",
               np.r_[g.cell, g.block, g.h, g.stride, g.vstride],
               [int(x) for x in (M["cell"] + " " + M["block"]).split()]
               + [int(M[k]) for k in ("halo", "cell_stride", "vstride")])
    tally.same("layout", case, "origins", g.origins4, load(d, "origins.i32"))
    tally.same("layout", case, "pe_of_cell", g.pe_of_cell, load(d, "pe_of_cell.i32"))
    cells_ref = load(d, "cells.f32")
    tally.same("layout", case, "cells with halo (Python)", g.layout(vol.reshape(dims[::-1])),
               cells_ref)
    # Layout group: simdvol_layout, sy sz by bz / 64 (volume, cells, origins, pe_of_cell, dims,
    # cell, block, splits); simdvol_layout_voxel, P stride / 64; simdvol_gather, P cy cz / 64.
    L = host.layout_group()
    b_vol, b_org = host.buf(vol), host.buf(g.origins4)
    b_poc, n_cells = host.buf(g.pe_of_cell), P * g.stride
    geo_args = [g.args(k) for k in ("dims", "cell", "block")]
    cells = host.buf(np.full(n_cells, NAN))
    host.run(L.simdvol_layout, int(g.splits[1] * g.splits[2] * g.block[1] * g.block[2]), WGS,
             b_vol, cells, b_org, b_poc, *geo_args, g.args("splits"))
    tally.same("layout", case, "simdvol_layout", host.read(cells, np.float32, n_cells), cells_ref)
    cells_v = host.buf(np.full(n_cells, NAN))
    host.run(L.simdvol_layout_voxel, n_cells, WGS, b_vol, cells_v, b_org, *geo_args, np.int32(P))
    tally.same("layout", case, "simdvol_layout_voxel", host.read(cells_v, np.float32, n_cells),
               cells_ref)
    flat = host.buf(np.full(vol.size, NAN))
    host.run(L.simdvol_gather, P * int(g.cell[1] * g.cell[2]), WGS, cells, flat, b_org, *geo_args,
             np.int32(P))
    tally.same("layout", case, "simdvol_gather", host.read(flat, np.float32, vol.size), vol)

    # Shade: shade.cl alone, shade_defines then SV_RW; (cells, out, origins, dims, cell, block,
    # pes, vstride, sp); sp a __constant buffer of sizeof(sv_shade_params) = 108 bytes.
    sp, cp = load(d, "shade_params.bin", np.uint8), load(d, "classify_params.bin", np.uint8)
    tally.same("params", case, "struct sizes 108, 2032", [sp.size, cp.size], [108, 2032])
    shade_params_check(tally, case, sp, M)
    defs = [tuple(v.split()) for k, v in (ln.split(" ", 1) for ln in
            (d / "meta.txt").read_text().splitlines()) if k in ("shade_define", "classify_define")]
    sdef = [("SV_GRAD_OVER", "1")] if sp.view(np.int32)[25] else []
    cdef = [(k, str(v)) for k, v in classify_defines(cp)]
    tally.text("params", case, "shade_defines, classify_defines", sdef + cdef, defs)
    rw = [("SV_RW", sv_rw(int(g.cell[0])))]
    vs, nv = g.vstride, P * 4 * g.vstride
    b_sp, b_cp = host.buf(sp), host.buf(cp)
    common = (b_org, *geo_args, np.int32(P), np.int32(vs), b_sp)  # after (cells, out)
    shaded = host.buf(np.full(nv, NAN))
    chunk_run(host, host.program("shade", sdef + rw).simdvol_shade16, P, vs, cells, shaded, *common)
    sh = host.read(shaded, np.float32, nv)
    got, want = g.gather(sh), load(d, "shade.f32").reshape(-1, 4)
    # Section 8: Id, Is within 1e-5; |g| within 1e-6 max(1, |g|); channel 3 the volume's
    # value (equal); zero tails.
    tally.close("shade", case, "shade16 Id, Is", got[:, :2], want[:, :2], 1e-5, channels=2)
    tally.close("shade", case, "shade16 |g|", got[:, 2], want[:, 2], 1e-6, rel=True)
    tally.same("shade", case, "shade16 channel 3 = value", got[:, 3], vol, zeros_alike=True)
    ne = int(np.prod(g.cell))
    tally.same("shade", case, "shade16 zero tails", g.planes(sh)[:, ne:],
               np.zeros_like(g.planes(sh)[:, ne:]))
    # The scalar kernels (same arguments) within 1e-6 of shade16 (section 8), every position:
    # simdvol_shade_rows 2-D (cy cz, P) / (lr, max(1, min(64 / lr, P))), lr = min(64, 2^k >=
    # cy cz); simdvol_shade 3-D (cx, cy cz, P) / (LX, LY, LZ), LX = clamp(2^k >= cx, 8, 64),
    # LY = max(16 / LX, min(256 / LX, 2^k >= cy cz)), LZ = max(1, min(256 / (LX LY), P)).
    S, cx, rows = host.program("shade", sdef), int(g.cell[0]), int(g.cell[1] * g.cell[2])
    lr = min(64, pow2_at_least(rows))
    lx = min(max(pow2_at_least(cx), 8), 64)
    ly = max(16 // lx, min(256 // lx, pow2_at_least(rows)))
    lz = max(1, min(256 // (lx * ly), P))
    for name, gs, ls in (("simdvol_shade_rows", (rows, P), (lr, max(1, min(64 // lr, P)))),
                         ("simdvol_shade", (cx, rows, P), (lx, ly, lz))):
        out = host.buf(np.full(nv, NAN))
        host.run(getattr(S, name), gs, ls, cells, out, *common)
        v = g.planes(host.read(out, np.float32, nv)).reshape(-1, 4)
        w = g.planes(sh).reshape(-1, 4)
        tally.close("shade", case, f"{name} Id, Is = shade16's", v[:, :2], w[:, :2], 1e-6,
                    channels=2)
        tally.close("shade", case, f"{name} |g| = shade16's", v[:, 2], w[:, 2], 1e-6, rel=True)
        tally.same("shade", case, f"{name} channel 3 = shade16's", v[:, 3], w[:, 3])
    # Classify alone (classify.cl, its defines): simdvol_classify16(shading, out, vstride, pes, cp);
    # simdvol_classify16_in_place(voxels, vstride, pes, cp): bit for bit, tails included.
    C, rgba = host.program("classify", cdef), host.buf(np.full(nv, NAN))
    chunk_run(host, C.simdvol_classify16, P, vs, shaded, rgba, np.int32(vs), np.int32(P), b_cp)
    sep = host.read(rgba, np.float32, nv)
    chunk_run(host, C.simdvol_classify16_in_place, P, vs, shaded, np.int32(vs), np.int32(P), b_cp)
    tally.same("shade+classify", case, "classify16_in_place = classify16",
               host.read(shaded, np.float32, nv), sep, channels=4)
    sep = g.planes(sep)[:, :ne]
    # Fused: program ("shade", d, {"classify"}), d = classify_defines, shade_defines, SV_RW;
    # (cells .. sp, cp, occ, nbx, nby, mark, live, use_live, kc, kc_mode); occ zeroed.
    F = host.program("shade", cdef + sdef + rw, ("classify",))
    brick = 1 << shared_define(kd, "SV_BRICK_LOG2")
    rgba_ref = load(d, "rgba.f32").reshape(-1, 4)
    fused = {}
    for il in (False, True):
        name = "simdvol_shade_classify16" + ("_il" if il else "")
        out, occ_b = host.buf(np.full(nv, NAN)), host.zeros(4 * int(np.prod(-(-g.dims // brick))))
        nbx, nby = (-(-g.dims // brick))[:2]
        chunk_run(host, getattr(F, name), P, vs, cells, out, *common, b_cp, occ_b,
                  *i32(nbx, nby, 1), host.empty(16), np.int32(0), host.empty(16), np.int32(0))
        v = host.read(out, np.float32, nv)
        fused[il] = g.planes(v, il)
        occ_want, nb = occupancy(g.gather(v, il), dims, brick)
        tally.same("shade+classify", case, f"{name} marks",
                   host.read(occ_b, np.uint32, occ_want.size), occ_want)
    tally.same("shade+classify", case, "shade_classify16 = shade16, classify16", fused[0][:, :ne],
               sep, zeros_alike=True, channels=4)
    tally.same("shade+classify", case, "shade_classify16 zero tails", fused[0][:, ne:],
               np.zeros_like(fused[0][:, ne:]))
    tally.same("shade+classify", case, "shade_classify16_il = planar", fused[1], fused[0],
               channels=4)
    got = g.gather(fused[0].transpose(0, 2, 1).ravel())
    tally.close("shade+classify", case, "shade_classify16 against classify()", got, rgba_ref,
                1e-5, channels=4)
    tally.same("shade+classify", case, "the same voxels empty", got[:, 3] > 0, rgba_ref[:, 3] > 0)

    # The reference's classified voxels in voxel cells (section 3), against voxels_to_cells.
    vox = {il: g.to_cells(rgba_ref, il) for il in (False, True)}
    tally.same("tables", case, "voxel cells (Python)", g.planes(vox[False]).ravel(),
               load(d, "rgba_cells.f32"))
    b_vox = {il: host.buf(v) for il, v in vox.items()}
    # Resample tables (section 3) against resample_address_table, _pair_table, _cell_bits.
    tab = {}
    for il in (False, True):
        t, cs, st = g.table(il)
        tab[il] = (t, cs, st)
        sfx = "_il" if il else ""
        tally.same("tables", case, f"address table{sfx}", t, load(d, f"table{sfx}.i32"))
        tally.same("tables", case, f"cs{sfx}", [cs], [int(M["cs" + sfx])])
    pairs = pair_table(tab[True][0], dims)
    bits = cell_bits(tab[True][0], dims)
    tally.same("tables", case, "pair table", pairs, load(d, "pairs_il.i64"))
    tally.same("tables", case, "cell bits", bits, load(d, "cell_bits_il.i32"))
    b_pairs = host.buf(pairs)
    b_pairs_c = host.buf(np.concatenate([pairs.view(np.int32), bits])) if bits.size else None

    # Occupancy (resample.cl): (vox, stride, cell, origins, dims, nbx, nby, occ) over
    # (cz rounded to min(8, cz), P) / (min(8, cz), 1); occ zeroed; then the reach per order.
    R = {o: host.program("resample", [("ORDER", o)], ("local",)) for o in ORDERS}
    occ_want, nb = occupancy(rgba_ref, dims, brick)
    lz = min(8, int(g.cell[2]))
    for il in (False, True):
        occ_b = host.zeros(4 * occ_want.size)
        host.run(getattr(R[1], "simdvol_occupancy" + ("_il" if il else "")), (int(g.cell[2]), P),
                 (lz, 1), b_vox[il], np.int32(vs), g.args("cell0"), b_org, g.args("dims"),
                 *i32(*nb[:2]), occ_b)
        tally.same("occupancy", case, "simdvol_occupancy" + ("_il" if il else ""),
                   host.read(occ_b, np.uint32, occ_want.size), occ_want)
    b_reach = {}
    for o in ORDERS:
        b_reach[o] = host.empty(occ_want.size)
        host.run(R[o].simdvol_occupancy_reach, int(nb[1] * nb[2]), 64, occ_b, *i32(*nb),
                 *i32(1 if o >= 2 else 0, 1), b_reach[o])
        tally.same("occupancy", case, f"reach, order {o}",
                   host.read(b_reach[o], np.uint8, occ_want.size), reach(occ_want, nb, o))

    # Segments, offsets, rectangles (section 3), the balanced bounds as kb short2.
    segs, bsegs = load(d, "segs.bin", SEG), load(d, "bal_segs.bin", SEG)
    seg_off, rects = load(d, "seg_offset.i32"), load(d, "rects.bin", np.int32).reshape(P, 4)
    cand = load(d, "cand.bin", np.int32).reshape(P, 4)
    rect_off = np.r_[0, np.cumsum(rects[:, 2].astype(np.int64) * rects[:, 3])]
    sample_off = np.r_[0, np.cumsum(bsegs["k1"] - bsegs["k0"])]
    tally.same("tables", case, "rect_off", rect_off, load(d, "rect_off.i64"))
    tally.same("tables", case, "sample_off", sample_off, load(d, "sample_off.i64"))
    kb = np.stack([bsegs["k0"], bsegs["k1"]], 1).astype(np.int16)
    npix, nsmp = int(rect_off[-1]), int(sample_off[-1])
    b_segs, b_bsegs, b_soff = host.buf(segs), host.buf(bsegs), host.buf(seg_off)
    b_rects, b_roff, b_kb = host.buf(rects), host.buf(rect_off[:P].astype(np.int32)), host.buf(kb)
    b_view, b_smpoff = host.buf(view), host.buf(sample_off.astype(np.int32))

    # zero_uncovered on the rows of simdvol_match_rows_nolinks (section 5 match.cl: H = the
    # largest candidate height rounded up to 8, at least 8; P H / 8 work-items; save 0).
    H = match_rows(cand)
    geo, stepc = match_geo(view, g.cell)
    rowsum = host.empty(16 * P * H)
    # (view, geo, stepc, cand, cidx, cell, splits, pe_of, active, pes, H, rowsum, rowlk, kscr,
    # koff, save): every PE active; rowlk, kscr and koff unused here (save 0).
    host.run(L.simdvol_match_rows_nolinks, P * H // 8, WGS, host.buf(view), host.buf(geo),
             host.buf(stepc), host.buf(cand), host.buf(g.cidx4), g.args("cell0"), g.args("splits"),
             b_poc, host.buf(np.ones(P, np.uint8)), *i32(P, H), rowsum, host.empty(16 * P * H),
             host.empty(16), host.zeros(4 * P), np.int32(0))

    def footprints(zero_uncovered=False):
        """Footprint buffer: NaN, then zero_uncovered; or zeroed (simdvol_zero4, n / 256)."""
        fp = host.buf(np.full(4 * max(npix, 1), NAN))
        if zero_uncovered:
            host.run(L.simdvol_zero_uncovered, P * H // 8, WGS, host.buf(cand), b_rects, rowsum,
                     *i32(P, H), b_roff, fp)
        else:
            host.run(R[1].simdvol_zero4, npix, 256, fp, np.int32(npix))
        return fp

    # Lanes' order: (segs, nseg, seg_off, log2p, order, kb, use_kb, with_pe),
    # ceil(nseg / SV_ORDER_BLOCK) / 64; checked against the page's rule.
    blk, lanes = shared_define(kd, "SV_ORDER_BLOCK"), {}
    for use_kb, with_pe in ((0, 0), (1, 1)):
        n_ord = nseg + (-(-nseg // 8) if with_pe else 0)
        ob = host.empty(4 * n_ord)
        host.run(R[1].simdvol_segment_order, -(-nseg // blk), 64, b_segs if use_kb else b_bsegs,
                 np.int32(nseg), b_soff, log2p, ob, b_kb, *i32(use_kb, with_pe))
        lanes[with_pe] = ob
        tally.same("order", case, f"simdvol_segment_order use_kb {use_kb} with_pe {with_pe}",
                   host.read(ob, np.int32, n_ord),
                   segment_order(segs if use_kb else bsegs, seg_off, kb if use_kb else None,
                                 blk, with_pe))

    for o in ORDERS:
        foot_ref, smp_ref = load(d, f"foot_o{o}.f32"), load(d, f"samples_o{o}.f32")
        # Variants: (name, interleaved, segments with kb, ordered, skip, pairs). The plain planar
        # one passes 16-byte dummies where the page says a buffer is not read (reach with skip
        # 0, kb with use_kb 0, pairs on planar cells, origins with pe_cell.w 0); the interleaved
        # one takes the matching's segments with the balanced kb (the direct frame's deferred
        # unpack), the lanes' order with PEs (ordered 2), skipping; _ilc (order 1) the cell bits.
        variants = [("v8", 0, 0, 0, 0, None), ("v8_il", 1, 1, 2, 1, b_pairs)]
        if o == 1 and b_pairs_c is not None:
            variants.append(("v8_ilc", 1, 0, 1, 0, b_pairs_c))

        def common(il, ordered, skip, pb):  # order .. pairs as both kernels take them
            return dict(order=lanes[ordered == 2] if ordered else host.empty(16),
                        ordered=np.int32(ordered), reach=b_reach[o] if skip else host.empty(16),
                        nb=i32(*nb[:2], skip), origins=b_org if pb else host.empty(16),
                        pe_cell=int4(*g.cell, 1 if pb else 0), pairs=pb or host.empty(16),
                        table=host.buf(tab[il][0]), cs=np.int32(tab[il][1]))

        # Resample (ceil(nseg / 8) / 64): (segs, nseg, sample_off, view, table, vox, cs, out,
        # order, ordered, reach, nbx, nby, skip, seg_off, log2p, origins, pe_cell, pairs), the
        # balanced segments.
        smp = {}
        for name, il, _, ordered, skip, pb in variants[:2]:
            a, out = common(il, ordered, skip, pb), host.buf(np.full(4 * max(nsmp, 1), NAN))
            host.run(getattr(R[o], "simdvol_resample_" + name), -(-nseg // 8), 64, b_bsegs,
                     np.int32(nseg), b_smpoff, b_view, a["table"], b_vox[il], a["cs"], out,
                     a["order"], a["ordered"], a["reach"], *a["nb"], b_soff, log2p, a["origins"],
                     a["pe_cell"], a["pairs"])
            smp[name] = host.read(out, np.float32, 4 * nsmp)
        tally.close("resample", case, f"order {o} resample_v8 against resample_reference",
                    smp["v8"], smp_ref, 1e-5, channels=4)
        tally.same("resample", case, f"order {o} resample_v8_il (lanes' order, skip)", smp["v8_il"],
                   smp["v8"], zeros_alike=True, channels=4)
        # Local (nseg / 64): (segs, nseg, seg_off, log2p, sample_off, samples, rects, rect_off,
        # foot) into zeroed footprints.
        fp = footprints()
        host.run(R[o].simdvol_local, nseg, 64, b_bsegs, np.int32(nseg), b_soff, log2p, b_smpoff,
                 host.buf(smp["v8"]), b_rects, b_roff, fp)
        tally.close("local", case, f"order {o} simdvol_local against footprints_reference",
                    host.read(fp, np.float32, 4 * npix), foot_ref, 1e-5, channels=4)
        # Fused (ceil(nseg / 8) / 64): (segs, nseg, seg_off, log2p, view, table, vox, cs, rects,
        # rect_off, foot, reach, nbx, nby, skip, order, ordered, origins, pe_cell, pairs, kb,
        # use_kb); the interleaved variant's footprints zeroed by zero_uncovered only.
        base = None
        for name, il, use_kb, ordered, skip, pb in variants:
            a, fp = common(il, ordered, skip, pb), footprints(zero_uncovered=bool(use_kb))
            host.run(getattr(R[o], "simdvol_resample_local_" + name), -(-nseg // 8), 64,
                     b_segs if use_kb else b_bsegs, np.int32(nseg), b_soff, log2p, b_view,
                     a["table"], b_vox[il], a["cs"], b_rects, b_roff, fp, a["reach"], *a["nb"],
                     a["order"], a["ordered"], a["origins"], a["pe_cell"], a["pairs"],
                     b_kb if use_kb else host.empty(16), np.int32(use_kb))
            got = host.read(fp, np.float32, 4 * npix)
            if base is None:
                base = got
                tally.close("fused", case, f"order {o} resample_local_v8 against "
                            "footprints_reference", got, foot_ref, 1e-5, channels=4)
            else:
                tally.same("fused", case, f"order {o} resample_local_{name} = v8", got, base,
                           channels=4)


# ---------------------------------------------------------------- match, balance (sections 3-5)
GUARD = 4096  # a placeholder's guard: the bytes after its 16 must stay as they were


class Guarded:
    """Section 5's "one-element placeholders" (kscr without save, bounds without fill_bounds,
    llist without links, lbase without narrow): 16-byte sub-buffers at the start of buffers of
    a known pattern, so that a kernel that writes past the element it was given is caught
    (intact: the bytes after the first 16 unchanged)."""

    def __init__(self, host):
        self.host, self.bufs = host, []

    def __call__(self):
        whole = self.host.buf(np.full(GUARD, 0xA5, np.uint8))
        self.bufs.append(whole)
        return whole.get_sub_region(0, 16)

    def intact(self):
        return all((self.host.read(b, np.uint8, GUARD)[16:] == 0xA5).all() for b in self.bufs)


def match_rows(cand):
    """Section 5 match.cl: H = the largest candidate height rounded up to 8, at least 8."""
    return max(8, round_up(cand[:, 3].max(), 8))


def balance_pairs(g):
    """Section 5 balance.cl `pair_list`: per (axis a, parity par) the int2 (the PE of cell
    index c, the PE of c + 1) along a for every c = 2 m + par with c + 1 inside; pair_first[2 a
    + par] .. pair_first[2 a + par + 1] - 1 (7 ints)."""
    pairs, first, s = [], [0], g.splits
    for a in range(3):
        for par in (0, 1):
            ci = g.cidx[:, a]
            lo = np.flatnonzero((ci % 2 == par) & (ci + 1 < s[a]))
            nxt = g.cidx[lo].copy()
            nxt[:, a] += 1
            hi = g.pe_of_cell[(nxt[:, 2] * s[1] + nxt[:, 1]) * s[0] + nxt[:, 0]]
            pairs.append(np.stack([lo, hi], 1))
            first.append(first[-1] + len(lo))
    return np.concatenate(pairs).astype(np.int32), first


def link_lists(links, seg_off, P):
    """Section 5 match.cl: llist holds every PE's list of links along x, then every PE's along
    y, then along z, each PE's list in the order of its segments; lofs[p] = (seg_offset[p],
    where PE p's x, y, z lists start), lofs[P] = (the segments, where the lists end). From
    balance_links()'s format (linked * 4 + axis per segment, -1: none). Returns the wide
    entries (segment, linked), the narrow ones (indices within the two PEs), lofs and petot."""
    nseg = len(links)
    pe = np.searchsorted(seg_off, np.arange(nseg), side="right") - 1
    has = links >= 0
    axis, linked = np.where(has, links & 3, 3), np.where(has, links >> 2, 0)
    wide, narrow = [], []
    count = np.zeros((3, P), np.int64)
    for a in range(3):
        s = np.flatnonzero(axis == a)  # in segment order, so by PE, then the PE's order
        count[a] = np.bincount(pe[s], minlength=P)
        wide.append(np.stack([s, linked[s]], 1))
        t = linked[s]
        narrow.append(((s - seg_off[pe[s]]) | ((t - seg_off[pe[t]]) << 16)).astype(np.uint32))
    lofs = np.zeros((P + 1, 4), np.int64)
    lofs[:, 0] = seg_off
    base = 0
    for a in range(3):
        lofs[:, a + 1] = base + np.r_[0, np.cumsum(count[a])]
        base += count[a].sum()
    petot = np.c_[np.diff(seg_off), count.T]
    return (np.concatenate(wide).astype(np.int32), np.concatenate(narrow), lofs.astype(np.int32),
            petot.astype(np.int32))


def uncovered(segs, seg_off, rects, rect_off):
    """simdvol_zero_uncovered's rule (section 5): per PE and row of its rectangle, the pixels left
    of the row's first and right of its last segment zeroed, the whole row where it has none or
    a gap. Returns the footprints as NaN-filled ones look after it: +0 there, NaN elsewhere."""
    out = np.full((int(rect_off[-1]), 4), NAN)
    for p in range(len(rects)):
        i0, j0, w, h = (int(v) for v in rects[p])
        if w * h == 0:
            continue
        fp = out[rect_off[p]:rect_off[p + 1]].reshape(h, w, 4)
        s = segs[seg_off[p]:seg_off[p + 1]]
        keep = np.zeros((h, w), bool)
        rows = s["j"] - j0
        for r in np.unique(rows):
            i = s["i"][rows == r] - i0
            if i.max() - i.min() + 1 == i.size:
                keep[r, i.min():i.max() + 1] = True
        fp[~keep] = 0
    return out


def check_match(host, tally, d):
    """Section 5 match.cl and balance.cl from the page: the PE mask (simdvol_match_active), the
    matching (rows, pe, scan, fill; with and without links, saved columns or stepped, wide and
    narrow link lists, the balance's 16-bit bounds or none), zero_uncovered on its rows, and the
    balance rounds on 16- and 32-bit bounds with wide and narrow lists, unpacked or deferred."""
    M, case = read_meta(d), d.name
    P, dims, sweeps = int(M["pes"]), [int(x) for x in M["dims"].split()], int(M["sweeps"])
    g, L = Cells(dims, P), host.layout_group()
    view, cand = load(d, "view.bin", np.int64), load(d, "cand.bin", np.int32).reshape(P, 4)
    segs, seg_off = load(d, "segs.bin", SEG), load(d, "seg_offset.i32")
    rects, loads = load(d, "rects.bin", np.int32).reshape(P, 4), load(d, "loads.i64")
    links, nseg = load(d, "links.i32"), int(M["nseg"])
    wide, narrow, lofs, petot = link_lists(links, seg_off, P)
    guard = Guarded(host)
    b_view, b_cand, b_cidx = host.buf(view), host.buf(cand), host.buf(g.cidx4)
    b_poc, cell0, splits = host.buf(g.pe_of_cell), g.args("cell0"), g.args("splits")

    # The PE mask: simdvol_match_active (cidx, cell, dims, pes, reach, bricks, active), P / 64;
    # all 1 without one.
    active = np.ones(P, np.uint8)
    if int(M["skip"]):
        nb, active = [int(x) for x in M["bricks"].split()], load(d, "active.u8", np.uint8)
        b_active = host.empty(P)
        host.run(L.simdvol_match_active, P, WGS, b_cidx, cell0, g.args("dims"), np.int32(P),
                 host.buf(load(d, "reach.u8", np.uint8)), int4(*nb), b_active)
        tally.same("match", case, "simdvol_match_active: match_active_reference",
                   host.read(b_active, np.uint8, P), active)
    else:
        b_active = host.buf(np.ones(P, np.uint8))

    # Host tables: H, geo, stepc; koff[p] = the sum of ceil8(h) w over the PEs before p;
    # capacity = the candidates' w h, at least 1.
    H = match_rows(cand)
    geo, stepc = match_geo(view, g.cell)
    b_geo, b_stepc = host.buf(geo), host.buf(stepc)
    area = cand[:, 2].astype(np.int64) * cand[:, 3]
    cap = max(1, int(area.sum()))
    koff = np.r_[0, np.cumsum([round_up(h, 8) * w for w, h in cand[:, 2:4].astype(np.int64)])]
    b_koff = host.buf(koff[:P].astype(np.int32))
    can_narrow = bool(area.max() <= 65536)
    rect_off = np.r_[0, np.cumsum(rects[:, 2].astype(np.int64) * rects[:, 3])]
    junk = np.int32(0x7A5A5A5A)  # the pooled buffers' leftovers in the rows of inactive PEs

    def match(links_on, save, narrow_on, bounds_on):
        """rows (P H / 8), pe (P), scan (64, work-item 0), fill (P H / 8), each / 64; the
        placeholders guarded. Returns the buffers and what they hold."""
        sfx = "" if links_on else "_nolinks"
        rowsum, rowlk, rowoff = (host.buf(np.full(4 * P * H, junk)) for _ in range(3))
        kscr = host.buf(np.full(int(koff[-1]), junk)) if save else guard()
        # (view, geo, stepc, cand, cidx, cell, splits, pe_of, active, pes, H, rowsum, rowlk,
        # kscr, koff, save)
        head = (b_view, b_geo, b_stepc, b_cand, b_cidx, cell0, splits, b_poc, b_active,
                *i32(P, H))
        host.run(getattr(L, "simdvol_match_rows" + sfx), P * H // 8, WGS, *head, rowsum, rowlk,
                 kscr, b_koff, np.int32(save))
        # (cand, active, pes, H, rowsum, rowlk, rowoff, petot, counts, rects, loads)
        b = {k: host.empty(n) for k, n in (("petot", 16 * P), ("counts", 4 * P),
                                          ("rects", 16 * P), ("loads", 4 * P),
                                          ("seg_offset", 4 * (P + 1)), ("lofs", 16 * (P + 1)),
                                          ("segments", 16 * cap))}
        host.run(L.simdvol_match_pe, P, WGS, b_cand, b_active, *i32(P, H), rowsum, rowlk, rowoff,
                 b["petot"], b["counts"], b["rects"], b["loads"])
        host.run(L.simdvol_match_scan, WGS, WGS, b["petot"], np.int32(P), b["seg_offset"],
                 b["lofs"])
        b["bounds"] = host.empty(4 * cap) if bounds_on else guard()
        b["llist"] = host.empty((4 if narrow_on else 8) * cap) if links_on else guard()
        b["lbase"] = host.empty(16 * P) if narrow_on else guard()
        # (view .. H, rowsum, rowlk, rowoff, seg_offset, lofs, segments, bounds, fill_bounds,
        # llist, narrow, lbase, kscr, koff, saved)
        host.run(getattr(L, "simdvol_match_fill" + sfx), P * H // 8, WGS, *head, rowsum, rowlk,
                 rowoff, b["seg_offset"], b["lofs"], b["segments"], b["bounds"],
                 np.int32(bounds_on), b["llist"], np.int32(narrow_on), b["lbase"], kscr, b_koff,
                 np.int32(save))
        b["rowsum"] = rowsum
        return b

    def check_matching(b, what, links_on, narrow_on, bounds_on):
        tally.same("match", case, f"{what}: seg_offset", host.read(b["seg_offset"], np.int32,
                                                                   P + 1), seg_off)
        got = host.read(b["segments"], np.int32, 4 * nseg)
        tally.same("match", case, f"{what}: segments", got, segs.view(np.int32))
        tally.same("match", case, f"{what}: rects", host.read(b["rects"], np.int32, 4 * P),
                   rects.ravel())
        tally.same("match", case, f"{what}: loads", host.read(b["loads"], np.int32, P), loads)
        tally.same("match", case, f"{what}: counts", host.read(b["counts"], np.int32, P),
                   np.diff(seg_off))
        # petot (segments, links along x, y, z) and lofs; without links rowlk is 0: no links.
        pt, lo = (petot, lofs) if links_on else (petot * [1, 0, 0, 0], lofs * [1, 0, 0, 0])
        tally.same("match", case, f"{what}: petot", host.read(b["petot"], np.int32, 4 * P),
                   pt.ravel())
        tally.same("match", case, f"{what}: lofs", host.read(b["lofs"], np.int32, 4 * (P + 1)),
                   lo.ravel())
        if links_on:
            if narrow_on:
                tally.same("match", case, f"{what}: narrow link list",
                           host.read(b["llist"], np.uint32, len(narrow)), narrow)
            else:
                tally.same("match", case, f"{what}: wide link list",
                           host.read(b["llist"], np.int32, 2 * len(wide)), wide.ravel())
        if narrow_on:
            tally.same("match", case, f"{what}: lbase", host.read(b["lbase"], np.int32, 4 * P),
                       link_base(g, view, seg_off, active).ravel())
        if bounds_on:
            tally.same("match", case, f"{what}: bounds", host.read(b["bounds"], np.int16,
                                                                   2 * nseg),
                       np.stack([segs["k0"], segs["k1"]], 1).astype(np.int16).ravel())
        tally.same("match", case, f"{what}: placeholders not overrun", [guard.intact()], [True])

    def zero_uncovered(b, what):
        """(cand, rects, rowsum, pes, H, rect_off, foot), P H / 8 / 64, on NaN footprints sized
        by the device's rectangles (as a host sizes them: section 4, 6)."""
        r = host.read(b["rects"], np.int32, 4 * P).reshape(P, 4)
        off = np.r_[0, np.cumsum(r[:, 2].astype(np.int64) * r[:, 3])]
        fp = host.buf(np.full(4 * max(int(off[-1]), 1), NAN))
        host.run(L.simdvol_zero_uncovered, P * H // 8, WGS, b_cand, b["rects"], b["rowsum"],
                 *i32(P, H), host.buf(off[:P].astype(np.int32)), fp)
        tally.same("match", case, f"zero_uncovered on the {what} rows",
                   host.read(fp, np.float32, 4 * int(off[-1])), want_fp, channels=4)

    # Without links (sweeps 0), saved columns and stepped; zero_uncovered on the first one's rows.
    want_fp = uncovered(segs, seg_off, rects, rect_off)
    for save in (1, 0):
        b = match(False, save, False, False)
        check_matching(b, f"nolinks save {save}", False, False, False)
        if save:
            zero_uncovered(b, "nolinks")

    # With links, then the balance on each: (save, narrow, bounds16).
    variants = [(1, 1, 1), (0, 0, 1), (1, 0, 0), (0, 1, 0)]
    bal_axes = [a for a in range(3) if view[4 + 4 * a + 2] != 0 and g.splits[a] >= 2]
    pairs, pfirst = balance_pairs(g)
    # The page gives no order of a round's pairs (they share no PE): the stepped variants take
    # each round's pairs shuffled.
    shuffled = pairs.copy()
    rng = np.random.default_rng(P)
    for a in range(6):
        shuffled[pfirst[a]:pfirst[a + 1]] = rng.permutation(pairs[pfirst[a]:pfirst[a + 1]])
    b_pairs = {1: host.buf(pairs), 0: host.buf(shuffled)}
    stride, per = (shared_define(host.kdir, n) for n in ("SV_BAL_MOVES_STRIDE", "SV_BAL_PES"))
    if sweeps:
        bal = load(d, "bal_segs.bin", SEG)
        bal_kk = np.stack([bal["k0"], bal["k1"]], 1).ravel()
    for save, nar, b16 in variants:
        if nar and not can_narrow:
            continue
        what = f"links save {save} narrow {nar} fill_bounds {b16}"
        b = match(True, save, nar, b16)
        check_matching(b, what, True, nar, b16)
        if save and nar == can_narrow:
            zero_uncovered(b, "linked")
        if not sweeps:
            continue
        if not bal_axes:  # no round, so no pack or unpack: the matching is the balanced one
            tally.same("balance", case, f"{what}: no round: balance_reference's segments",
                       host.read(b["segments"], np.int32, 4 * nseg), bal.view(np.int32))
            continue
        # Balance: 16-bit bounds as the fill wrote them, or 32-bit ones packed from the
        # segments (seg_offset, pes, segments, kk), capacity / 64.
        w = "16" if b16 else ""
        bname = (f"balance {'16' if b16 else '32'}-bit, {'narrow' if nar else 'wide'} lists"
                 + ("" if save else ", pairs shuffled"))
        kk = b["bounds"]
        if not b16:
            kk = host.empty(8 * cap)
            host.run(L.simdvol_balance_pack, cap, WGS, b["seg_offset"], np.int32(P),
                     b["segments"], kk)
        # The rounds: per sweep, balanced axis and parity (pair_list, first, npairs, axis, dir,
        # lofs, llist, kk, loads, moves, sweep), ceil(npairs / SV_BAL_PES) / 64; moves
        # int[sweeps * SV_BAL_MOVES_STRIDE] zeroed first.
        moves = host.zeros(4 * sweeps * stride)
        rnd = getattr(L, f"simdvol_balance_round{w}" + ("n" if nar else ""))
        for s in range(sweeps):
            for a in bal_axes:
                dr = 1 if view[4 + 4 * a + 2] > 0 else -1
                for par in (0, 1):
                    first, n = pfirst[2 * a + par], pfirst[2 * a + par + 1] - pfirst[2 * a + par]
                    if n == 0:  # (a global size of 0 is CL_INVALID_GLOBAL_WORK_SIZE)
                        continue
                    host.run(rnd, -(-n // per), WGS, b_pairs[save], *i32(first, n, a, dr),
                             b["lofs"], b["llist"], kk, b["loads"], moves, np.int32(s))
        tally.same("balance", case, f"{bname}: loads", host.read(b["loads"], np.int32, P),
                   load(d, "bal_loads.i64"))
        tally.same("balance", case, f"{bname}: moves flags",
                   host.read(moves, np.int32, sweeps * stride)[::stride],
                   load(d, "sweep_changed.i32"))
        got = host.read(kk, np.int16 if b16 else np.int32, 2 * nseg)
        tally.same("balance", case, f"{bname}: bounds" + (" (deferred unpack)" if b16 else ""),
                   got, bal_kk)
        # Unpack (seg_offset, pes, kk, segments), capacity / 64.
        host.run(getattr(L, f"simdvol_balance_unpack{w}"), cap, WGS, b["seg_offset"],
                 np.int32(P), kk, b["segments"])
        tally.same("balance", case, f"{bname}: unpacked segments",
                   host.read(b["segments"], np.int32, 4 * nseg), bal.view(np.int32))


def link_base(g, view, seg_off, active):
    """Section 5 match.cl lbase[p] (narrow lists): (the first segment of p's link target along
    x, y, z; p's first segment). The target along a is the PE of p's cell index + 1 along a where
    view.step[a][2] > 0, - 1 otherwise (also where it is 0: no links then); -1 where that cell is
    outside the split or its PE inactive. Written for inactive PEs too."""
    P, s = g.P, g.splits
    out = np.full((P, 4), -1, np.int64)
    out[:, 3] = seg_off[:P]
    for a in range(3):
        nxt = g.cidx.copy()
        nxt[:, a] += 1 if int(view[4 + 4 * a + 2]) > 0 else -1
        ok = (nxt[:, a] >= 0) & (nxt[:, a] < s[a])
        t = np.full(P, -1)
        t[ok] = g.pe_of_cell[((nxt[:, 2] * s[1] + nxt[:, 1]) * s[0] + nxt[:, 0])[ok]]
        ok &= active[np.maximum(t, 0)] != 0
        out[ok, a] = seg_off[t[ok]]
    return out.astype(np.int32)


# ---------------------------------------------------------------- main
SUMMARY = (
    ("plan", "swap plan", "bit_axis, front, pixel bits, rectangles, offsets, xpe, ype: plan_swap"),
    ("swap", "swap", "level N per stage and in fused runs: swap_reference's"),
    ("display", "display", "images: display_reference's"),
    ("lists", "mc lists", "sample offsets, ray lists: sample_offsets(), ray_segments()"),
    ("whole", "mc whole", "images and counters: mc_whole_reference's"),
    ("alloc", "allocation", "segment alphas, walks: segment_alphas(), allocation_reference()"),
    ("sub", "mc sub", "footprints and counters: mc_sub_reference's"),
    ("adaptive", "adaptive", "images: composite_adaptive's"),
    ("warp", "warp", "tables and images: output_to_intermediate's, warp_to_output's"),
    ("layout", "layout", "geometry, origins, pe_of_cell, cells, gather: layout_reference's"),
    ("params", "params", "sv_shade_params rules, struct sizes, defines: the library's"),
    ("shade", "shade", "shade16 against shade() (1e-5, |g| 1e-6 rel), value, zero tails"),
    ("shade+classify", "shade+cls", "fused = shade16 + classify16, _il = planar, marks; "
     "classify() 1e-5"),
    ("tables", "tables", "voxel cells, address/pair tables, cell bits, offsets: the library's"),
    ("occupancy", "occupancy", "simdvol_occupancy(_il), reach per order: the page's rule"),
    ("order", "lanes", "simdvol_segment_order (with PEs, kb): the page's rule"),
    ("resample", "resample", "v8 against resample_reference (1e-5); v8_il equal"),
    ("local", "local", "simdvol_local against footprints_reference (1e-5)"),
    ("fused", "fused", "resample_local_v8 against footprints_reference (1e-5); _il (kb, "
     "zero_uncovered, lanes, skip), _ilc bit for bit"),
    ("match", "match", "mask, segments, offsets, rects, loads, link lists, bounds: the library's"),
    ("balance", "balance", "rounds, unpack: balance_reference's bounds, loads; moves flags"),
)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kernels", required=True, type=pathlib.Path,
                    help="installed kernel directory (PREFIX/share/simdvol/kernels)")
    ap.add_argument("--cases", required=True, type=pathlib.Path,
                    help="directory written by kernel-abi-ref")
    ap.add_argument("-v", "--verbose", action="store_true", help="print every check")
    args = ap.parse_args()
    cases = sorted(p.parent for p in args.cases.glob("*/meta.txt"))
    if not cases:
        raise RuntimeError(f"no cases in {args.cases}")
    host, tally = Host(args.kernels), Tally(args.verbose)
    print(f"kernel-abi-check: pyopencl {cl.VERSION_TEXT} on {host.dev.name.strip()}, "
          f"kernels from {args.kernels}; WGS {host.wgs} ({WorkGroupLimits(host.dev).describe()})")
    kinds = [read_meta(d)["kind"] for d in cases]
    checks = {"swap": check_swap, "mc": check_mc, "direct": check_direct, "match": check_match}
    for d, kind in zip(cases, kinds):
        checks[kind](host, tally, d)
    print(f"kernel-abi-check: {kinds.count('swap')} swap cases (2 layouts each), "
          f"{kinds.count('mc')} Monte Carlo cases, {kinds.count('direct')} direct-frame cases, "
          f"{kinds.count('match')} match cases; bit for bit unless a tolerance is named:")
    for key, stage, text in SUMMARY:
        big = f" (largest difference {tally.largest[key]:.2g})" if key in tally.largest else ""
        print(f"kernel-abi-check: {stage:10s} {tally.ok.get(key, 0):4d} equal  {text}{big}")
    if host.fitted:
        print(f"kernel-abi-check: {len(host.fitted)} kernels launched with smaller work-groups "
              "than asked (section 1), e.g. " + ", ".join(
                  f"{k} {'x'.join(map(str, a))} -> {'x'.join(map(str, l))}"
                  for k, (a, l) in sorted(host.fitted.items())[:3]))
    if tally.failed:
        print(f"kernel-abi-check: FAILED: {len(tally.failed)} differ, the first: {tally.failed[0]}")
        return 1
    print("kernel-abi-check: the kernels run by KERNELS.md's rules equal the library's references")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Exception as e:  # noqa: BLE001
        print(f"kernel-abi-check: {type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(2)
