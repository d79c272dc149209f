"""Device-side material rows and the constitutive functions (docs/physics.md, "Materials").

Pure `wp.func`s: the B-spline weights shared by both transfers, the stress of each mode
(as the Kirchhoff stress tau = P F^T that MLS-MPM fuses into the affine term) and the
return maps (plasticity as a projection of the trial elastic F). They compile into the
kernels that call them; this module has no kernels of its own.
"""

from __future__ import annotations

import warp as wp

from .materials import Material, Mode

MODE_SNOW = wp.constant(int(Mode.SNOW))
MODE_SAND = wp.constant(int(Mode.SAND))
MODE_WATER = wp.constant(int(Mode.WATER))
MODE_TRACER = wp.constant(int(Mode.TRACER))


@wp.struct
class MaterialParams:
    """One material row on the device (see materials.Material for units)."""

    mode: int
    mu0: float
    lambda0: float
    hardening: float
    theta_c: float
    theta_s: float
    jp_min: float
    jp_max: float
    plastic: int  # 0: the snow clamp can never fire (Elastic), skip its SVD
    dp_alpha: float
    cohesion: float
    volume_correction: int
    bulk_modulus: float
    eos_gamma: float
    clamp_pressure: int
    density: float
    volume_recovery: int
    volume_recovery_rate: float


def pack_material(m: Material) -> MaterialParams:
    """Host Material -> device MaterialParams."""
    p = MaterialParams()
    p.mode = int(m.mode)
    p.mu0 = m.mu0
    p.lambda0 = m.lambda0
    p.hardening = m.hardening
    p.theta_c = m.theta_c
    p.theta_s = m.theta_s
    p.jp_min = m.jp_min
    p.jp_max = m.jp_max
    p.plastic = int(m.plastic)
    p.dp_alpha = m.dp_alpha
    p.cohesion = m.cohesion
    p.volume_correction = int(m.volume_correction)
    p.bulk_modulus = m.bulk_modulus
    p.eos_gamma = m.eos_gamma
    p.clamp_pressure = int(m.clamp_pressure)
    p.density = m.density
    p.volume_recovery = int(m.volume_recovery and m.mode == Mode.WATER)
    p.volume_recovery_rate = m.volume_recovery_rate
    return p


vec5 = wp.types.vector(length=5, dtype=wp.float32)
"""A varied particle's factors (variation.variation_factors): stiffness, hardening, dp_alpha,
cohesion, and stiffness / density (its wave speed's, squared)."""


@wp.func
def vary_material(mat: MaterialParams, f: vec5) -> MaterialParams:
    """A particle's own copy of its material row under variation, f its factors (vec5). The
    array row is unchanged."""
    out = mat
    out.mu0 = mat.mu0 * f[0]
    out.lambda0 = mat.lambda0 * f[0]
    out.hardening = mat.hardening * f[1]
    out.dp_alpha = mat.dp_alpha * f[2]
    out.cohesion = mat.cohesion * f[3]
    return out


@wp.func
def pack_f_jp(F: wp.mat33, jp: float) -> wp.mat44:
    """(F, Jp) -> mat44, because a wp.func returns one value here."""
    return wp.mat44(
        F[0, 0],
        F[0, 1],
        F[0, 2],
        0.0,
        F[1, 0],
        F[1, 1],
        F[1, 2],
        0.0,
        F[2, 0],
        F[2, 1],
        F[2, 2],
        0.0,
        0.0,
        0.0,
        0.0,
        jp,
    )


@wp.func
def unpack_f(m: wp.mat44) -> wp.mat33:
    return wp.mat33(m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2])


@wp.func
def bspline_weights(fx: wp.vec3) -> wp.mat33:
    """Quadratic B-spline weights. fx: offset from the base node, cells,
    in [0.5, 1.5) per axis. Row k holds the weight of node base + k along each axis;
    each column sums to 1 (partition of unity)."""
    a = wp.vec3(1.5) - fx
    b = fx - wp.vec3(1.0)
    c = fx - wp.vec3(0.5)
    w0 = 0.5 * wp.cw_mul(a, a)
    w1 = wp.vec3(0.75) - wp.cw_mul(b, b)
    w2 = 0.5 * wp.cw_mul(c, c)
    return wp.mat33(w0[0], w0[1], w0[2], w1[0], w1[1], w1[2], w2[0], w2[1], w2[2])


@wp.func
def bspline_gradients(fx: wp.vec3) -> wp.mat33:
    """d/dfx of bspline_weights, per cell (multiply by 1/dx for domain units); rows as there."""
    return wp.mat33(
        fx[0] - 1.5,
        fx[1] - 1.5,
        fx[2] - 1.5,
        -2.0 * (fx[0] - 1.0),
        -2.0 * (fx[1] - 1.0),
        -2.0 * (fx[2] - 1.0),
        fx[0] - 0.5,
        fx[1] - 0.5,
        fx[2] - 0.5,
    )


@wp.func
def hardening_factor(mat: MaterialParams, jp: float) -> float:
    """exp(xi (1 - Jp)): how much stiffer (Jp < 1) or softer a packed snow particle is."""
    return wp.exp(mat.hardening * (1.0 - jp))


vec6 = wp.types.vector(length=6, dtype=wp.float32)
"""A symmetric 3x3 matrix as (xx, yy, zz, xy, xz, yz): the stress G2P stores for P2G."""


@wp.func
def sym6(A: wp.mat33) -> vec6:
    """A symmetric A's six independent entries (its upper triangle)."""
    return vec6(A[0, 0], A[1, 1], A[2, 2], A[0, 1], A[0, 2], A[1, 2])


@wp.func
def to_sym(U: wp.mat33, d: wp.vec3) -> vec6:
    """U diag(d) U^T, kept as its six independent entries."""
    return sym6(U * wp.diag(d) * wp.transpose(U))


@wp.func
def from_sym(s: vec6) -> wp.mat33:
    return wp.mat33(s[0], s[3], s[4], s[3], s[1], s[5], s[4], s[5], s[2])


@wp.func
def hencky_diag(eps: wp.vec3, mu: float, la: float) -> wp.vec3:
    """Principal Kirchhoff stresses of StVK on Hencky strain: 2 mu eps + lambda tr(eps)."""
    return 2.0 * mu * eps + wp.vec3(la * (eps[0] + eps[1] + eps[2]))


@wp.func
def log_strain(sig: wp.vec3) -> wp.vec3:
    """Hencky strain of singular values (clamped away from 0: an inverted axis is a compressed one)."""
    return wp.vec3(
        wp.log(wp.max(wp.abs(sig[0]), 1.0e-4)),
        wp.log(wp.max(wp.abs(sig[1]), 1.0e-4)),
        wp.log(wp.max(wp.abs(sig[2]), 1.0e-4)),
    )


@wp.func
def fixed_corotated_tau(F: wp.mat33, mu: float, la: float) -> wp.mat33:
    """Kirchhoff stress tau = P F^T of fixed-corotated elasticity:
    2 mu (F - R) F^T + lambda (J - 1) J I, with R the rotation of F."""
    U, sig, V = wp.svd3(F)
    R = U * wp.transpose(V)
    J = sig[0] * sig[1] * sig[2]
    return 2.0 * mu * (F - R) * wp.transpose(F) + wp.identity(n=3, dtype=float) * (la * (J - 1.0) * J)


@wp.func
def hencky_tau(F: wp.mat33, mu: float, la: float) -> wp.mat33:
    """Kirchhoff stress of St. Venant-Kirchhoff on Hencky strain (Klar et al. 2016):
    tau = U (2 mu ln S + lambda tr(ln S) I) U^T."""
    U, sig, V = wp.svd3(F)
    return U * wp.diag(hencky_diag(log_strain(sig), mu, la)) * wp.transpose(U)


@wp.func
def tait_pressure(mat: MaterialParams, J: float) -> float:
    """Tait equation of state p = K (J^-gamma - 1); p >= 0 when clamped."""
    p = mat.bulk_modulus * (wp.pow(wp.max(J, 1.0e-4), -mat.eos_gamma) - 1.0)
    if mat.clamp_pressure != 0:
        p = wp.max(p, 0.0)
    return p


@wp.func
def solid_tau(mat: MaterialParams, F: wp.mat33, jp: float) -> wp.mat33:
    """Kirchhoff stress of a snow (hardened fixed-corotated) or sand particle."""
    if mat.mode == MODE_SAND:
        return hencky_tau(F, mat.mu0, mat.lambda0)
    h = hardening_factor(mat, jp)
    return fixed_corotated_tau(F, mat.mu0 * h, mat.lambda0 * h)


POLAR_LO = wp.constant(0.8)  # singular values the polar shortcut (snow_plastic) takes: 3 Newton
POLAR_HI = wp.constant(1.25)  # steps from 0.8 or 1.25 leave R off by < 5e-8 (float32's own rounding)


@wp.func
def positive_definite(a00: float, a11: float, a22: float, a01: float, a02: float, a12: float) -> bool:
    """Whether a symmetric 3x3 is positive definite (Sylvester: its leading minors > 0)."""
    m2 = a00 * a11 - a01 * a01
    det = a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02) + a02 * (a01 * a12 - a11 * a02)
    return a00 > 0.0 and m2 > 0.0 and det > 0.0


@wp.func
def singular_values_within(F: wp.mat33, lo: float, hi: float) -> bool:
    """Whether every singular value of F lies strictly inside (lo, hi), without an SVD: the
    eigenvalues of F^T F are the squared singular values, so both F^T F - lo^2 I and
    hi^2 I - F^T F must be positive definite."""
    C = wp.transpose(F) * F
    l2 = lo * lo
    h2 = hi * hi
    below = positive_definite(C[0, 0] - l2, C[1, 1] - l2, C[2, 2] - l2, C[0, 1], C[0, 2], C[1, 2])
    above = positive_definite(h2 - C[0, 0], h2 - C[1, 1], h2 - C[2, 2], -C[0, 1], -C[0, 2], -C[1, 2])
    return below and above


@wp.func
def polar_rotation(F: wp.mat33) -> wp.mat33:
    """The rotation R of F = R S (= U V^T of its SVD) by Newton's iteration R <- (R + R^-T) / 2
    (Higham 1986), three steps from R = F. Each step maps a singular value s to (s + 1/s) / 2,
    so it is exact to float32 rounding only for singular values in [POLAR_LO, POLAR_HI];
    det F > 0. R^-T is the cofactor matrix over the determinant (columns: cross products)."""
    R = F
    for _ in range(3):
        c0 = wp.vec3(R[0, 0], R[1, 0], R[2, 0])
        c1 = wp.vec3(R[0, 1], R[1, 1], R[2, 1])
        c2 = wp.vec3(R[0, 2], R[1, 2], R[2, 2])
        k0 = wp.cross(c1, c2)
        k1 = wp.cross(c2, c0)
        k2 = wp.cross(c0, c1)
        inv_det = 1.0 / wp.dot(c0, k0)
        R = 0.5 * (R + inv_det * wp.mat33(k0[0], k1[0], k2[0], k0[1], k1[1], k2[1], k0[2], k1[2], k2[2]))
    return R


@wp.func
def snow_plastic(mat: MaterialParams, F: wp.mat33, jp: float):
    """Stomakhin clamp (Stomakhin et al. 2013): singular values of the trial elastic F into
    [1 - theta_c, 1 + theta_s]; the clamped-away volume goes into Jp, clamped to
    [jp_min, jp_max]. F must not be inverted (G2P mirrors inverted particles first, see
    `uninvert`). Returns (elastic F, new Jp, tau): tau is the Kirchhoff stress of the
    returned F and Jp (hardened fixed-corotated, = solid_tau of them), from the same SVD,
    so P2G needs none of its own.
    F is rebuilt from its SVD only when the clamp fires: each rebuild shrinks the
    singular values by ~1e-6 (float32 SVD), which would otherwise creep in every substep.

    A particle whose singular values all lie inside the clamp's range (and [POLAR_LO,
    POLAR_HI]) keeps F and Jp, and its stress needs only the rotation R of F: 2 mu h (F - R)
    F^T + lambda h (J - 1) J I, the same fixed-corotated stress, with R from three Newton
    steps instead of the SVD's twelve Jacobi rotations, QR and sort. Tested first, without
    an SVD (singular_values_within): most of a snow body at rest or in elastic motion takes
    it; a yielding particle takes the SVD as before."""
    # (a material that never yields has thetas >= 1e8: its range is [POLAR_LO, POLAR_HI])
    lo_fast = wp.max(1.0 - mat.theta_c, POLAR_LO)
    hi_fast = wp.min(1.0 + mat.theta_s, POLAR_HI)
    if singular_values_within(F, lo_fast, hi_fast):
        R = polar_rotation(F)
        h_fast = hardening_factor(mat, jp)
        J_fast = wp.determinant(F)
        tau_fast = (2.0 * mat.mu0 * h_fast) * (F - R) * wp.transpose(F)
        k = mat.lambda0 * h_fast * (J_fast - 1.0) * J_fast
        return (
            F,
            jp,
            vec6(
                tau_fast[0, 0] + k,
                tau_fast[1, 1] + k,
                tau_fast[2, 2] + k,
                tau_fast[0, 1],
                tau_fast[0, 2],
                tau_fast[1, 2],
            ),
        )
    U, sig, V = wp.svd3(F)
    Fe = F
    jp_new = jp
    s = sig
    if mat.plastic != 0:
        lo = 1.0 - mat.theta_c
        hi = 1.0 + mat.theta_s
        sc = wp.vec3(wp.clamp(sig[0], lo, hi), wp.clamp(sig[1], lo, hi), wp.clamp(sig[2], lo, hi))
        if sc[0] != sig[0] or sc[1] != sig[1] or sc[2] != sig[2]:
            jp_new = jp * (sig[0] * sig[1] * sig[2]) / (sc[0] * sc[1] * sc[2])
            jp_new = wp.clamp(jp_new, mat.jp_min, mat.jp_max)
            Fe = U * wp.diag(sc) * wp.transpose(V)
            s = sc
    # fixed-corotated: 2 mu (F - R) F^T + lambda (J - 1) J I = U diag(2 mu (s - 1) s + lambda (J - 1) J) U^T
    h = hardening_factor(mat, jp_new)
    J = s[0] * s[1] * s[2]
    d = 2.0 * mat.mu0 * h * wp.cw_mul(s - wp.vec3(1.0), s) + wp.vec3(mat.lambda0 * h * (J - 1.0) * J)
    return Fe, jp_new, to_sym(U, d)


@wp.func
def sand_plastic(mat: MaterialParams, F: wp.mat33, vc: float):
    """Drucker-Prager projection in Hencky strain (Klar et al. 2016) with cohesion and
    volume correction. vc: log-volume expansion discarded at the apex so far (>= 0; kept
    in the particle's Jp slot). Returns (elastic F, new vc, tau), tau the Kirchhoff stress
    of the returned F (= hencky_tau of it), from the same SVD."""
    U, sig, V = wp.svd3(F)
    eps = log_strain(sig)
    tr = eps[0] + eps[1] + eps[2] + vc
    eps_hat = eps - wp.vec3(tr / 3.0)
    norm = wp.length(eps_hat) + 1.0e-20
    # cohesion shifts the cone apex into tension
    trc = tr - mat.cohesion
    vc_new = float(0.0)
    eps_new = eps
    projected = bool(True)
    if trc >= 0.0:
        # beyond the apex: no strength at all; keep the cohesive part only
        eps_new = wp.vec3(mat.cohesion / 3.0)
        if mat.volume_correction != 0:
            vc_new = trc
    else:
        dgamma = norm + (3.0 * mat.lambda0 + 2.0 * mat.mu0) / (2.0 * mat.mu0) * trc * mat.dp_alpha
        projected = dgamma > 0.0
        if projected:
            eps_new = eps - (dgamma / norm) * eps_hat
    Fe = F
    if projected:  # rebuild only when projected (each SVD rebuild drifts ~1e-6)
        s = wp.vec3(wp.exp(eps_new[0]), wp.exp(eps_new[1]), wp.exp(eps_new[2]))
        Fe = U * wp.diag(s) * wp.transpose(V)
        eps_new = log_strain(s)  # what hencky_tau of Fe reads
    return Fe, vc_new, to_sym(U, hencky_diag(eps_new, mat.mu0, mat.lambda0))


@wp.func
def snow_return_map(mat: MaterialParams, F: wp.mat33, jp: float) -> wp.mat44:
    """snow_plastic's (new F, new Jp) packed in a mat44 (3x3 block and [3, 3])."""
    Fe, jp_new, tau = snow_plastic(mat, F, jp)
    return pack_f_jp(Fe, jp_new)


@wp.func
def sand_return_map(mat: MaterialParams, F: wp.mat33, vc: float) -> wp.mat44:
    """sand_plastic's (new F, new vc) packed like snow_return_map."""
    Fe, vc_new, tau = sand_plastic(mat, F, vc)
    return pack_f_jp(Fe, vc_new)


@wp.func
def uninvert(F: wp.mat33) -> wp.mat33:
    """Mirror an inverted F (det F <= 0) back out: U diag(|sigma|) V^T.

    wp.svd3 returns rotations U, V (det +1) and puts the sign of det F on the smallest
    singular value, so R = U V^T is a proper rotation and fixed-corotated stays well defined
    through inversion (Irving et al. 2004). That alone does not save a particle whose
    neighbours are not inverted: all of them share one smooth grid velocity, and the joint
    energy of an inverted and a non-inverted particle is smallest at J = 0, so the body
    flattens. An inversion is therefore treated as a plastic event: the particle keeps the
    magnitude of its stretches and forgets the reflection (a sigma of -0.1 becomes 0.1, still
    compressed and pushing outward; a mirror image F = diag(-1, 1, 1) becomes a rotation)."""
    U, sig, V = wp.svd3(F)
    s = wp.vec3(wp.abs(sig[0]), wp.abs(sig[1]), wp.abs(sig[2]))
    return U * wp.diag(s) * wp.transpose(V)


@wp.func
def solid_energy_density(mat: MaterialParams, F: wp.mat33, jp: float) -> float:
    """Elastic energy per rest volume, mass/(domain*s^2): hardened fixed-corotated
    mu h sum (sigma_i - 1)^2 + lambda h / 2 (J - 1)^2 (snow), or St. Venant-Kirchhoff on
    Hencky strain mu sum eps_i^2 + lambda / 2 (tr eps)^2 (sand). Both are the potentials of
    the stresses `solid_tau` applies.
    Snow whose singular values lie in [POLAR_LO, POLAR_HI] (nearly all of it: its clamp keeps
    them within a few per cent of 1) takes sum (sigma_i - 1)^2 = |F - R|^2 (Frobenius), R from
    polar_rotation, without the SVD, which was most of the once-a-frame report's arithmetic."""
    if mat.mode == MODE_SNOW:
        j_fast = wp.determinant(F)
        if j_fast > 0.0 and singular_values_within(F, POLAR_LO, POLAR_HI):
            D = F - polar_rotation(F)
            return hardening_factor(mat, jp) * (
                mat.mu0 * wp.ddot(D, D) + 0.5 * mat.lambda0 * (j_fast - 1.0) * (j_fast - 1.0)
            )
    U, sig, V = wp.svd3(F)
    if mat.mode == MODE_SAND:
        eps = log_strain(sig)
        tr = eps[0] + eps[1] + eps[2]
        return mat.mu0 * wp.dot(eps, eps) + 0.5 * mat.lambda0 * tr * tr
    h = hardening_factor(mat, jp)
    d = sig - wp.vec3(1.0)
    J = sig[0] * sig[1] * sig[2]
    return h * (mat.mu0 * wp.dot(d, d) + 0.5 * mat.lambda0 * (J - 1.0) * (J - 1.0))


@wp.func
def tait_energy_density(mat: MaterialParams, J: float) -> float:
    """Energy per rest volume stored by the Tait pressure, psi(J) = -int_1^J p dJ:
    K ((J^(1-gamma) - 1) / (gamma - 1) + J - 1), K (J - 1 - ln J) for gamma = 1.
    Zero in tension when the pressure is clamped to p >= 0 (nothing stores it there)."""
    Jc = wp.max(J, 1.0e-4)
    if mat.clamp_pressure != 0 and Jc >= 1.0:
        return 0.0
    g = mat.eos_gamma
    psi = float(0.0)
    if g - 1.0 < 1.0e-6:
        psi = Jc - 1.0 - wp.log(Jc)
    else:
        psi = (wp.pow(Jc, 1.0 - g) - 1.0) / (g - 1.0) + Jc - 1.0
    return mat.bulk_modulus * psi
