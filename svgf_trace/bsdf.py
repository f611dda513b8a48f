"""The glossy material: a GGX microfacet specular lobe over an energy-conserving diffuse base.

A glossy material has a base colour ``c`` (``Kd`` x texture), a perceptual roughness ``r``
(GGX alpha = r^2, at least ``MIN_ALPHA``), a metallic weight ``m`` and a dielectric
reflectance at normal incidence ``f0d`` (0.04 for the usual IOR 1.5). Its BRDF is

    f = f_spec + f_diff
    f_spec(wo, wi) = F(wo.h) D(h) G2(wo, wi) / (4 cos_o cos_i)          (Walter et al. 2007)
    D    = alpha^2 / (pi (cos_h^2 (alpha^2 - 1) + 1)^2)                  (GGX / Trowbridge-Reitz)
    G2   = 1 / (1 + Lambda(wo) + Lambda(wi)),  Lambda(w) = (sqrt(1 + alpha^2 tan^2) - 1) / 2
                                                         (height-correlated Smith, Heitz 2014)
    F(c) = F0 + (1 - F0) (1 - c)^5,  F0 = (1 - m) f0d + m c             (Schlick, per channel)
    f_diff(wo, wi) = (1 - m) c / pi (1 - Ed(cos_o)) (1 - Ed(cos_i)) / (1 - Ed_avg)

``Ed(mu)`` is the directional albedo of the dielectric specular lobe (F0 = f0d) and
``Ed_avg = 2 int Ed(mu) mu dmu`` its cosine-weighted average, so the diffuse base receives
exactly the energy the coat does not reflect: the diffuse lobe's directional albedo is
``(1 - m) c (1 - Ed(cos_o))`` (the ``DiffCol`` pass), the specular lobe's is
``E(cos_o) = F0 E1 + E2`` (the ``GlossCol`` pass), and their sum is at most 1 (equal to 1
for a white dielectric base, up to the tables' accuracy). The BRDF is reciprocal. Energy
lost to single scattering at high roughness (no multiple-scattering term) is not restored.

``E1``, ``E2`` (Schlick's F0 = 1 and F0 = 0 parts of the albedo, as in the split-sum
tables of real-time renderers) are tabulated over (roughness, cos) by a fixed stratified
quadrature and interpolated bilinearly; ``A1``, ``A2`` are their cosine-weighted averages,
integrated from the interpolated table so the diffuse normalisation matches it exactly.

Sampling: the specular lobe by the distribution of visible normals (Heitz 2018) with the
spherical-cap construction (Dupuy and Benyoub 2023); the diffuse lobe by the cosine; the
lobe is picked with probability proportional to the two directional albedos, and the pdf
of a direction is the mixture of both (one-sample MIS over lobes).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

INV_PI = 1.0 / math.pi
# Smallest GGX alpha (roughness 0.01): below it D overflows nothing but the lobe is a mirror
# to any image resolution, and light sampling can never hit it.
MIN_ALPHA = 1e-4
# Albedo table resolution (roughness x cos) and quadrature samples per table entry.
TABLE_SIZE = 32
TABLE_STRATA = 64
# Cosines below this count as grazing: the specular lobe is not evaluated there.
MIN_COS = 1e-6


@njit(cache=True)
def ggx_d(cos_h: float, a2: float) -> float:
    """GGX normal distribution D(h) for cos(theta_h) and alpha^2."""
    t = cos_h * cos_h * (a2 - 1.0) + 1.0
    return a2 / (math.pi * t * t)


@njit(cache=True)
def smith_lambda(cos_t: float, a2: float) -> float:
    """Smith's Lambda for GGX: (sqrt(1 + alpha^2 tan^2(theta)) - 1) / 2."""
    c2 = cos_t * cos_t
    tan2 = max(0.0, 1.0 - c2) / c2
    return 0.5 * (math.sqrt(1.0 + a2 * tan2) - 1.0)


@njit(cache=True)
def schlick_weight(c: float) -> float:
    """(1 - c)^5, the grazing weight of Schlick's Fresnel approximation."""
    m = min(max(1.0 - c, 0.0), 1.0)
    m2 = m * m
    return m2 * m2 * m


@njit(cache=True)
def sample_visible_normal(ox, oy, oz, alpha, u1, u2):  # noqa: ANN001, ANN201
    """A microfacet normal from GGX's distribution of visible normals for the local view
    direction ``o`` (z = normal, oz > 0): stretch to alpha = 1, sample the spherical cap
    below the hemisphere of visible normals (Dupuy and Benyoub 2023), unstretch."""
    vx = alpha * ox
    vy = alpha * oy
    vz = oz
    inv = 1.0 / math.sqrt(vx * vx + vy * vy + vz * vz)
    vx *= inv
    vy *= inv
    vz *= inv
    phi = 2.0 * math.pi * u1
    z = (1.0 - u2) * (1.0 + vz) - vz
    sin_t = math.sqrt(max(0.0, 1.0 - z * z))
    hx = sin_t * math.cos(phi) + vx
    hy = sin_t * math.sin(phi) + vy
    hz = z + vz
    mx = alpha * hx
    my = alpha * hy
    mz = max(hz, 0.0)
    inv = 1.0 / math.sqrt(mx * mx + my * my + mz * mz)
    return mx * inv, my * inv, mz * inv


@njit(cache=True)
def _albedo_tables(size: int, strata: int) -> tuple[np.ndarray, np.ndarray]:
    """E1, E2 [roughness node, cos node]: the specular albedo is F0 E1 + E2. Each entry is
    the mean of F G2 / G1(wo) over a strata x strata midpoint grid of visible-normal
    samples (the estimator of int f_spec cos for that sampler, no random numbers)."""
    e1 = np.zeros((size, size))
    e2 = np.zeros((size, size))
    for j in range(size):
        rough = j / (size - 1)
        alpha = max(rough * rough, MIN_ALPHA)
        a2 = alpha * alpha
        for k in range(size):
            mu = max(k / (size - 1), 1e-3)
            ox = math.sqrt(1.0 - mu * mu)
            oz = mu
            lam_o = smith_lambda(oz, a2)
            s1 = 0.0
            s2 = 0.0
            for a in range(strata):
                for b in range(strata):
                    mx, my, mz = sample_visible_normal(
                        ox, 0.0, oz, alpha, (a + 0.5) / strata, (b + 0.5) / strata
                    )
                    c = ox * mx + oz * mz
                    iz = 2.0 * c * mz - oz
                    if c <= 0.0 or iz <= 0.0:
                        continue
                    g = (1.0 + lam_o) / (1.0 + lam_o + smith_lambda(iz, a2))
                    w5 = schlick_weight(c)
                    s1 += (1.0 - w5) * g
                    s2 += w5 * g
            n = strata * strata
            e1[j, k] = s1 / n
            e2[j, k] = s2 / n
    return e1, e2


@njit(cache=True)
def table_lookup(table: np.ndarray, rough: float, mu: float) -> float:
    """Bilinear lookup of a [roughness, cos] table on the grid j/(N-1), k/(N-1)."""
    n = table.shape[0]
    fr = min(max(rough, 0.0), 1.0) * (n - 1)
    fm = min(max(mu, 0.0), 1.0) * (n - 1)
    j = min(int(fr), n - 2)
    k = min(int(fm), n - 2)
    tr = fr - j
    tm = fm - k
    lo = table[j, k] * (1.0 - tm) + table[j, k + 1] * tm
    hi = table[j + 1, k] * (1.0 - tm) + table[j + 1, k + 1] * tm
    return lo * (1.0 - tr) + hi * tr


@njit(cache=True)
def row_lookup(row: np.ndarray, rough: float) -> float:
    n = row.shape[0]
    fr = min(max(rough, 0.0), 1.0) * (n - 1)
    j = min(int(fr), n - 2)
    t = fr - j
    return row[j] * (1.0 - t) + row[j + 1] * t


def _cosine_average(table: np.ndarray, points: int = 4096) -> np.ndarray:
    """2 int_0^1 E(mu) mu dmu per roughness node, from the linearly interpolated table."""
    mu = (np.arange(points) + 0.5) / points
    nodes = np.linspace(0.0, 1.0, table.shape[1])
    return np.array([2.0 * np.mean(np.interp(mu, nodes, row) * mu) for row in table])


@lru_cache(maxsize=1)
def albedo_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(E1, E2, A1, A2): the specular albedo tables and their cosine-weighted averages."""
    e1, e2 = _albedo_tables(TABLE_SIZE, TABLE_STRATA)
    e1.setflags(write=False)
    e2.setflags(write=False)
    return e1, e2, _cosine_average(e1), _cosine_average(e2)


@njit(cache=True)
def glossy_setup(base_r, base_g, base_b, rough, alpha, metal, f0d, mu_o,
                 tab_e1, tab_e2, tab_a1, tab_a2):  # fmt: skip  # noqa: ANN001, ANN201
    """Per-vertex constants of the glossy BRDF for the view cosine ``mu_o``.

    Returns F0 (3), the diffuse weight (1 - m) c (3), Ed(mu_o), 1 / (1 - Ed_avg), the
    specular lobe's directional albedo (3, ``GlossCol``), the diffuse lobe's (3,
    ``DiffCol``) and the probability of sampling the specular lobe.
    """
    f0r = (1.0 - metal) * f0d + metal * base_r
    f0g = (1.0 - metal) * f0d + metal * base_g
    f0b = (1.0 - metal) * f0d + metal * base_b
    kdr = (1.0 - metal) * base_r
    kdg = (1.0 - metal) * base_g
    kdb = (1.0 - metal) * base_b
    e1 = table_lookup(tab_e1, rough, mu_o)
    e2 = table_lookup(tab_e2, rough, mu_o)
    ed_o = f0d * e1 + e2
    ed_avg = f0d * row_lookup(tab_a1, rough) + row_lookup(tab_a2, rough)
    inv_eavg = 1.0 / (1.0 - ed_avg)
    gr = f0r * e1 + e2
    gg = f0g * e1 + e2
    gb = f0b * e1 + e2
    dr = kdr * (1.0 - ed_o)
    dg = kdg * (1.0 - ed_o)
    db = kdb * (1.0 - ed_o)
    spec = 0.2126 * gr + 0.7152 * gg + 0.0722 * gb
    diff = 0.2126 * dr + 0.7152 * dg + 0.0722 * db
    p_spec = spec / (spec + diff) if spec + diff > 0.0 else 1.0
    return (f0r, f0g, f0b, kdr, kdg, kdb, ed_o, inv_eavg, gr, gg, gb, dr, dg, db, p_spec)


@njit(cache=True)
def glossy_eval(ox, oy, oz, ix, iy, iz, rough, alpha, f0d,
                f0r, f0g, f0b, kdr, kdg, kdb, ed_o, inv_eavg, p_spec,
                tab_e1, tab_e2):  # fmt: skip  # noqa: ANN001, ANN201
    """BRDF value of both lobes and the sampling pdf (solid angle) of ``i`` given ``o``,
    both in the local shading frame (z = normal): (diffuse rgb, specular rgb, pdf)."""
    if oz < MIN_COS or iz <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    ed_i = f0d * table_lookup(tab_e1, rough, iz) + table_lookup(tab_e2, rough, iz)
    kd = INV_PI * (1.0 - ed_o) * (1.0 - ed_i) * inv_eavg
    fdr = kdr * kd
    fdg = kdg * kd
    fdb = kdb * kd
    hx = ox + ix
    hy = oy + iy
    hz = oz + iz
    hl = math.sqrt(hx * hx + hy * hy + hz * hz)
    fsr = 0.0
    fsg = 0.0
    fsb = 0.0
    pdf_spec = 0.0
    if hl > 0.0:
        hz /= hl
        c = (ox * hx + oy * hy) / hl + oz * hz
        if c > 0.0 and hz > 0.0:
            a2 = alpha * alpha
            d = ggx_d(hz, a2)
            lam_o = smith_lambda(oz, a2)
            g2 = 1.0 / (1.0 + lam_o + smith_lambda(iz, a2))
            w5 = schlick_weight(c)
            common = d * g2 / (4.0 * oz * iz)
            fsr = (f0r + (1.0 - f0r) * w5) * common
            fsg = (f0g + (1.0 - f0g) * w5) * common
            fsb = (f0b + (1.0 - f0b) * w5) * common
            pdf_spec = d / ((1.0 + lam_o) * 4.0 * oz)
    pdf = p_spec * pdf_spec + (1.0 - p_spec) * iz * INV_PI
    return fdr, fdg, fdb, fsr, fsg, fsb, pdf


@njit(cache=True)
def glossy_sample(ox, oy, oz, alpha, p_spec, u_lobe, u1, u2):  # noqa: ANN001, ANN201
    """A local direction from the lobe mixture: the specular lobe (visible normals,
    reflected) with probability ``p_spec``, else the cosine-weighted diffuse lobe."""
    if u_lobe < p_spec:
        mx, my, mz = sample_visible_normal(ox, oy, oz, alpha, u1, u2)
        c = ox * mx + oy * my + oz * mz
        return 2.0 * c * mx - ox, 2.0 * c * my - oy, 2.0 * c * mz - oz
    radius = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    return radius * math.cos(phi), radius * math.sin(phi), math.sqrt(max(0.0, 1.0 - u1))
