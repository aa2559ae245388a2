// The C interface of libsimdvol_oiio (host/oiio/oiio_module.cpp): the
// OpenImageIO writer (.exr, .tif) and reader (any format OpenImageIO reads)
// that image.cpp loads with dlopen the first time an image needs it.
// OpenImageIO 2.4 on Debian brings about 260 shared libraries; linked into
// every program they cost about 0.3 s of dynamic linking at each start,
// whether an image is read or not (`simdvol --version` took 0.43 s).
// PNG, the format of `render`'s default output, is written with libpng
// (image.cpp), so a render to .png never loads the module.
// Private to simdvol: not installed as a header.
#pragma once

/// Bumped whenever a signature below changes; the loader refuses a module
/// of another version.
#define SIMDVOL_OIIO_ABI 3

extern "C" {
/// SIMDVOL_OIIO_ABI of the module.
typedef int (*simdvol_oiio_abi_fn)(void);
/// Writes w x h premultiplied float RGBA pixels (rows top to bottom) to the
/// open file `fd` (left open; written through a duplicate), `path` naming
/// it in OpenImageIO's messages: format 1 = OpenEXR (half RGBA), 2 = TIFF
/// (float RGBA, zip). Returns 0 on success, else an error message to free
/// with simdvol_oiio_free.
typedef char* (*simdvol_oiio_write_fn)(const char* path, int fd, int format, int w, int h,
                                       const float* rgba);
/// Reads the first subimage of `path` as float RGBA (*rgba: w * h * 4
/// floats, to free with simdvol_oiio_free): 1 channel is grey, 2 grey and
/// alpha, 3 RGB, 4 or more RGBA (alpha where the file says, else the fourth
/// channel); a missing alpha is 1 (*has_alpha 0, else 1). Returns 0 on
/// success, else an error message to free with simdvol_oiio_free.
typedef char* (*simdvol_oiio_read_fn)(const char* path, int* w, int* h, float** rgba,
                                      int* has_alpha);
typedef void (*simdvol_oiio_free_fn)(void* p);
}
