#!/usr/bin/python3
"""The classify stage from a second host language: Python + pyopencl.

Loads the INSTALLED kernel sources (share/simdvol/kernels of an install
prefix), assembles classify's program exactly as the C++ host does
(program_source: the #define lines, then simdvol_shared.h, common.cl and
classify.cl, each after a #line directive), builds it on the first CPU device
(as examples/embed picks), runs simdvol_classify16 on the shaded voxel cells
that `simdvol-embed --dump DIR` wrote, and compares the result with the C++
host's output from the same run: the same source and defines on the same
device must give the same floats (required: max |difference| <= 1e-6; the
number of bitwise differences is reported too).

Usage: /usr/bin/python3 scripts/pyopencl-check.py --kernels PREFIX/share/simdvol/kernels --dump DIR
(the system python: Debian's python3-pyopencl and python3-numpy).
Exit status 0 when the outputs agree, 1 when they do not, 2 on an error.
"""
import argparse
import os
import pathlib
import sys

os.environ.setdefault("PYOPENCL_COMPILER_OUTPUT", "0")
import numpy as np  # noqa: E402
import pyopencl as cl  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cl_program import (WorkGroupLimits, fit_work_group, pick_device,  # noqa: E402
                        program_source, round_up)

TOL = 1e-6
CHUNK_WGS = 64  # chunks of 16 voxels per work-group (host/cl/chunk_ranges.hpp)


def read_meta(path):
    meta = {"defines": []}
    for line in path.read_text().splitlines():
        key, _, value = line.partition(" ")
        if key == "define":
            name, _, val = value.partition(" ")
            meta["defines"].append((name, val))
        else:
            meta[key] = value
    return meta


def pow2_at_least(n):
    p = 1
    while p < n:
        p *= 2
    return p


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kernels", required=True, type=pathlib.Path,
                    help="installed kernel directory (PREFIX/share/simdvol/kernels)")
    ap.add_argument("--dump", required=True, type=pathlib.Path,
                    help="directory written by simdvol-embed --dump")
    args = ap.parse_args()

    meta = read_meta(args.dump / "classify.txt")
    pes, vstride = int(meta["pes"]), int(meta["vstride"])
    kernel_name = meta["kernel"]
    inp = np.fromfile(args.dump / "classify_in.f32", dtype=np.float32)
    want = np.fromfile(args.dump / "classify_out.f32", dtype=np.float32)
    params = np.fromfile(args.dump / "classify_params.bin", dtype=np.uint8)
    n = pes * 4 * vstride
    if inp.size != n or want.size != n:
        raise RuntimeError(f"buffers hold {inp.size} and {want.size} floats, expected {n}")

    dev = pick_device()
    ctx = cl.Context([dev])
    queue = cl.CommandQueue(ctx)
    src = program_source(args.kernels, "classify", meta["defines"])
    program = cl.Program(ctx, src).build(options=meta.get("options", "").split())
    kernel = cl.Kernel(program, kernel_name)

    mf = cl.mem_flags
    b_in = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=inp)
    b_par = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=params)
    got = np.full(n, np.nan, dtype=np.float32)
    b_out = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=got)
    # simdvol_classify16(shading, out, vstride, pes, params): one work-item per
    # chunk of 16 positions of a PE block, 2-D range (chunk, PE).
    chunks = vstride // 16
    l0 = min(CHUNK_WGS, pow2_at_least(chunks))
    l1 = max(1, min(CHUNK_WGS // l0, pes))
    # (KERNELS.md section 1: a smaller group where the device or the kernel
    # takes fewer work-items; the global size rounded up to the one asked for)
    g = (round_up(chunks, l0), round_up(pes, l1))
    l0, l1 = fit_work_group((l0, l1), WorkGroupLimits(dev, kernel))
    kernel.set_args(b_in, b_out, np.int32(vstride), np.int32(pes), b_par)
    cl.enqueue_nd_range_kernel(queue, kernel, (round_up(g[0], l0), round_up(g[1], l1)), (l0, l1))
    cl.enqueue_copy(queue, got, b_out)
    queue.finish()

    diff = np.abs(got.astype(np.float64) - want.astype(np.float64))
    max_diff = float(np.nanmax(diff)) if np.isfinite(diff).all() else float("inf")
    bitwise = int(np.count_nonzero(got.view(np.uint32) != want.view(np.uint32)))
    alpha = got.reshape(pes, 4, vstride)[:, 3, :]
    print(f"pyopencl {cl.VERSION_TEXT} on {dev.name.strip()} ({dev.platform.name.strip()})")
    print(f"kernels from {args.kernels}")
    print(f"{kernel_name}: {pes} PEs x {vstride} positions, defines "
          + " ".join(f"{k}={v}" for k, v in meta["defines"]))
    print(f"sum of alpha (Python) {float(alpha.sum(dtype=np.float64)):.4f}; "
          f"max |Python - C++| {max_diff:.3g} (tol {TOL:g}); "
          f"{bitwise} of {n} floats differ bitwise")
    ok = max_diff <= TOL
    print("pyopencl-check: " + ("Python result equals the C++ one" if ok else "FAILED"))
    return 0 if ok else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Exception as e:  # noqa: BLE001
        print(f"pyopencl-check: {e}", file=sys.stderr)
        sys.exit(2)
