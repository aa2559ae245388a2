#!/usr/bin/python3
"""The swap, Monte Carlo, adaptive and warp kernels from docs/KERNELS.md alone: Python + pyopencl.

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
Prints one line per stage; a disagreement names the case, the check and the
first differing value.

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

LAYOUTS = ("cut-and-stack", "hierarchical")
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
        self.ok, self.failed, self.verbose = {}, [], verbose

    def same(self, stage, case, what, got, want, channels=1):
        """Bit for bit: floats by their bits (+0 and -0 differ), ints by value."""
        g, w = np.ascontiguousarray(got).ravel(), np.ascontiguousarray(want).ravel()
        diff = None
        if g.size != w.size:
            diff = f"{g.size} values, the reference has {w.size}"
        else:
            bad = np.flatnonzero(bits(g) != bits(w))
            if bad.size:
                i = int(bad[0])
                at = f"[{i // 4}].{'rgba'[i % 4]}" if channels == 4 else f"[{i}]"
                diff = (f"{bad.size} of {g.size} values differ, the first {at}: "
                        f"{show(g[i])}, the reference {show(w[i])}")
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
def program_source(kdir, stage, defines, more=()):
    """Section 1: the #define lines, then simdvol_shared.h, common.cl, the
    stage's file and the further files, each after a #line directive."""
    src = "".join(f"#define {n} {v}\n" for n, v in defines)
    for name in ("simdvol_shared.h", "common.cl", stage + ".cl") + tuple(f + ".cl" for f in more):
        text = (kdir / name).read_text()
        src += f'#line 1 "{name}"\n' + text + ("" if text.endswith("\n") else "\n")
    return src


def pick_device():
    """The first CPU device, else the first device (as examples/embed picks)."""
    first = None
    for p in cl.get_platforms():
        for d in p.get_devices():
            if d.type & cl.device_type.CPU:
                return d
            first = first or d
    if first is None:
        raise RuntimeError("no OpenCL device")
    return first


class Host:
    def __init__(self, kdir):
        self.kdir = kdir
        self.dev = pick_device()
        self.ctx = cl.Context([self.dev])
        self.q = cl.CommandQueue(self.ctx)
        self.local_mem = self.dev.local_mem_size
        self.programs = {}

    def program(self, stage, defines=(), more=(), options=()):
        key = (stage, tuple(defines), tuple(more), tuple(options))
        if key not in self.programs:
            src = program_source(self.kdir, stage, defines, more)
            self.programs[key] = cl.Program(self.ctx, src).build(options=list(options))
        return self.programs[key]

    def layout_group(self):
        """Section 1's third program (layout, match, balance, swap; WGS = 64):
        the swap, display and warp kernels."""
        return self.program("layout", [("WGS", 64)], ("match", "balance", "swap"))

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

    def run(self, kernel, g, l, *args):
        """Section 1: an explicit local size, each global size rounded up to it."""
        g, l = (g, l) if isinstance(g, tuple) else ((g,), (l,))
        kernel.set_args(*args)
        rounded = tuple(-(-max(a, 1) // b) * b for a, b in zip(g, l))
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
    is short. Returns level N's buffer, rectangles, offsets and pixels."""
    prog = host.layout_group()
    P, N = held[0].shape[0], len(front)
    R, O = [host.buf(h) for h in held], [host.buf(o) for o in off]
    lv = [host.buf(foot)] + [host.empty(16 * int(o[-1])) for o in off[1:]]
    k = 0
    while k < N:
        m = min(FUSED_MAX, N - k) if fused else 1
        while m > 1 and sum(local_bytes(off, P, k, m)) + FUSED_FIXED_LOCAL > host.local_mem:
            m -= 1
        if not fused:  # (in, in_rect, in_off, out, out_rect, out_off, pes, k, front): P / 64
            host.run(prog.simdvol_swap_stage, P, 64, lv[k], R[k], O[k], lv[k + 1], R[k + 1],
                     O[k + 1], *i32(P, k, front[k]))
        else:  # P / 2^m; r_s, o_s past m repeat level k + m; bit s of fronts = front[k + s]
            la, lb = local_bytes(off, P, k, m)
            host.run(prog.simdvol_swap_stages, P, 1 << m, lv[k], lv[k + m],
                     cl.LocalMemory(max(la, 16)), cl.LocalMemory(max(lb, 16)),
                     *[R[k + min(s, m)] for s in range(8)], *[O[k + min(s, m)] for s in range(8)],
                     *i32(k, m, sum(front[k + s] << s for s in range(m))))
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
          f"kernels from {args.kernels}")
    kinds = [read_meta(d)["kind"] for d in cases]
    for d, kind in zip(cases, kinds):
        (check_swap if kind == "swap" else check_mc)(host, tally, d)
    print(f"kernel-abi-check: {kinds.count('swap')} swap cases (2 layouts each), "
          f"{kinds.count('mc')} Monte Carlo cases; bit for bit:")
    for key, stage, text in SUMMARY:
        print(f"kernel-abi-check: {stage:10s} {tally.ok.get(key, 0):4d} equal  {text}")
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
