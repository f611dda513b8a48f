"""Numba kernels of the wavefront path tracer: G-buffer, lobe colours, motion, shading with
next-event estimation and MIS (Lambertian and glossy materials, ``bsdf``), lobe passes.

Every kernel works on a batch of rays (structure of arrays) between two Embree calls. Each
iteration touches only its own rows (and its own path's accumulator row), so the caller can
run row ranges on several threads (the kernels release the GIL; serial kernels compile in
half the time of ``parallel=True`` ones) and results do not depend on the thread count.
Random numbers are counter based: a 64-bit hash of (frame key, path key, dimension), so a
sample's numbers do not depend on batching, ordering or threads either. ``fastmath`` is off
so results are reproducible bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from svgf_trace.bsdf import glossy_eval, glossy_sample, glossy_setup

_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_DIM_STRIDE = np.uint64(0xD1B54A32D192ED03)
_SHIFT30 = np.uint64(30)
_SHIFT27 = np.uint64(27)
_SHIFT31 = np.uint64(31)
_SHIFT11 = np.uint64(11)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2**-53
INV_PI = 1.0 / math.pi

# Random dimensions used per bounce: light pick, 2 for the light point, 2 for the BSDF
# direction, 1 for Russian roulette.
DIMS_PER_BOUNCE = 6
# Fraction of the way to its triangle's centroid a ray origin is moved (see shade_kernel).
EDGE_NUDGE = 1e-4
# Path keys with this bit set give a second stream of numbers per path: the lobe choice of a
# glossy vertex draws from it, so the six dimensions above (and every Lambertian scene's
# samples) stay exactly what they were before glossy materials existed.
LOBE_STREAM = np.uint64(1 << 63)
# shade_kernel's mis_mode values.
MIS_POWER = 0
MIS_BSDF_ONLY = 1
MIS_LIGHT_ONLY = 2


@njit(cache=True)
def _mix64(z: np.uint64) -> np.uint64:
    # splitmix64's finaliser: a bijective avalanche mix of 64 bits.
    z = (z ^ (z >> _SHIFT30)) * _MIX1
    z = (z ^ (z >> _SHIFT27)) * _MIX2
    return z ^ (z >> _SHIFT31)


@njit(cache=True)
def uniform(key: np.uint64, path_key: np.uint64, dim: int) -> float:
    """A uniform double in [0, 1) for (frame key, path, dimension)."""
    h = _mix64(key + path_key * _GOLDEN)
    h = _mix64(h ^ (np.uint64(dim + 1) * _DIM_STRIDE))
    return float(h >> _SHIFT11) * _TO_UNIT


@njit(cache=True)
def _texture(tex_data, offset, width, height, u, v):
    """Bilinear lookup with wrap-around; v = 0 is the bottom row of the image (OBJ)."""
    fu = u - math.floor(u)
    fv = v - math.floor(v)
    x = fu * width - 0.5
    y = (1.0 - fv) * height - 0.5
    x0 = math.floor(x)
    y0 = math.floor(y)
    tx = x - x0
    ty = y - y0
    ix0 = int(x0) % width
    iy0 = int(y0) % height
    ix1 = (ix0 + 1) % width
    iy1 = (iy0 + 1) % height
    r = 0.0
    g = 0.0
    b = 0.0
    for k in range(4):
        ix = ix1 if (k & 1) else ix0
        iy = iy1 if (k & 2) else iy0
        wx = tx if (k & 1) else 1.0 - tx
        wy = ty if (k & 2) else 1.0 - ty
        base = offset + (iy * width + ix) * 3
        w = wx * wy
        r += w * tex_data[base]
        g += w * tex_data[base + 1]
        b += w * tex_data[base + 2]
    return r, g, b


@njit(cache=True)
def _albedo(tri, b0, b1, b2, tri_uv, tri_mat, mat_kd, tex_off, tex_w, tex_h, tex_data):
    m = tri_mat[tri]
    r = mat_kd[m, 0]
    g = mat_kd[m, 1]
    b = mat_kd[m, 2]
    if tex_off[m] >= 0:
        u = b0 * tri_uv[tri, 0, 0] + b1 * tri_uv[tri, 1, 0] + b2 * tri_uv[tri, 2, 0]
        v = b0 * tri_uv[tri, 0, 1] + b1 * tri_uv[tri, 1, 1] + b2 * tri_uv[tri, 2, 1]
        tr, tg, tb = _texture(tex_data, tex_off[m], tex_w[m], tex_h[m], u, v)
        r *= tr
        g *= tg
        b *= tb
    return r, g, b


@njit(cache=True)
def _frame_normals(tri, b0, b1, b2, dx, dy, dz, tri_ng, tri_ns, tri_has_ns):
    """Geometric and shading normals flipped to the side the ray arrives from; also returns
    whether the ray hit the front (winding) side."""
    gx = tri_ng[tri, 0]
    gy = tri_ng[tri, 1]
    gz = tri_ng[tri, 2]
    front = gx * dx + gy * dy + gz * dz < 0.0
    if not front:
        gx, gy, gz = -gx, -gy, -gz
    if tri_has_ns[tri]:
        sx = b0 * tri_ns[tri, 0, 0] + b1 * tri_ns[tri, 1, 0] + b2 * tri_ns[tri, 2, 0]
        sy = b0 * tri_ns[tri, 0, 1] + b1 * tri_ns[tri, 1, 1] + b2 * tri_ns[tri, 2, 1]
        sz = b0 * tri_ns[tri, 0, 2] + b1 * tri_ns[tri, 1, 2] + b2 * tri_ns[tri, 2, 2]
        length = math.sqrt(sx * sx + sy * sy + sz * sz)
        if length > 0.0:
            sx /= length
            sy /= length
            sz /= length
            if sx * gx + sy * gy + sz * gz < 0.0:
                sx, sy, sz = -sx, -sy, -sz
        else:
            sx, sy, sz = gx, gy, gz
    else:
        sx, sy, sz = gx, gy, gz
    return front, gx, gy, gz, sx, sy, sz


@njit(cache=True)
def _centroid(tri_v, t, axis):
    return (tri_v[t, 0, axis] + tri_v[t, 1, axis] + tri_v[t, 2, axis]) / 3.0


@njit(cache=True)
def _barycentrics(u, v):
    """Embree's (u, v) clamped into the triangle: float32 rounding can put a hit just
    outside it, and a point outside a box corner makes its continuation ray start behind
    the neighbouring face."""
    b1 = min(max(np.float64(u), 0.0), 1.0)
    b2 = min(max(np.float64(v), 0.0), 1.0)
    total = b1 + b2
    if total > 1.0:
        b1 /= total
        b2 /= total
    return 1.0 - b1 - b2, b1, b2


@njit(cache=True)
def _project(m, x, y, z, width, height):
    hx = m[0, 0] * x + m[0, 1] * y + m[0, 2] * z + m[0, 3]
    hy = m[1, 0] * x + m[1, 1] * y + m[1, 2] * z + m[1, 3]
    hw = m[3, 0] * x + m[3, 1] * y + m[3, 2] * z + m[3, 3]
    return hx / hw * width, hy / hw * height


@njit(nogil=True, cache=True)
def gbuffer_kernel(
    prim, bu, bv, dirs, eye, forward,
    tri_v, tri_prev_v, tri_ng, tri_ns, tri_has_ns, tri_uv, tri_mat, tri_obj, tri_ke,
    mat_kd, tex_off, tex_w, tex_h, tex_data,
    ndc_now, ndc_prev, width, height,
    out_p, out_n, out_albedo, out_emission, out_z, out_id, out_motion,
):  # fmt: skip
    """Primary-hit layers for every pixel (rays through pixel centres)."""
    for i in range(prim.shape[0]):
        t = prim[i]
        if t < 0:
            for c in range(3):
                out_p[i, c] = 0.0
                out_n[i, c] = 0.0
                out_albedo[i, c] = 0.0
                out_emission[i, c] = 0.0
            out_z[i] = np.inf
            out_id[i] = -1.0
            out_motion[i, 0] = 0.0
            out_motion[i, 1] = 0.0
            continue
        b0, b1, b2 = _barycentrics(bu[i], bv[i])
        px = b0 * tri_v[t, 0, 0] + b1 * tri_v[t, 1, 0] + b2 * tri_v[t, 2, 0]
        py = b0 * tri_v[t, 0, 1] + b1 * tri_v[t, 1, 1] + b2 * tri_v[t, 2, 1]
        pz = b0 * tri_v[t, 0, 2] + b1 * tri_v[t, 1, 2] + b2 * tri_v[t, 2, 2]
        front, gx, gy, gz, sx, sy, sz = _frame_normals(
            t, b0, b1, b2, dirs[i, 0], dirs[i, 1], dirs[i, 2], tri_ng, tri_ns, tri_has_ns
        )
        r, g, b = _albedo(t, b0, b1, b2, tri_uv, tri_mat, mat_kd, tex_off, tex_w, tex_h, tex_data)
        out_p[i, 0] = px
        out_p[i, 1] = py
        out_p[i, 2] = pz
        out_n[i, 0] = sx
        out_n[i, 1] = sy
        out_n[i, 2] = sz
        out_albedo[i, 0] = r
        out_albedo[i, 1] = g
        out_albedo[i, 2] = b
        for c in range(3):
            out_emission[i, c] = tri_ke[t, c] if front else 0.0
        out_z[i] = (
            (px - eye[0]) * forward[0] + (py - eye[1]) * forward[1] + (pz - eye[2]) * forward[2]
        )
        out_id[i] = tri_obj[t]
        # The same surface point one frame earlier: barycentrics are preserved by the rigid
        # (affine) object transform, so interpolate the previous frame's vertices.
        qx = b0 * tri_prev_v[t, 0, 0] + b1 * tri_prev_v[t, 1, 0] + b2 * tri_prev_v[t, 2, 0]
        qy = b0 * tri_prev_v[t, 0, 1] + b1 * tri_prev_v[t, 1, 1] + b2 * tri_prev_v[t, 2, 1]
        qz = b0 * tri_prev_v[t, 0, 2] + b1 * tri_prev_v[t, 1, 2] + b2 * tri_prev_v[t, 2, 2]
        prev_x, prev_y = _project(ndc_prev, qx, qy, qz, width, height)
        now_x, now_y = _project(ndc_now, px, py, pz, width, height)
        out_motion[i, 0] = prev_x - now_x
        out_motion[i, 1] = prev_y - now_y


@njit(nogil=True, cache=True)
def reproject_kernel(prim, bu, bv, tri_v, tri_other_v, ndc_now, ndc_other, width, height, out):
    """Screen motion of each pixel's surface point to another frame: the point's barycentrics
    on the other frame's vertices, projected with that frame's camera, minus its projection
    now (pixels, x right, y down; 0 on background)."""
    for i in range(prim.shape[0]):
        t = prim[i]
        if t < 0:
            out[i, 0] = 0.0
            out[i, 1] = 0.0
            continue
        b0, b1, b2 = _barycentrics(bu[i], bv[i])
        px = b0 * tri_v[t, 0, 0] + b1 * tri_v[t, 1, 0] + b2 * tri_v[t, 2, 0]
        py = b0 * tri_v[t, 0, 1] + b1 * tri_v[t, 1, 1] + b2 * tri_v[t, 2, 1]
        pz = b0 * tri_v[t, 0, 2] + b1 * tri_v[t, 1, 2] + b2 * tri_v[t, 2, 2]
        qx = b0 * tri_other_v[t, 0, 0] + b1 * tri_other_v[t, 1, 0] + b2 * tri_other_v[t, 2, 0]
        qy = b0 * tri_other_v[t, 0, 1] + b1 * tri_other_v[t, 1, 1] + b2 * tri_other_v[t, 2, 1]
        qz = b0 * tri_other_v[t, 0, 2] + b1 * tri_other_v[t, 1, 2] + b2 * tri_other_v[t, 2, 2]
        other_x, other_y = _project(ndc_other, qx, qy, qz, width, height)
        now_x, now_y = _project(ndc_now, px, py, pz, width, height)
        out[i, 0] = other_x - now_x
        out[i, 1] = other_y - now_y


@njit(nogil=True, cache=True)
def lobe_colours_kernel(
    prim, bu, bv, dirs, tri_ng, tri_ns, tri_has_ns, tri_uv, tri_mat,
    mat_kd, mat_gloss, mat_rough, mat_alpha, mat_metal, mat_f0,
    tex_off, tex_w, tex_h, tex_data, tab_e1, tab_e2, tab_a1, tab_a2,
    out_diff, out_gloss,
):  # fmt: skip
    """Noise-free lobe reflectances at the primary hit (``DiffCol``, ``GlossCol``): the
    diffuse and specular lobes' directional albedos for the view direction (bsdf module).
    A Lambertian material's ``DiffCol`` is its albedo and its ``GlossCol`` 0."""
    for i in range(prim.shape[0]):
        t = prim[i]
        for c in range(3):
            out_diff[i, c] = 0.0
            out_gloss[i, c] = 0.0
        if t < 0:
            continue
        b0, b1, b2 = _barycentrics(bu[i], bv[i])
        dx = np.float64(dirs[i, 0])
        dy = np.float64(dirs[i, 1])
        dz = np.float64(dirs[i, 2])
        _, _, _, _, sx, sy, sz = _frame_normals(t, b0, b1, b2, dx, dy, dz, tri_ng, tri_ns,
                                                tri_has_ns)  # fmt: skip
        r, g, b = _albedo(t, b0, b1, b2, tri_uv, tri_mat, mat_kd, tex_off, tex_w, tex_h, tex_data)
        m = tri_mat[t]
        if mat_gloss[m] == 0:
            out_diff[i, 0] = r
            out_diff[i, 1] = g
            out_diff[i, 2] = b
            continue
        mu_o = -(sx * dx + sy * dy + sz * dz)
        setup = glossy_setup(r, g, b, mat_rough[m], mat_alpha[m], mat_metal[m], mat_f0[m],
                             mu_o, tab_e1, tab_e2, tab_a1, tab_a2)  # fmt: skip
        out_gloss[i, 0] = setup[8]
        out_gloss[i, 1] = setup[9]
        out_gloss[i, 2] = setup[10]
        out_diff[i, 0] = setup[11]
        out_diff[i, 1] = setup[12]
        out_diff[i, 2] = setup[13]


@njit(cache=True)
def _add_split(acc_lobes, pid, slot, v0, v1, v2, f0, f1, f2):
    """Add a contribution to the diffuse pass ``slot`` (0 direct, 1 indirect) and the glossy
    pass ``slot + 2`` in the per-channel proportions ``f`` : ``1 - f``."""
    acc_lobes[pid, slot, 0] += v0 * f0
    acc_lobes[pid, slot, 1] += v1 * f1
    acc_lobes[pid, slot, 2] += v2 * f2
    acc_lobes[pid, slot + 2, 0] += v0 * (1.0 - f0)
    acc_lobes[pid, slot + 2, 1] += v1 * (1.0 - f1)
    acc_lobes[pid, slot + 2, 2] += v2 * (1.0 - f2)


@njit(cache=True)
def _diffuse_share(fd, fs):
    """The diffuse lobe's share of a BSDF value (1 where both are 0)."""
    total = fd + fs
    return fd / total if total > 0.0 else 1.0


@njit(nogil=True, cache=True)
def shade_kernel(
    depth, max_depth, rr_depth, key, eps, mis_mode, lobes,
    path_id, path_key, ray_dir, prim, bu, bv, tfar, throughput, prev_pdf, lobe_frac,
    acc_direct, acc_indirect, acc_lobes,
    tri_v, tri_ng, tri_ns, tri_has_ns, tri_uv, tri_mat, tri_ke,
    mat_kd, mat_gloss, mat_rough, mat_alpha, mat_metal, mat_f0,
    tex_off, tex_w, tex_h, tex_data, tab_e1, tab_e2, tab_a1, tab_a2,
    light_tri, light_cdf, tri_light_pdf,
    shadow_org, shadow_dir, shadow_dist, shadow_value, shadow_frac, shadow_on,
    next_org, next_dir, next_pdf, next_frac, alive,
):  # fmt: skip
    """One bounce for every active path: emission (MIS-weighted after the first hit), a
    next-event-estimation shadow ray, and a BSDF-sampled continuation with Russian
    roulette. Contributions of the primary hit and of the first bounce's light go to
    ``acc_direct``; everything later to ``acc_indirect``.

    Path-length convention (as in pbrt): ``depth`` counts bounces before this hit; at
    ``depth == max_depth`` only emission is added.

    ``mis_mode``: ``MIS_POWER`` combines light and BSDF sampling with the power heuristic
    (Veach 1997); ``MIS_BSDF_ONLY`` traces no shadow rays and counts every emitter hit in
    full; ``MIS_LIGHT_ONLY`` counts emitters hit after a bounce as 0 and shadow rays in full
    (the two are for tests: all three estimate the same image).

    With ``lobes``, every contribution except the primary hit's emission is also split into
    ``acc_lobes[path, (DiffDir, DiffInd, GlossDir, GlossInd)]``: at the first hit by each
    lobe's share of the BSDF value for that direction, per channel; after it by the share
    the first bounce's sampled direction had (``lobe_frac``), as Blender Cycles' light
    passes do, so the four add up to ``direct + indirect - emission``.
    """
    n_lights = light_tri.shape[0]
    dim0 = depth * DIMS_PER_BOUNCE
    for i in range(prim.shape[0]):
        alive[i] = False
        shadow_on[i] = False
        t = prim[i]
        if t < 0:
            continue
        pid = path_id[i]
        pkey = path_key[i]
        dx = np.float64(ray_dir[i, 0])
        dy = np.float64(ray_dir[i, 1])
        dz = np.float64(ray_dir[i, 2])
        b0, b1, b2 = _barycentrics(bu[i], bv[i])
        px = b0 * tri_v[t, 0, 0] + b1 * tri_v[t, 1, 0] + b2 * tri_v[t, 2, 0]
        py = b0 * tri_v[t, 0, 1] + b1 * tri_v[t, 1, 1] + b2 * tri_v[t, 2, 1]
        pz = b0 * tri_v[t, 0, 2] + b1 * tri_v[t, 1, 2] + b2 * tri_v[t, 2, 2]
        front, gx, gy, gz, sx, sy, sz = _frame_normals(
            t, b0, b1, b2, dx, dy, dz, tri_ng, tri_ns, tri_has_ns
        )
        m = tri_mat[t]
        tp0 = throughput[i, 0]
        tp1 = throughput[i, 1]
        tp2 = throughput[i, 2]
        direct = depth <= 1
        slot = 0 if direct else 1
        fr0 = lobe_frac[i, 0]
        fr1 = lobe_frac[i, 1]
        fr2 = lobe_frac[i, 2]

        # Emission seen by this ray (front side only), MIS against light sampling.
        ke0 = tri_ke[t, 0]
        ke1 = tri_ke[t, 1]
        ke2 = tri_ke[t, 2]
        if front and (ke0 > 0.0 or ke1 > 0.0 or ke2 > 0.0):
            weight = 1.0
            if depth > 0:
                if mis_mode == MIS_POWER:
                    cos_light = -(tri_ng[t, 0] * dx + tri_ng[t, 1] * dy + tri_ng[t, 2] * dz)
                    dist = np.float64(tfar[i])
                    pdf_light = tri_light_pdf[t] * dist * dist / cos_light
                    pdf_bsdf = prev_pdf[i]
                    weight = pdf_bsdf * pdf_bsdf / (pdf_bsdf * pdf_bsdf + pdf_light * pdf_light)
                elif mis_mode == MIS_LIGHT_ONLY:
                    weight = 0.0
            if direct:
                acc_direct[pid, 0] += tp0 * ke0 * weight
                acc_direct[pid, 1] += tp1 * ke1 * weight
                acc_direct[pid, 2] += tp2 * ke2 * weight
            else:
                acc_indirect[pid, 0] += tp0 * ke0 * weight
                acc_indirect[pid, 1] += tp1 * ke1 * weight
                acc_indirect[pid, 2] += tp2 * ke2 * weight
            if lobes and depth > 0:
                _add_split(acc_lobes, pid, slot, tp0 * ke0 * weight, tp1 * ke1 * weight,
                           tp2 * ke2 * weight, fr0, fr1, fr2)  # fmt: skip
        if depth >= max_depth:
            continue

        ar, ag, ab = _albedo(
            t, b0, b1, b2, tri_uv, tri_mat, mat_kd, tex_off, tex_w, tex_h, tex_data
        )
        # Spawned rays start eps off the surface along the normal, from a point nudged
        # towards the triangle's centroid: embreex fixes tnear = 0, and at a concave edge a
        # point on the edge itself would start its rays on the neighbouring face's plane
        # (hitting its back at t = 0, or slipping behind it).
        ox = px + (_centroid(tri_v, t, 0) - px) * EDGE_NUDGE + gx * eps
        oy = py + (_centroid(tri_v, t, 1) - py) * EDGE_NUDGE + gy * eps
        oz = pz + (_centroid(tri_v, t, 2) - pz) * EDGE_NUDGE + gz * eps

        # Orthonormal basis around the shading normal (Duff et al. 2017, branchless).
        sign = 1.0 if sz >= 0.0 else -1.0
        a = -1.0 / (sign + sz)
        bb = sx * sy * a
        t1x = 1.0 + sign * sx * sx * a
        t1y = sign * bb
        t1z = -sign * sx
        t2x = bb
        t2y = sign + sy * sy * a
        t2z = -sy

        # Glossy materials: the view direction in the local frame and the lobe constants.
        glossy = mat_gloss[m] != 0
        wox = 0.0
        woy = 0.0
        woz = 0.0
        rough = mat_rough[m]
        alpha = mat_alpha[m]
        f0d = mat_f0[m]
        g_f0r = g_f0g = g_f0b = g_kdr = g_kdg = g_kdb = g_edo = g_inv = g_pspec = 0.0
        if glossy:
            wox = -(t1x * dx + t1y * dy + t1z * dz)
            woy = -(t2x * dx + t2y * dy + t2z * dz)
            woz = -(sx * dx + sy * dy + sz * dz)
            setup = glossy_setup(ar, ag, ab, rough, alpha, mat_metal[m], f0d, woz,
                                 tab_e1, tab_e2, tab_a1, tab_a2)  # fmt: skip
            g_f0r = setup[0]
            g_f0g = setup[1]
            g_f0b = setup[2]
            g_kdr = setup[3]
            g_kdg = setup[4]
            g_kdb = setup[5]
            g_edo = setup[6]
            g_inv = setup[7]
            g_pspec = setup[14]

        # Next-event estimation: a triangle picked by power, a uniform point on it.
        if n_lights > 0 and mis_mode != MIS_BSDF_ONLY:
            u_pick = uniform(key, pkey, dim0)
            lo = 0
            hi = n_lights - 1
            while lo < hi:
                mid = (lo + hi) // 2
                if light_cdf[mid] > u_pick:
                    hi = mid
                else:
                    lo = mid + 1
            lt = light_tri[lo]
            su = math.sqrt(uniform(key, pkey, dim0 + 1))
            c0 = 1.0 - su
            c1 = uniform(key, pkey, dim0 + 2) * su
            c2 = 1.0 - c0 - c1
            lx = c0 * tri_v[lt, 0, 0] + c1 * tri_v[lt, 1, 0] + c2 * tri_v[lt, 2, 0]
            ly = c0 * tri_v[lt, 0, 1] + c1 * tri_v[lt, 1, 1] + c2 * tri_v[lt, 2, 1]
            lz = c0 * tri_v[lt, 0, 2] + c1 * tri_v[lt, 1, 2] + c2 * tri_v[lt, 2, 2]
            wx = lx - ox
            wy = ly - oy
            wz = lz - oz
            dist = math.sqrt(wx * wx + wy * wy + wz * wz)
            if dist > 4.0 * eps:
                wx /= dist
                wy /= dist
                wz /= dist
                cos_surf = sx * wx + sy * wy + sz * wz
                cos_geom = gx * wx + gy * wy + gz * wz
                cos_light = -(tri_ng[lt, 0] * wx + tri_ng[lt, 1] * wy + tri_ng[lt, 2] * wz)
                if cos_surf > 0.0 and cos_geom > 0.0 and cos_light > 0.0:
                    pdf_light = tri_light_pdf[lt] * dist * dist / cos_light
                    if glossy:
                        fd0, fd1, fd2, fs0, fs1, fs2, pdf_bsdf = glossy_eval(
                            wox, woy, woz,
                            t1x * wx + t1y * wy + t1z * wz, t2x * wx + t2y * wy + t2z * wz,
                            cos_surf, rough, alpha, f0d, g_f0r, g_f0g, g_f0b,
                            g_kdr, g_kdg, g_kdb, g_edo, g_inv, g_pspec, tab_e1, tab_e2,
                        )  # fmt: skip
                        f0 = fd0 + fs0
                        f1 = fd1 + fs1
                        f2 = fd2 + fs2
                        if depth == 0:
                            shadow_frac[i, 0] = _diffuse_share(fd0, fs0)
                            shadow_frac[i, 1] = _diffuse_share(fd1, fs1)
                            shadow_frac[i, 2] = _diffuse_share(fd2, fs2)
                    else:
                        pdf_bsdf = cos_surf * INV_PI
                        f0 = ar
                        f1 = ag
                        f2 = ab
                        if depth == 0:
                            shadow_frac[i, 0] = 1.0
                            shadow_frac[i, 1] = 1.0
                            shadow_frac[i, 2] = 1.0
                    if depth > 0:
                        shadow_frac[i, 0] = fr0
                        shadow_frac[i, 1] = fr1
                        shadow_frac[i, 2] = fr2
                    if mis_mode == MIS_POWER:
                        weight = pdf_light * pdf_light / (pdf_light * pdf_light
                                                          + pdf_bsdf * pdf_bsdf)  # fmt: skip
                    else:
                        weight = 1.0
                    if glossy:
                        scale = cos_surf * weight / pdf_light
                    else:
                        scale = cos_surf * INV_PI * weight / pdf_light
                    shadow_value[i, 0] = tp0 * f0 * tri_ke[lt, 0] * scale
                    shadow_value[i, 1] = tp1 * f1 * tri_ke[lt, 1] * scale
                    shadow_value[i, 2] = tp2 * f2 * tri_ke[lt, 2] * scale
                    shadow_org[i, 0] = ox
                    shadow_org[i, 1] = oy
                    shadow_org[i, 2] = oz
                    shadow_dir[i, 0] = wx
                    shadow_dir[i, 1] = wy
                    shadow_dir[i, 2] = wz
                    shadow_dist[i] = dist - 2.0 * eps
                    shadow_on[i] = (f0 > 0.0 or f1 > 0.0 or f2 > 0.0) or not glossy

        # Continue the path: a direction from the BSDF (cosine-weighted for Lambertian).
        u1 = uniform(key, pkey, dim0 + 3)
        u2 = uniform(key, pkey, dim0 + 4)
        if glossy:
            u_lobe = uniform(key, pkey | LOBE_STREAM, dim0)
            lx, ly, lz = glossy_sample(wox, woy, woz, alpha, g_pspec, u_lobe, u1, u2)
        else:
            radius = math.sqrt(u1)
            phi = 2.0 * math.pi * u2
            lx = radius * math.cos(phi)
            ly = radius * math.sin(phi)
            lz = math.sqrt(max(0.0, 1.0 - u1))
        nx = lx * t1x + ly * t2x + lz * sx
        ny = lx * t1y + ly * t2y + lz * sy
        nz = lx * t1z + ly * t2z + lz * sz
        if nx * gx + ny * gy + nz * gz <= 0.0 or lz <= 0.0:
            continue  # below the geometric surface (shading-normal artefact): stop
        if glossy:
            fd0, fd1, fd2, fs0, fs1, fs2, pdf = glossy_eval(
                wox, woy, woz, lx, ly, lz, rough, alpha, f0d, g_f0r, g_f0g, g_f0b,
                g_kdr, g_kdg, g_kdb, g_edo, g_inv, g_pspec, tab_e1, tab_e2,
            )  # fmt: skip
            if pdf <= 0.0:
                continue
            tp0 *= (fd0 + fs0) * lz / pdf
            tp1 *= (fd1 + fs1) * lz / pdf
            tp2 *= (fd2 + fs2) * lz / pdf
            if depth == 0:
                fr0 = _diffuse_share(fd0, fs0)
                fr1 = _diffuse_share(fd1, fs1)
                fr2 = _diffuse_share(fd2, fs2)
        else:
            pdf = lz * INV_PI
            tp0 *= ar
            tp1 *= ag
            tp2 *= ab
            if depth == 0:
                fr0 = 1.0
                fr1 = 1.0
                fr2 = 1.0
        if depth + 1 >= rr_depth:
            survive = min(0.95, max(tp0, max(tp1, tp2)))
            if survive <= 0.0 or uniform(key, pkey, dim0 + 5) >= survive:
                continue
            tp0 /= survive
            tp1 /= survive
            tp2 /= survive
        elif tp0 <= 0.0 and tp1 <= 0.0 and tp2 <= 0.0:
            continue
        throughput[i, 0] = tp0
        throughput[i, 1] = tp1
        throughput[i, 2] = tp2
        next_org[i, 0] = ox
        next_org[i, 1] = oy
        next_org[i, 2] = oz
        next_dir[i, 0] = nx
        next_dir[i, 1] = ny
        next_dir[i, 2] = nz
        next_pdf[i] = pdf
        next_frac[i, 0] = fr0
        next_frac[i, 1] = fr1
        next_frac[i, 2] = fr2
        alive[i] = True


@njit(cache=True)
def add_shadow_kernel(depth, path_id, shadow_value, shadow_frac, visible, acc_direct,
                      acc_indirect, acc_lobes, lobes):  # fmt: skip
    """Add the unoccluded next-event contributions to the paths' accumulators (and, with
    ``lobes``, to the lobe passes in the shares ``shadow_frac``)."""
    target = acc_direct if depth == 0 else acc_indirect
    slot = 0 if depth == 0 else 1
    for k in range(path_id.shape[0]):
        if visible[k]:
            pid = path_id[k]
            target[pid, 0] += shadow_value[k, 0]
            target[pid, 1] += shadow_value[k, 1]
            target[pid, 2] += shadow_value[k, 2]
            if lobes:
                _add_split(acc_lobes, pid, slot, shadow_value[k, 0], shadow_value[k, 1],
                           shadow_value[k, 2], shadow_frac[k, 0], shadow_frac[k, 1],
                           shadow_frac[k, 2])  # fmt: skip


@njit(cache=True)
def compact_paths(alive, path_id, path_key, throughput, next_pdf, next_frac, next_org, next_dir):
    """The surviving paths' state, gathered into fresh contiguous arrays (one pass)."""
    count = 0
    for i in range(alive.shape[0]):
        if alive[i]:
            count += 1
    out_id = np.empty(count, path_id.dtype)
    out_key = np.empty(count, path_key.dtype)
    out_tp = np.empty((count, 3), throughput.dtype)
    out_pdf = np.empty(count, next_pdf.dtype)
    out_frac = np.empty((count, 3), next_frac.dtype)
    out_org = np.empty((count, 3), next_org.dtype)
    out_dir = np.empty((count, 3), next_dir.dtype)
    k = 0
    for i in range(alive.shape[0]):
        if alive[i]:
            out_id[k] = path_id[i]
            out_key[k] = path_key[i]
            out_pdf[k] = next_pdf[i]
            for c in range(3):
                out_tp[k, c] = throughput[i, c]
                out_frac[k, c] = next_frac[i, c]
                out_org[k, c] = next_org[i, c]
                out_dir[k, c] = next_dir[i, c]
            k += 1
    return out_id, out_key, out_tp, out_pdf, out_frac, out_org, out_dir


@njit(cache=True)
def compact_shadow_rays(shadow_on, path_id, shadow_org, shadow_dir, shadow_dist, shadow_value,
                        shadow_frac):  # fmt: skip
    """The shadow rays that were generated, gathered into contiguous arrays."""
    count = 0
    for i in range(shadow_on.shape[0]):
        if shadow_on[i]:
            count += 1
    out_id = np.empty(count, path_id.dtype)
    out_org = np.empty((count, 3), shadow_org.dtype)
    out_dir = np.empty((count, 3), shadow_dir.dtype)
    out_dist = np.empty(count, shadow_dist.dtype)
    out_value = np.empty((count, 3), shadow_value.dtype)
    out_frac = np.empty((count, 3), shadow_frac.dtype)
    k = 0
    for i in range(shadow_on.shape[0]):
        if shadow_on[i]:
            out_id[k] = path_id[i]
            out_dist[k] = shadow_dist[i]
            for c in range(3):
                out_org[k, c] = shadow_org[i, c]
                out_dir[k, c] = shadow_dir[i, c]
                out_value[k, c] = shadow_value[i, c]
                out_frac[k, c] = shadow_frac[i, c]
            k += 1
    return out_id, out_org, out_dir, out_dist, out_value, out_frac


@njit(cache=True)
def stratum_pixels(key, width, height, size):
    """One pixel index per ``size`` x ``size`` stratum of the image, in stratum order (row
    by row), chosen by hashing (key, stratum); border strata are clipped to the image."""
    sx = (width + size - 1) // size
    sy = (height + size - 1) // size
    out = np.empty(sx * sy, np.int64)
    for j in range(sy):
        for i in range(sx):
            s = j * sx + i
            w = min(size, width - i * size)
            h = min(size, height - j * size)
            pick = min(int(uniform(key, np.uint64(s), 0) * (w * h)), w * h - 1)
            out[s] = (j * size + pick // w) * width + i * size + pick % w
    return out
