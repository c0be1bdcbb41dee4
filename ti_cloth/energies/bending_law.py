"""The bending law of a Fabric whose rigidity depends on curvature (body/bending_curve.py: the
law, its secant rigidities S and why every solver can use them), on the kernels' side: a
triangle's secant matrix B(k) = A sum_d c_d S_d b_d b_d^T from its hinge tangents, in place
of the constant B of energies/bending.py wherever that reads one (the moments, the implicit
solvers' Gauss-Newton blocks, XPBD's stiffness). Compiled in only for a model that has a
curve (Model.curved)."""

import taichi as ti

# rho^2 [1/m^2] below which a triangle bends at its flat rigidities (a radius of 1e12 m: the
# law's mean 2 F / rho^2 is D(0) to within 1e-12 there, and the quotient would lose digits)
FLAT = 1e-24


@ti.func
def secant_rigidities(model: ti.template(), c, k):
    """S (3,) of curve c at the change of curvature k = (k11, k22, k12) [1/m]: D at rho, the
    mean 2 F(rho) / rho^2 on the segment rho falls in (segment_integral's form), and the
    secant S_d = mean_d + sum_e w_e (D_e - mean_e) (bending_curve.py, module doc)."""
    w = ti.Vector([k[0] * k[0], k[1] * k[1], 2.0 * k[2] * k[2]])
    rho2 = w.sum()
    rho = ti.sqrt(rho2)
    first = c * ti.static(model.curve_length)
    j = first
    for i in ti.static(range(1, model.curve_length)):
        if rho >= model.curve_samples[first + i]:
            j = first + i
    s = model.curve_samples[j]
    d = model.curve_rigidity[j]
    m = model.curve_slope[j]
    secant = d
    if rho2 > FLAT:
        u = rho - s
        energy = model.curve_integral[j] + d * (u * (rho + s) / 2.0) + m * (u * u * (2.0 * rho + s) / 6.0)
        mean = (2.0 / rho2) * energy
        secant = mean + w.dot(d + m * u - mean) / rho2
    return secant


@ti.func
def secant_matrix(model: ti.template(), f, dt, positive: ti.template()):
    """Triangle f's B(k) (00 11 22 01 02 12) at its hinge tangents dt (3,) (t - t_rest), k
    from its curvature components; with `positive`, S_d clamped at 0 (the Hessian's and
    XPBD's use: positive semi-definite)."""
    b = model.face_components[f]                # b[3 d + i]
    k = ti.Vector([b[0] * dt[0] + b[1] * dt[1] + b[2] * dt[2],
                   b[3] * dt[0] + b[4] * dt[1] + b[5] * dt[2],
                   b[6] * dt[0] + b[7] * dt[1] + b[8] * dt[2]])
    s = secant_rigidities(model, model.face_curve[f], k)
    if ti.static(positive):
        s = ti.max(s, 0.0)
    w = model.face_area[f] * ti.Vector([s[0], s[1], 2.0 * s[2]])
    out = ti.Vector([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    for d in ti.static(range(3)):
        r = ti.Vector([b[3 * d], b[3 * d + 1], b[3 * d + 2]])
        out += w[d] * ti.Vector([r[0] * r[0], r[1] * r[1], r[2] * r[2],
                                 r[0] * r[1], r[0] * r[2], r[1] * r[2]])
    return out


@ti.func
def face_matrix(model: ti.template(), f, dt, positive: ti.template()):
    """Triangle f's bending matrix at hinge tangents dt: its secant matrix where it has a
    curve, else the constant face_bending (either, 00 11 22 01 02 12)."""
    out = model.face_bending[f]
    if ti.static(model.curved):
        if model.face_curve[f] >= 0:
            out = secant_matrix(model, f, dt, positive)
    return out
