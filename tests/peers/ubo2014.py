"""An independent writer and reader of the Bonn UBO2014 .btf formats, for tests/ubo2014.rs.

Written from btflib's documentation of the layout (Merzbach, University of Bonn; the Matlab
readers read_meta_data, read_bidir_sampling, read_common_header, read_ubo_fmf, read_ubo_dfmf,
read_ubo_pvf, undecorrelate, restore_dynamic_range), not from mesoflow's Rust code. numpy's
float16 does the half-float conversion.

    python ubo2014.py write VARIANT OUT_DIR   writes OUT_DIR/VARIANT.btf, the factors exactly as
        stored (OUT_DIR/VARIANT.NAME.npy, float32 in file layout) and the expanded BTF in
        mesoflow's convention (OUT_DIR/VARIANT.expected.npy: pairs × 3 × H × W, float32,
        view-major pairs, cos θi included).
    python ubo2014.py read FILE OUT_PREFIX    reads a DFMF file and writes OUT_PREFIX.NAME.npy
        and OUT_PREFIX.expected.npy the same way.
"""
import struct
import sys

import numpy as np

EPS = 1e-5  # btflib's dynamic-range offset
YUV2RGB = np.array([[1, 0, 1.13983], [1, -0.39465, -0.5806], [1, 2.03211, 0]])
VARIANTS = ["dfmf_rgb", "dfmf_yuv_transposed", "dfmf_pca_f32", "fmf12_log_heightmap",
            "fmf06r_images", "fmf06", "pvf06r_lightfield", "pvf06_legacy_images"]


def meta_block(version, cosine, channels=("R", "G", "B")):
    body = struct.pack("<I", version)
    for s in (b"peer setup", b"peer sensor", b"peer light"):
        body += s.ljust(80, b"\0")
    body += struct.pack("<f", 0.1) + struct.pack("<3f", 1, 1, 1)
    if version > 1:
        body += struct.pack("<I", cosine)
    if version > 2:
        xml = b"<measurement/>"
        body += struct.pack("<I", len(xml)) + xml
    if version > 3:
        body += struct.pack("<I", len(channels))
        for c in channels:
            body += struct.pack("<I", len(c)) + c.encode()
    return struct.pack("<I", len(body) + 4) + body


def directions(views, lights):
    out = struct.pack("<I", len(views))
    for v in views:
        out += struct.pack("<2f", *v) + struct.pack("<I", len(lights))
        for l in lights:
            out += struct.pack("<2f", *l)
    return out


def scalars(a, size):
    return np.asarray(a, dtype={2: "<f2", 4: "<f4", 8: "<f8"}[size]).tobytes()


def stored(a, size):
    """The values as the file holds them, as float64."""
    return np.asarray(a, dtype={2: np.float16, 4: np.float32, 8: np.float64}[size]).astype(np.float64)


def svd_block(size, rows, cols, k, rng):
    s = stored(np.sort(rng.uniform(0.5, 2.0, k))[::-1], size)
    u = stored(rng.normal(0, 0.3, (rows, k)), size)
    sxv = stored(rng.normal(0, 0.3, (cols, k)), size)
    return s, u, sxv


def svd_bytes(size, s, u, sxv):
    return (struct.pack("<B", size) + struct.pack("<III", len(s), u.shape[0], sxv.shape[0])
            + scalars(s, size) + scalars(u, size) + scalars(sxv, size))


def to_mesoflow(values, views, lights, w, h, cosine):
    """values[c, l + nL·v, y + h·x] -> pairs × 3 × H × W, with cos θi if the file lacks it."""
    nl, nv = len(lights), len(views)
    out = np.zeros((nv * nl, 3, h, w))
    for v in range(nv):
        for l in range(nl):
            a = l + nl * v
            img = values[:, a, :].reshape(3, w, h).transpose(0, 2, 1)  # texel y + h·x
            out[v * nl + l] = img * (1.0 if cosine else np.cos(lights[l][0]))
    return out.astype(np.float32)


def write(variant, out_dir):
    rng = np.random.default_rng(VARIANTS.index(variant) + 1)
    views = [(0.0, 0.0), (0.6, 1.2)]
    lights = [(0.1, 0.0), (0.7, 2.0), (1.1, 4.0)]
    w, h, nl, nv = 5, 4, 3, 2
    t, na = w * h, nl * nv
    rot = struct.pack("<I", 1) + np.eye(3, dtype="<f4").tobytes()
    factors = {}
    if variant.startswith("dfmf"):
        sig, size = b"!DFMF08FCR", 4 if variant == "dfmf_pca_f32" else 2
        model = {"dfmf_rgb": 0, "dfmf_yuv_transposed": 1, "dfmf_pca_f32": 3}[variant]
        cosine = 1
        mean = np.array([0.2, 0.3, 0.1], dtype=np.float32)
        mat = (np.eye(3) + rng.normal(0, 0.1, (3, 3))).astype(np.float32) if model == 3 else np.eye(3, dtype=np.float32)
        body = rot + struct.pack("<I", 3) + struct.pack("<i", model) + mean.tobytes() + mat.tobytes()
        chans = []
        for c in range(3):
            k = 2 + c
            transposed = variant == "dfmf_yuv_transposed"
            s, u, sxv = svd_block(size, t if transposed else na, na if transposed else t, k, rng)
            body += svd_bytes(size, s, u, sxv)
            factors[f"u{c}"], factors[f"sxv{c}"] = u, sxv
            prod = sxv @ u.T if transposed else u @ sxv.T  # angles × texels
            chans.append(prod)
        vals = np.stack(chans)  # channel, angle, texel
        flat = vals.reshape(3, -1).T
        if model == 1:
            flat = flat @ YUV2RGB.T
        elif model == 3:
            flat = flat @ mat.astype(np.float64) + mean.astype(np.float64)
        vals = flat.T.reshape(3, na, t)
        data = sig + meta_block(4, cosine) + directions(views, lights) + struct.pack("<II", w, h) + body
    elif variant.startswith("fmf"):
        size = 2
        if variant == "fmf12_log_heightmap":
            sig, version, cosine = b"!FMF12FCER", 3, 0
            hm = stored(rng.uniform(0, 1, (3, 2)), 2)
            extra = struct.pack("<B", 2) + struct.pack("<I", 1) + struct.pack("<II", 3, 2) + scalars(hm, 2)
        elif variant == "fmf06r_images":
            sig, version, cosine, extra = b"!FMF06FCR", 2, 1, b""
        else:
            sig, version, cosine, extra = b"!FMF06FC", 1, 0, b""
        k = 3
        images = variant == "fmf06r_images"
        s, u, sxv = svd_block(size, 3 * t if images else 3 * na, na if images else t, k, rng)
        factors["u0"], factors["sxv0"] = u, sxv
        if images:
            # U rows c + 3·texel, S×V rows angles.
            vals = np.einsum("ctk,ak->cat", u.reshape(t, 3, k).transpose(1, 0, 2), sxv)
        else:
            # U rows c + 3·angle, S×V rows texels.
            vals = np.einsum("cak,tk->cat", u.reshape(na, 3, k).transpose(1, 0, 2), sxv)
        if variant == "fmf12_log_heightmap":
            vals = np.exp(vals) - EPS
        head = sig + meta_block(version, cosine) + directions(views, lights) + struct.pack("<II", w, h)
        if sig.endswith(b"R"):
            head += rot
        data = head + extra + struct.pack("<I", k) + svd_bytes(size, s, u, sxv)
    else:
        size = 2
        legacy = variant == "pvf06_legacy_images"
        k = 2
        if legacy:
            sig, cosine = b"!PVF06FC", 0
            data = sig + struct.pack("<i", 301074) + struct.pack("<IIII", k, w, h, nv) + directions(views, lights)
        else:
            sig, cosine = b"!PVF06FCR", 1
            data = sig + meta_block(3, cosine) + directions(views, lights) + struct.pack("<II", w, h) + rot
            data += struct.pack("<II", k, nv)
        vals = np.zeros((3, na, t))
        for v in range(nv):
            dim, nw = (3 * t, nl) if legacy else (3 * nl, t)
            ev = stored(rng.uniform(0.5, 2, k), size)
            m = stored(rng.uniform(0, 0.5, dim), size)
            cm = stored(rng.normal(0, 0.3, (dim, k)), size)
            wm = stored(rng.normal(0, 0.3, (nw, k)), size)
            factors[f"c{v}"], factors[f"w{v}"], factors[f"m{v}"] = cm, wm, m
            data += (struct.pack("<B", size) + struct.pack("<III", k, nw, dim)
                     + scalars(ev, size) + scalars(m, size) + scalars(cm, size) + scalars(wm, size))
            if legacy:  # rows c + 3·texel, weights per light
                x = (cm @ wm.T + m[:, None]).reshape(t, 3, nl)  # texel, c, light
                vals[:, v * nl:(v + 1) * nl, :] = x.transpose(1, 2, 0)
            else:  # rows c + 3·light, weights per texel
                x = (wm @ cm.T + m[None, :]).reshape(t, nl, 3)  # texel, light, c
                vals[:, v * nl:(v + 1) * nl, :] = x.transpose(2, 1, 0)
    with open(f"{out_dir}/{variant}.btf", "wb") as f:
        f.write(data)
    for k, v in factors.items():
        np.save(f"{out_dir}/{variant}.{k}.npy", v.astype(np.float32))
    np.save(f"{out_dir}/{variant}.expected.npy", to_mesoflow(vals, views, lights, w, h, cosine))


def read(path, prefix):
    """A DFMF reader (the variant mesoflow writes)."""
    b = open(path, "rb").read()
    assert b[:10] == b"!DFMF08FCR", b[:10]
    at = 10
    size, version = struct.unpack_from("<II", b, at)
    cosine = struct.unpack_from("<I", b, at + 8 + 240 + 16)[0] if version > 1 else 0
    at += size
    nv = struct.unpack_from("<I", b, at)[0]
    at += 4
    views, lights = [], []
    for _ in range(nv):
        views.append(struct.unpack_from("<2f", b, at))
        nl = struct.unpack_from("<I", b, at + 8)[0]
        at += 12
        lights = [struct.unpack_from("<2f", b, at + 8 * i) for i in range(nl)]
        at += 8 * nl
    w, h = struct.unpack_from("<II", b, at)
    at += 8
    nrot = struct.unpack_from("<I", b, at)[0]
    at += 4 + 36 * nrot
    _, model = struct.unpack_from("<Ii", b, at)
    at += 8 + 12 + 36
    chans, factors = [], {}
    for c in range(3):
        sz = b[at]
        k, rows, cols = struct.unpack_from("<III", b, at + 1)
        at += 13
        dt = {2: "<f2", 4: "<f4", 8: "<f8"}[sz]
        take = lambda n: np.frombuffer(b, dt, n, at).astype(np.float64)
        at += k * sz
        u = take(rows * k).reshape(rows, k)
        at += rows * k * sz
        sxv = take(cols * k).reshape(cols, k)
        at += cols * k * sz
        factors[f"u{c}"], factors[f"sxv{c}"] = u, sxv
        chans.append(u @ sxv.T)
    assert at == len(b), (at, len(b))
    flat = np.stack(chans).reshape(3, -1).T
    if model == 1:
        flat = flat @ YUV2RGB.T
    vals = flat.T.reshape(3, len(views) * len(lights), w * h)
    for k, v in factors.items():
        np.save(f"{prefix}.{k}.npy", v.astype(np.float32))
    np.save(f"{prefix}.expected.npy", to_mesoflow(vals, views, lights, w, h, cosine))


if __name__ == "__main__":
    if sys.argv[1] == "write":
        write(sys.argv[2], sys.argv[3])
    elif sys.argv[1] == "list":
        print("\n".join(VARIANTS))
    else:
        read(sys.argv[2], sys.argv[3])
