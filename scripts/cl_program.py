"""What the Python hosts of simdvol's kernels share (scripts/pyopencl-check.py,
tests/kernel_abi/kernel_abi_check.py): a stage's program assembled as
docs/KERNELS.md section 1 says, the device examples/embed picks, the
rounding up that the sizes take, and the work-group sizes section 1 allows
on a device (or for a kernel) that takes fewer work-items than asked."""
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


class WorkGroupLimits:
    """Section 1's limits on a local size: CL_DEVICE_MAX_WORK_ITEM_SIZES per
    dimension, and CL_DEVICE_MAX_WORK_GROUP_SIZE and the kernel's
    CL_KERNEL_WORK_GROUP_SIZE on the product (host/cl/device.cpp's
    WorkGroupLimits)."""

    def __init__(self, device, kernel=None):
        self.per_dimension = list(device.max_work_item_sizes)
        self.device_total = device.max_work_group_size
        self.kernel_total = self.device_total
        self.of_kernel = kernel is not None
        if kernel is not None:
            self.kernel_total = kernel.get_work_group_info(
                cl.kernel_work_group_info.WORK_GROUP_SIZE, device)

    def total(self):
        return min(self.device_total, self.kernel_total)

    def fits(self, local):
        product = 1
        for d, n in enumerate(local):
            if n < 1 or n > self.per_dimension[d]:
                return False
            product *= n
        return product <= self.total()

    def describe(self):
        s = self.per_dimension
        text = (f"CL_DEVICE_MAX_WORK_GROUP_SIZE {self.device_total}, CL_DEVICE_MAX_WORK_ITEM_SIZES "
                f"{' x '.join(str(n) for n in s)}")
        if self.of_kernel:
            text += f", the kernel's CL_KERNEL_WORK_GROUP_SIZE {self.kernel_total}"
        return text


def fit_work_group(wanted, limits):
    """Section 1 (fit_work_group): `wanted` where it fits, else each
    dimension halved until it fits its own limit, then the last dimension
    above 1 halved, then the one before it, until the product fits."""
    w = [max(int(n), 1) for n in wanted]
    if limits.fits(w):
        return tuple(w)
    for d in range(len(w)):
        while w[d] > 1 and w[d] > limits.per_dimension[d]:
            w[d] = (w[d] + 1) // 2

    def product():
        p = 1
        for n in w:
            p *= n
        return p

    for d in reversed(range(len(w))):
        while w[d] > 1 and product() > limits.total():
            w[d] = (w[d] + 1) // 2
    return tuple(w)


def fixed_group_size(device, most=64):
    """Section 1: the WGS of the reqd_work_group_size kernels (layout, match,
    balance): 64, or the largest power of two the device takes in a group
    and along x (Device::wgs())."""
    limits = WorkGroupLimits(device)
    cap = min(max(most, 1), limits.per_dimension[0], limits.total())
    p = 1
    while p <= cap // 2:
        p <<= 1
    return p
