"""Minimal reader for simdvol's float32 RGBA TIFF (uncompressed or Deflate,
predictor none/horizontal/floating-point, strips or tiles, chunky)."""
import struct, zlib
import numpy as np

TYPES = {1: 'B', 2: 's', 3: 'H', 4: 'I', 5: 'II', 6: 'b', 7: 'B', 8: 'h', 9: 'i', 11: 'f', 12: 'd', 16: 'Q'}
SIZES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 11: 4, 12: 8, 16: 8}


def read_tiff(path, verbose=False):
    data = open(path, 'rb').read()
    bo = {b'II': '<', b'MM': '>'}[data[:2]]
    assert struct.unpack(bo + 'H', data[2:4])[0] == 42, 'not a classic TIFF'
    off = struct.unpack(bo + 'I', data[4:8])[0]
    n = struct.unpack(bo + 'H', data[off:off + 2])[0]
    tags = {}
    for e in range(n):
        p = off + 2 + 12 * e
        tag, typ, cnt = struct.unpack(bo + 'HHI', data[p:p + 8])
        sz = SIZES[typ] * cnt
        vp = p + 8 if sz <= 4 else struct.unpack(bo + 'I', data[p + 8:p + 12])[0]
        raw = data[vp:vp + sz]
        if typ == 2:
            val = raw.rstrip(b'\0').decode('latin1')
        else:
            val = list(struct.unpack(bo + TYPES[typ] * cnt if typ != 5 else bo + 'I' * 2 * cnt, raw))
        tags[tag] = val
    if verbose:
        for k, v in tags.items():
            print(k, v if not isinstance(v, list) or len(v) < 8 else v[:8])
    W, H = tags[256][0], tags[257][0]
    bps = tags[258]
    spp = tags.get(277, [1])[0]
    comp = tags.get(259, [1])[0]
    pred = tags.get(317, [1])[0]
    fmt = tags.get(339, [1])[0]
    planar = tags.get(284, [1])[0]
    assert planar == 1 and all(b == 32 for b in bps) and fmt == 3, (planar, bps, fmt)
    tiled = 322 in tags
    if tiled:
        tw, th = tags[322][0], tags[323][0]
        offs, cnts = tags[324], tags[325]
    else:
        tw, th = W, tags.get(278, [H])[0]
        offs, cnts = tags[273], tags[279]
    img = np.zeros((H, W, spp), np.float32)

    def decode(chunk, w, h):
        if comp == 1:
            b = chunk
        elif comp in (8, 32946):
            b = zlib.decompress(chunk)
        else:
            raise ValueError('compression %d' % comp)
        if pred == 3:  # floating-point predictor: byte-delta then byte planes
            a = np.frombuffer(b, np.uint8).reshape(h, w * 4, spp).copy()
            a = np.cumsum(a, axis=1, dtype=np.uint8)  # libtiff: differences at stride spp
            a = a.reshape(h, 4, w * spp)
            a = a.reshape(h, 4, w * spp)  # byte planes, most significant first
            out = np.zeros((h, w * spp, 4), np.uint8)
            for plane in range(4):
                out[:, :, plane] = a[:, plane, :]
            return out.view('>f4').reshape(h, w, spp).astype(np.float32)
        arr = np.frombuffer(b, bo + 'f4').reshape(h, w, spp).astype(np.float32)
        if pred == 2:
            raise ValueError('horizontal predictor on float')
        return arr

    if tiled:
        tx = (W + tw - 1) // tw
        for t, (o, c) in enumerate(zip(offs, cnts)):
            ty_, tx_ = divmod(t, tx)
            tile = decode(data[o:o + c], tw, th)
            y0, x0 = ty_ * th, tx_ * tw
            hh, ww = min(th, H - y0), min(tw, W - x0)
            img[y0:y0 + hh, x0:x0 + ww] = tile[:hh, :ww]
    else:
        for s, (o, c) in enumerate(zip(offs, cnts)):
            y0 = s * tw * 0 + s * th
            h = min(th, H - y0)
            img[y0:y0 + h] = decode(data[o:o + c], W, h)
    return img

if __name__ == '__main__':
    import sys
    im = read_tiff(sys.argv[1], verbose=True)
    print(im.shape, im.min(axis=(0, 1)), im.max(axis=(0, 1)))
