"""What the Python hosts of simdvol's kernels share (scripts/pyopencl-check.py,
tests/kernel_abi/kernel_abi_check.py): a stage's program assembled as
docs/KERNELS.md section 1 says, the device examples/embed picks, and the
rounding up that the sizes take."""
import pyopencl as cl


def program_source(kdir, stage, defines, more=()):
    """Section 1: the #define lines, then simdvol_shared.h, common.cl, the
    stage's file and the further files, each after a #line directive."""
    src = "".join(f"#define {n} {v}\n" for n, v in defines)
    for name in ("simdvol_shared.h", "common.cl", stage + ".cl") + tuple(f + ".cl" for f in more):
        text = (kdir / name).read_text()
        src += f'#line 1 "{name}"\n' + text + ("" if text.endswith("\n") else "\n")
    return src


def round_up(n, m):
    """n rounded up to a multiple of m (a global size to its local size, a
    stride to 16, a height to 8)."""
    return -(-int(n) // m) * m


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
