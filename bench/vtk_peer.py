#!/usr/bin/env python3
"""VTK's CPU ray caster as a peer of simdvol (issue 5).

Renders a VolPack .den volume (data/brainsmall.den) with VTK's
vtkFixedPointVolumeRayCastMapper, offscreen, with VolPack's example
classification as simdvol's `--classify volpack` preset defines it, Phong
shading with simdvol's default coefficients and light, and the camera of
simdvol's `--view THETA,PHI,VARPHI`; then times N renders.

Run it with Debian's python (/usr/bin/python3, where python3-vtk9 lives),
under xvfb-run when there is no DISPLAY; scripts/bench-vtk does both and runs
simdvol beside it. scripts/install-peers installs VTK and xvfb.

What is the same as simdvol's render and what is not (see also --help):
  same:  the volume and its voxel grid (spacing 1, simdvol's volume centre
         n/2 at the image centre), an orthographic camera whose rows are
         simdvol's rotation T(theta, phi, varphi) (image right T[0], image
         down T[1], into the scene T[2]), the longest side spanning
         min(W, H) pixels; trilinear interpolation; sample distance 1 voxel
         (no opacity correction: VTK's unit distance is 1); the density ramp
         0 0, 24 1, 255 1 and the gradient ramp 0 0, 5 0, 20 1, 221 1 over
         the same gradient magnitude (central differences / 2 in value units:
         VTK's 8-bit magnitude covers 0 .. range / 4, where the ramp is
         already 1); white; ka kd ks n = 0.25 0.75 0.35 24, one directional
         light from simdvol's default direction (-0.4, -0.5, -1) in viewing
         space, the halfway vector H = (V + L) / |V + L|.
  not:   VTK classifies the interpolated sample (post-classification),
         simdvol classifies voxels and interpolates their colours
         (pre-classification, as VolPack); VTK shades from 8-bit gradient
         magnitudes and 16-bit encoded normals per voxel; VTK's two-sided
         lighting turns the normal towards the viewer, then max(N.L, 0), and
         adds specular only where N.L > 0, simdvol uses |N.L| and |N.H|;
         no depth cueing in VTK (simdvol's default 1 / (1 + 0.6 d));
         VTK casts one ray per output pixel (--image-sample-distance 1) where
         simdvol (--sampling voxel) casts one per voxel column and scales the
         image bilinearly; VTK stops a ray at an opacity near 1 and leaps
         empty space with its min-max volume; VTK computes the gradients
         once per volume (in the warm-up render), simdvol shades and
         classifies every frame.
"""

import argparse
import json
import os
import statistics
import struct
import sys
import tempfile
import time

DEN_HEADER = 62


class PeerError(Exception):
    """A bad input: the message names the file or the argument."""


def read_den_header(path):
    """Parses a VolPack .den header (as host/core/io.cpp load_den).

    A 62-byte header in the writer's byte order: int16 map_version (1; its
    byte order gives the file's), 27 int16 min/max/len fields (the dims are
    map_len at byte 50), int16 map_warps, int32 map_length (the voxel count,
    byte 58); then map_length 8-bit voxels, x fastest. Returns
    (dims, byte_order); raises PeerError naming the file otherwise.
    """
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as f:
            head = f.read(DEN_HEADER)
    except FileNotFoundError:
        raise PeerError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise PeerError(f"{path}: is a directory, not a .den file") from None
    except OSError as e:
        raise PeerError(f"{path}: cannot read: {e.strerror}") from None
    if len(head) < 2:
        raise PeerError(f"{path}: not a VolPack .den file (truncated header, {len(head)} bytes)")
    if head[0] == 1 and head[1] == 0:
        order = "<"
    elif head[0] == 0 and head[1] == 1:
        order = ">"
    else:
        raise PeerError(
            f"{path}: not a VolPack .den file (bad version/magic {head[0]} {head[1]})")
    if len(head) < DEN_HEADER:
        raise PeerError(f"{path}: truncated header ({len(head)} of {DEN_HEADER} bytes)")
    dims = struct.unpack_from(order + "3h", head, 50)
    (map_length,) = struct.unpack_from(order + "i", head, 58)
    if min(dims) <= 0:
        raise PeerError(f"{path}: bad dims {dims[0]} x {dims[1]} x {dims[2]} in the header")
    count = dims[0] * dims[1] * dims[2]
    if map_length != count:
        raise PeerError(f"{path}: inconsistent header: map_length {map_length} is not the "
                        f"product of the dims {dims[0]} x {dims[1]} x {dims[2]}")
    if size != DEN_HEADER + count:
        raise PeerError(f"{path}: file has {size} bytes, the header's dims "
                        f"{dims[0]} x {dims[1]} x {dims[2]} need {DEN_HEADER + count}")
    return tuple(dims), order


def read_den(path):
    """The header's dims and the voxels (bytes, x fastest)."""
    dims, _ = read_den_header(path)
    with open(path, "rb") as f:
        f.seek(DEN_HEADER)
        voxels = f.read()
    return dims, voxels


def rotation(theta, phi, varphi):
    """simdvol's T(theta, phi, varphi) (host/core/view.cpp, thesis eq 5.2):
    object -> viewing space, rows: image right, image down, into the scene."""
    import math

    d = math.pi / 180.0
    ct, st = math.cos(theta * d), math.sin(theta * d)
    cp, sp = math.cos(phi * d), math.sin(phi * d)
    cv, sv = math.cos(varphi * d), math.sin(varphi * d)
    a = [[0, 0, 1], [-sv, cv, 0], [cv, sv, 0]]
    b = [[sp, 0, cp], [0, 1, 0], [cp, 0, -sp]]
    c = [[ct, st, 0], [-st, ct, 0], [0, 0, 1]]

    def mul(x, y):
        return [[sum(x[i][k] * y[k][j] for k in range(3)) for j in range(3)] for i in range(3)]

    return mul(a, mul(b, c))


def parse_view(text):
    parts = text.split(",")
    try:
        if len(parts) != 3:
            raise ValueError
        return tuple(float(p) for p in parts)
    except ValueError:
        raise PeerError(f"--view: expected THETA,PHI,VARPHI in degrees, got '{text}'") from None


def parse_size(text):
    parts = text.lower().split("x")
    try:
        if len(parts) == 1:
            parts = parts * 2
        w, h = (int(p) for p in parts)
    except ValueError:
        raise PeerError(f"--size: expected WxH or N, got '{text}'") from None
    if w <= 0 or h <= 0 or w > 8192 or h > 8192:
        raise PeerError(f"--size: {w}x{h} must be 1 .. 8192 on each side")
    return w, h


def default_threads():
    t = os.environ.get("POCL_MAX_PTHREAD_COUNT")
    if t and t.isdigit() and int(t) > 0:
        return int(t)
    return os.cpu_count() or 1


def render(args, dims, voxels):
    try:
        import numpy as np
        import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: F401 (the OpenGL display helper)
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401 (the render window)
        from vtkmodules.util.numpy_support import numpy_to_vtk
        from vtkmodules.vtkCommonCore import vtkCommand
        from vtkmodules.vtkCommonDataModel import vtkImageData, vtkPiecewiseFunction
        from vtkmodules.vtkIOImage import vtkPNGWriter
        from vtkmodules.vtkRenderingCore import (vtkColorTransferFunction, vtkLight, vtkRenderer,
                                                 vtkRenderWindow, vtkVolume, vtkVolumeProperty,
                                                 vtkWindowToImageFilter)
        from vtkmodules.vtkRenderingVolume import vtkFixedPointVolumeRayCastMapper
    except ImportError as e:
        raise PeerError(f"cannot import VTK ({e}); run scripts/install-peers and use Debian's "
                        f"/usr/bin/python3 (python3-vtk9)") from None

    nx, ny, nz = dims
    arr = np.frombuffer(voxels, dtype=np.uint8)
    image = vtkImageData()
    image.SetDimensions(nx, ny, nz)
    image.SetSpacing(1.0, 1.0, 1.0)
    image.SetOrigin(0.0, 0.0, 0.0)
    scalars = numpy_to_vtk(arr, deep=True)
    scalars.SetName("density")
    image.GetPointData().SetScalars(scalars)

    # VolPack's example classification (simdvol's `--classify volpack`).
    opacity = vtkPiecewiseFunction()
    for x, y in ((0, 0), (24, 1), (255, 1)):
        opacity.AddPoint(x, y)
    # The argument of VTK's gradient opacity is |central difference| / 2 in
    # value units (spacing 1), simdvol's |g|: the same ramp.
    gradient = vtkPiecewiseFunction()
    for x, y in ((0, 0), (5, 0), (20, 1), (221, 1)):
        gradient.AddPoint(x, y)
    colour = vtkColorTransferFunction()
    colour.AddRGBPoint(0, 1, 1, 1)
    colour.AddRGBPoint(255, 1, 1, 1)

    prop = vtkVolumeProperty()
    prop.SetScalarOpacity(opacity)
    prop.SetGradientOpacity(gradient)
    prop.SetColor(colour)
    prop.SetInterpolationTypeToLinear()
    prop.SetScalarOpacityUnitDistance(1.0)
    prop.SetShade(0 if args.no_shade else 1)
    prop.SetAmbient(0.25)
    prop.SetDiffuse(0.75)
    prop.SetSpecular(0.35)
    prop.SetSpecularPower(24.0)

    mapper = vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(image)
    mapper.SetNumberOfThreads(args.threads)
    mapper.SetBlendModeToComposite()
    mapper.AutoAdjustSampleDistancesOff()  # else it trades rays for a frame-rate target
    mapper.LockSampleDistanceToInputSpacingOff()
    mapper.SetSampleDistance(1.0)
    mapper.SetImageSampleDistance(args.image_sample_distance)
    mapper.SetIntermixIntersectingGeometry(0)  # nothing else in the scene

    volume = vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)

    ren = vtkRenderer()
    ren.SetBackground(0, 0, 0)
    ren.AddVolume(volume)
    ren.SetTwoSidedLighting(1)
    ren.AutomaticLightCreationOff()

    # The camera of simdvol's view: T's rows are image right, image down and
    # the viewing direction in object (voxel index) space; simdvol's image
    # centre is the volume's centre n / 2; orthographic, the longest side
    # spanning min(W, H) pixels: parallel scale (half the viewport height
    # in voxels) = longest / 2 * H / min(W, H).
    t = rotation(*args.view)
    centre = [0.5 * n for n in dims]
    longest = max(dims)
    width, height = args.size
    cam = ren.GetActiveCamera()
    cam.ParallelProjectionOn()
    dist = 4.0 * longest
    cam.SetFocalPoint(*centre)
    cam.SetPosition(*(centre[a] - dist * t[2][a] for a in range(3)))
    cam.SetViewUp(*(-t[1][a] for a in range(3)))
    cam.SetParallelScale(0.5 * longest * height / min(width, height))
    cam.SetClippingRange(dist - longest, dist + longest)

    # simdvol's default light: towards the light (-0.4, -0.5, -1) in viewing
    # space (x right, y down, z into the scene), taken to object space with
    # T^T; a directional scene light of intensity 1, white.
    lv = (-0.4, -0.5, -1.0)
    ldir = [sum(t[r][a] * lv[r] for r in range(3)) for a in range(3)]
    light = vtkLight()
    light.SetLightTypeToSceneLight()
    light.PositionalOff()
    light.SetFocalPoint(*centre)
    light.SetPosition(*(centre[a] + ldir[a] for a in range(3)))
    light.SetAmbientColor(1, 1, 1)  # VTK's ambient term is ka x the light's ambient colour
    light.SetDiffuseColor(1, 1, 1)
    light.SetSpecularColor(1, 1, 1)
    light.SetIntensity(1.0)
    ren.AddLight(light)

    win = vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetSize(width, height)
    win.AddRenderer(ren)

    casts = [0]

    def count(_obj, _event):
        casts[0] += 1

    mapper.AddObserver(vtkCommand.VolumeMapperRenderEndEvent, count)

    t0 = time.perf_counter()
    win.Render()  # warm-up: gradients, tables, the GL context
    warm_ms = (time.perf_counter() - t0) * 1e3
    warm_draw_ms = mapper.GetTimeToDraw() * 1e3
    if casts[0] != 1:
        raise PeerError(f"the warm-up render ran the ray caster {casts[0]} times, expected 1")

    wall, draw = [], []
    for i in range(args.frames):
        # Force a new cast: the camera and the volume are marked modified
        # (the view itself stays the same).
        cam.Modified()
        volume.Modified()
        before = casts[0]
        t0 = time.perf_counter()
        win.Render()
        wall.append((time.perf_counter() - t0) * 1e3)
        draw.append(mapper.GetTimeToDraw() * 1e3)
        if casts[0] != before + 1:
            raise PeerError(f"frame {i}: the mapper did not ray cast ({casts[0] - before} casts)")

    png = None
    if args.png:
        grab = vtkWindowToImageFilter()
        grab.SetInput(win)
        grab.SetInputBufferTypeToRGB()
        grab.ReadFrontBufferOff()
        grab.Update()
        writer = vtkPNGWriter()
        writer.SetFileName(args.png)
        writer.SetInputConnection(grab.GetOutputPort())
        writer.Write()
        png = args.png
        if writer.GetErrorCode():
            raise PeerError(f"--png: cannot write {args.png}")

    from vtkmodules.vtkCommonCore import vtkVersion

    return {
        "renderer": "vtkFixedPointVolumeRayCastMapper",
        "vtk": vtkVersion.GetVTKVersion(),
        "render_window": win.GetClassName(),
        "volume": args.volume,
        "dims": list(dims),
        "size": [width, height],
        "view": list(args.view),
        "threads": args.threads,
        "image_sample_distance": args.image_sample_distance,
        "shade": not args.no_shade,
        "frames": args.frames,
        "warmup_ms": warm_ms,
        "warmup_cast_ms": warm_draw_ms,
        "wall_ms": wall,
        "cast_ms": draw,
        "median_ms": statistics.median(wall),
        "min_ms": min(wall),
        "max_ms": max(wall),
        "median_cast_ms": statistics.median(draw),
        "casts": casts[0],
        "png": png,
    }


def self_test(volume):
    """Checks the parts that need no VTK (the .den reader, the argument
    checks, the rotation): 0 when they pass, 1 otherwise; 77 (ctest's skip)
    when `volume` is missing and SIMDVOL_REQUIRE_DATA is not 1."""
    import tempfile

    failures = []

    def check(cond, what):
        if not cond:
            failures.append(what)

    def refused(path, words):
        try:
            read_den_header(path)
        except PeerError as e:
            msg = str(e)
            return path in msg and all(w in msg for w in words)
        return False

    with tempfile.TemporaryDirectory() as tmp:
        def den(name, order, dims, map_length=None, extra=0, magic=None):
            head = bytearray(DEN_HEADER)
            struct.pack_into(order + "h", head, 0, 1)
            if magic is not None:
                head[0:2] = magic
            struct.pack_into(order + "3h", head, 50, *dims)
            count = dims[0] * dims[1] * dims[2]
            struct.pack_into(order + "i", head, 58, count if map_length is None else map_length)
            path = os.path.join(tmp, name)
            with open(path, "wb") as f:
                f.write(bytes(head) + bytes(max(count + extra, 0)))
            return path

        def parsed(path):
            try:
                return read_den_header(path)
            except PeerError as e:
                return str(e)

        check(parsed(den("le.den", "<", (2, 3, 4))) == ((2, 3, 4), "<"),
              "little-endian 2x3x4 header")
        check(parsed(den("be.den", ">", (5, 1, 2))) == ((5, 1, 2), ">"),
              "big-endian 5x1x2 header")
        check(refused(den("magic.den", "<", (2, 2, 2), magic=b"P6"), ["not a VolPack .den"]),
              "a bad magic is refused, naming the file")
        check(refused(den("len.den", "<", (2, 2, 2), map_length=9), ["map_length 9"]),
              "a map_length that is not the product of the dims is refused")
        check(refused(den("short.den", "<", (4, 4, 4), extra=-1), ["need 126"]),
              "a truncated file is refused")
        check(refused(den("long.den", "<", (4, 4, 4), extra=3), ["need 126"]),
              "trailing bytes are refused")
        cut = os.path.join(tmp, "cut.den")
        with open(cut, "wb") as f:
            f.write(b"\x01\x00" + bytes(20))
        check(refused(cut, ["truncated header"]), "a truncated header is refused")
        check(refused(os.path.join(tmp, "none.den"), ["no such file"]), "a missing file")
        import contextlib
        import io

        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            rc_txt = main(["--volume", os.path.join(tmp, "x.nrrd")])
            rc_frames = main(["--frames", "0", "--info"])
            rc_view = main(["--view", "1,2", "--info"])
        check(rc_txt == 2 and "x.nrrd: not a .den file" in err.getvalue(),
              "a volume that is not a .den exits 2 naming it")
        check(rc_frames == 2 and "--frames" in err.getvalue(), "--frames 0 exits 2")
        check(rc_view == 2 and "--view" in err.getvalue(), "--view 1,2 exits 2")

    t = rotation(20, 35, 10)
    det = (t[0][0] * (t[1][1] * t[2][2] - t[1][2] * t[2][1]) -
           t[0][1] * (t[1][0] * t[2][2] - t[1][2] * t[2][0]) +
           t[0][2] * (t[1][0] * t[2][1] - t[1][1] * t[2][0]))
    check(abs(det - 1) < 1e-12, "T(20, 35, 10) is a rotation (det +1)")
    i3 = rotation(0, 0, 0)
    check(all(abs(i3[r][c] - (r == c)) < 1e-12 for r in range(3) for c in range(3)),
          "T(0, 0, 0) is the identity")
    check(all(abs(rotation(0, 30, 0)[1][c] - (c == 1)) < 1e-12 for c in range(3)),
          "phi alone turns about the image's vertical axis")
    check(not any(m.startswith("vtkmodules") for m in sys.modules),
          "the reader and the checks do not import VTK")

    skipped = False
    if os.path.exists(volume):
        try:
            check(read_den_header(volume) == ((128, 128, 84), "<"),
                  f"{volume}: 128 x 128 x 84, little-endian")
        except PeerError as e:
            failures.append(str(e))
    elif os.environ.get("SIMDVOL_REQUIRE_DATA") == "1":
        failures.append(f"{volume}: missing (run scripts/fetch-data)")
    else:
        skipped = True

    for f in failures:
        print(f"vtk_peer.py --self-test: FAILED: {f}", file=sys.stderr)
    if failures:
        return 1
    if skipped:
        print(f"vtk_peer.py --self-test: passed; {volume} missing, skipped (scripts/fetch-data)")
        return 77
    print(f"vtk_peer.py --self-test: passed ({volume}: 128 x 128 x 84)")
    return 0


def main(argv=None):
    here = os.path.dirname(os.path.abspath(__file__))
    p = argparse.ArgumentParser(
        description="VTK's vtkFixedPointVolumeRayCastMapper on a VolPack .den volume with "
        "simdvol's `--classify volpack` classification, shading and view; times N renders.")
    p.add_argument("--volume", default=os.path.join(here, "..", "data", "brainsmall.den"),
                   help="VolPack .den volume (default data/brainsmall.den)")
    p.add_argument("--size", default="256x256", help="output WxH (default 256x256)")
    p.add_argument("--view", default="20,35,10",
                   help="simdvol's --view THETA,PHI,VARPHI in degrees (default 20,35,10)")
    p.add_argument("--frames", type=int, default=20, help="timed renders (default 20)")
    p.add_argument("--threads", type=int, default=default_threads(),
                   help="the mapper's threads (default POCL_MAX_PTHREAD_COUNT, else nproc)")
    p.add_argument("--image-sample-distance", type=float, default=1.0,
                   help="pixels between rays (VTK's default 1: a ray per pixel)")
    p.add_argument("--no-shade", action="store_true", help="no lighting")
    p.add_argument("--png", help="write the last frame to this PNG")
    p.add_argument("--json", help="write the figures to this JSON file")
    p.add_argument("--info", action="store_true",
                   help="only read the volume's header and print its dims (no VTK needed)")
    p.add_argument("--self-test", action="store_true",
                   help="check the .den reader, the argument checks and the rotation on "
                   "--volume (expects brainsmall.den) and made-up headers (no VTK needed)")
    args = p.parse_args(argv)
    if args.self_test:
        return self_test(args.volume)
    prog = os.path.basename(sys.argv[0]) if argv is None else "vtk_peer.py"
    try:
        args.size = parse_size(args.size)
        args.view = parse_view(args.view)
        if args.frames < 1 or args.frames > 100000:
            raise PeerError(f"--frames: {args.frames} must be 1 .. 100000")
        if args.threads < 1 or args.threads > 1024:
            raise PeerError(f"--threads: {args.threads} must be 1 .. 1024")
        if not (0.1 <= args.image_sample_distance <= 16):
            raise PeerError(f"--image-sample-distance: {args.image_sample_distance} must be "
                            "0.1 .. 16")
        if not args.volume.endswith(".den"):
            raise PeerError(f"--volume: {args.volume}: not a .den file (VolPack's format; "
                            "the VTK peer reads only that)")
        if args.info:
            dims, order = read_den_header(args.volume)
            print(f"{args.volume}: VolPack .den, dims {dims[0]} x {dims[1]} x {dims[2]}, u8, "
                  f"{'little' if order == '<' else 'big'}-endian header")
            return 0
        dims, voxels = read_den(args.volume)
        result = render(args, dims, voxels)
    except PeerError as e:
        print(f"{prog}: {e}", file=sys.stderr)
        return 2
    print(f"vtk {result['vtk']} {result['renderer']} ({result['render_window']}), "
          f"{dims[0]}x{dims[1]}x{dims[2]} -> {args.size[0]}x{args.size[1]}, "
          f"{args.threads} threads, image sample distance {args.image_sample_distance:g}: "
          f"warm-up {result['warmup_ms']:.1f} ms; {args.frames} frames: median "
          f"{result['median_ms']:.2f} ms (min {result['min_ms']:.2f}, max "
          f"{result['max_ms']:.2f}); ray cast (mapper's time to draw) median "
          f"{result['median_cast_ms']:.2f} ms")
    if args.json:
        # A temporary file beside it, renamed into place: a failed write (a
        # full disk) leaves the file as it was and no temporary behind.
        tmp = None
        try:
            fd, tmp = tempfile.mkstemp(prefix=os.path.basename(args.json)[:64] + ".tmp-",
                                       dir=os.path.dirname(os.path.abspath(args.json)))
            umask = os.umask(0)
            os.umask(umask)
            os.fchmod(fd, 0o666 & ~umask)  # as open() would make it
            with os.fdopen(fd, "w") as f:
                json.dump(result, f, indent=1)
            os.replace(tmp, args.json)
        except OSError as e:
            if tmp is not None and os.path.exists(tmp):
                os.remove(tmp)
            print(f"{prog}: --json: cannot write {args.json}: {e.strerror}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
