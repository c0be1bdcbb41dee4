"""Position-level projection: the lecture's mass-weighted spring relaxation."""


import taichi as ti


@ti.kernel
def relax_springs(model: ti.template(), state: ti.template(), order: ti.template(),
                  offsets: ti.template(), stiffness: ti.math.vec3, tearing: ti.template(),
                  max_strain: float, stretched_only: ti.template()):
    """One relaxation pass over every spring, colour by colour (lecture, "relaxation").

    For a spring (p, q) with target length L = (1 + max_strain) L0:
    delta = (|q - p| - L) / |q - p|, dx = delta (q - p),
    p += w_p / (w_p + w_q) dx, q -= w_q / (w_p + w_q) dx, where w = 1/m and the lecture's
    m_q / (m_p + m_q) = w_p / (w_p + w_q); pins (w = 0) do not move. Springs of one colour share
    no particle, so each colour runs in parallel and the pass equals a sequential Gauss-Seidel
    sweep in colour order: deterministic. stiffness[kind] scales the correction (1 = the
    lecture's full projection; 0 leaves that kind alone). PBD uses max_strain = 0;
    strain limiting (Provot 1995) uses stretched_only, which leaves springs no longer than L.
    """
    for c in ti.static(range(len(offsets) - 1)):
        for t in range(offsets[c], offsets[c + 1]):
            s = order[t]
            alive = True
            if ti.static(tearing):
                alive = state.spring_alive[s] != 0
            p, q = model.spring_indices[s][0], model.spring_indices[s][1]
            wp, wq = model.particle_inv_mass[p], model.particle_inv_mass[q]
            d = state.particle_position[q] - state.particle_position[p]
            length = d.norm()
            target = (1.0 + max_strain) * model.spring_rest_length[s]
            if ti.static(stretched_only):
                alive = alive and length > target
            if alive and wp + wq > 0 and length > 0:
                delta = (length - target) / length
                dx = stiffness[model.spring_kind[s]] * delta * d
                state.particle_position[p] += wp / (wp + wq) * dx
                state.particle_position[q] -= wq / (wp + wq) * dx
