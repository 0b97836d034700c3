"""Elastic energy of a 3-D discrete elastic rod (stretch, bend, twist) with analytic gradient and Hessian.

The discrete elastic rods of Bergou et al. (2008, 2010), with the gradient and Hessian expressions of Jawed et al.,
"A Primer on the Kinematics of Discrete Elastic Rods" (2018). Notation (one rod):

=========  ===========================================================  =======
symbol     meaning                                                      unit
=========  ===========================================================  =======
x_i        node position                                                m
θ_e        twist angle of edge e's material frame about its reference   rad
t_e        unit tangent of edge e                                       1
a1, a2     reference directors of an edge, time-parallel transported    1
m1, m2     material directors: (a1, a2) rotated by θ_e about t_e        1
κb_i       curvature binormal 2·t_e × t_f / (1 + t_e·t_f) at node i      1
κ1, κ2     material curvatures ½·κb·(m2_e + m2_f), −½·κb·(m1_e + m1_f)  1
τ_i        twist θ_f − θ_e + reference twist                            rad
EA, EI,    stretching [N], bending and twisting [N·m²] stiffness         —
GJ
=========  ===========================================================  =======

E = Σ_edges ½·EA·l̄·(|e|/l̄ − 1)² + Σ_nodes EI/(2l_i)·((κ1 − κ̄)² + κ2²) + Σ_nodes GJ/(2l_i)·τ².
κ̄ acts on κ1; with m1 = +z at rest, κ̄ < 0 bends the finger toward −z, as in the planar model.

The reference frame of each edge is carried from the start of the step by parallel transport along the change of
its tangent; the derivative expressions are exact for that convention at the start-of-step frame, which is how
the finite-difference tests check them.
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import kernel
from .linalg import scatter_contiguous

# 3-vectors are tuples: value types that Numba keeps in registers, so the kernel allocates nothing per node.


@kernel
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@kernel
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@kernel
def _axpy(alpha, a, beta, b):
    """alpha·a + beta·b."""
    return (alpha * a[0] + beta * b[0], alpha * a[1] + beta * b[1], alpha * a[2] + beta * b[2])


@kernel
def _scale(alpha, a):
    return (alpha * a[0], alpha * a[1], alpha * a[2])


@kernel
def _row(array, i):
    return (array[i, 0], array[i, 1], array[i, 2])


@kernel
def _parallel_transport(u, t1, t2):
    """Transport vector u from tangent t1 to tangent t2 (rotation about t1 × t2)."""
    b = _cross(t1, t2)
    nb = math.sqrt(_dot(b, b))
    if nb < 1e-15:
        return u
    b = _scale(1.0 / nb, b)
    n1 = _cross(t1, b)
    n2 = _cross(t2, b)
    return _axpy(_dot(u, t1), t2, 1.0, _axpy(_dot(u, n1), n2, _dot(u, b), b))


@kernel
def _rotate(v, axis, angle):
    c = math.cos(angle)
    s = math.sin(angle)
    return _axpy(c, v, 1.0, _axpy(s, _cross(axis, v), _dot(axis, v) * (1.0 - c), axis))


@kernel
def _signed_angle(u, v, axis):
    w = _cross(u, v)
    angle = math.atan2(math.sqrt(_dot(w, w)), _dot(u, v))
    return -angle if _dot(axis, w) < 0.0 else angle


@kernel(python=True)
def rod_frames(qr, tangent_old, director_old, ref_twist_old, tangent, director1, ref_twist, m1, m2, lengths):
    """Frames of one rod at coordinates ``qr`` (N, 4), transported from the start-of-step frame.

    Writes edge ``tangent``, reference ``director1``, material directors ``m1``, ``m2`` (N − 1, 3), edge
    ``lengths`` (N − 1,) and the ``ref_twist`` (N,) of the interior nodes.
    """
    n_edges = qr.shape[0] - 1
    for e in range(n_edges):
        d = (qr[e + 1, 0] - qr[e, 0], qr[e + 1, 1] - qr[e, 1], qr[e + 1, 2] - qr[e, 2])
        length = math.sqrt(_dot(d, d))
        lengths[e] = length
        t = _scale(1.0 / length, d)
        a1 = _parallel_transport(_row(director_old, e), _row(tangent_old, e), t)
        a1 = _axpy(1.0, a1, -_dot(a1, t), t)
        a1 = _scale(1.0 / math.sqrt(_dot(a1, a1)), a1)
        a2 = _cross(t, a1)
        c = math.cos(qr[e, 3])
        s = math.sin(qr[e, 3])
        for k in range(3):
            tangent[e, k] = t[k]
            director1[e, k] = a1[k]
            m1[e, k] = c * a1[k] + s * a2[k]
            m2[e, k] = -s * a1[k] + c * a2[k]
    ref_twist[0] = 0.0
    ref_twist[n_edges] = 0.0
    for i in range(1, n_edges):
        t = _row(tangent, i)
        u = _parallel_transport(_row(director1, i - 1), _row(tangent, i - 1), t)
        u = _rotate(u, t, ref_twist_old[i])
        ref_twist[i] = ref_twist_old[i] + _signed_angle(u, _row(director1, i), t)


(_TT, _TE, _TF, _KB, _M1E, _M2E, _M1F, _M2F, _D1T, _D2T, _TF_X_D2T, _TE_X_D2T, _TF_X_D1T, _TE_X_D1T, _TE_TT,
 _TF_TT, _CE_THE, _CF_THE, _CE_THF, _CF_THF) = range(20)
"""The rows of :func:`_bend_twist`'s ``vectors``: t_e, t_f, t̃ = (t_e + t_f)/χ, (κb), the material directors of the
edges e and f, d̃1, d̃2 (the same sums for the directors), the cross products t_f × d̃2, t_e × d̃2, t_f × d̃1,
t_e × d̃1, t_e + t̃, t_f + t̃, and the mixed derivatives' columns by θ_e and θ_f of the edges e and f."""
N_STENCIL_VECTORS = 20


@kernel
def _bend_twist(te, tf, le, lf, m1e, m2e, m1f, m2f, twist, kappa_bar, eb, gj, stencil, vectors,
                accumulate_hessian):
    """Bending and twisting energy at one interior node; writes the lower triangle of its Hessian (11, 11) over
    (x_{i−1}, θ_e, x_i, θ_f, x_{i+1}) into ``stencil[0]`` and its gradient (11,) into ``stencil[1, 0]``.
    ``eb`` = EI/l_i, ``gj`` = GJ/l_i. The rest of ``stencil`` (6, 11, 11) is scratch: the gradients of κ1, κ2 and
    the twist in rows 0–2 of ``stencil[2]``, the blocks of second derivatives by the edges in ``stencil[3:6]``.
    One array for all of it, each part indexed in place: Numba binds every array argument again at each call, at
    two reference-count operations each, and this runs at every interior node of every rod assembled.
    ``vectors`` (:data:`N_STENCIL_VECTORS`, 3) is scratch for the 3-vectors the Hessian's blocks read."""
    chi = 1.0 + _dot(te, tf)
    kb = _scale(2.0 / chi, _cross(te, tf))
    tt = _scale(1.0 / chi, _axpy(1.0, te, 1.0, tf))
    d1t = _scale(1.0 / chi, _axpy(1.0, m1e, 1.0, m1f))
    d2t = _scale(1.0 / chi, _axpy(1.0, m2e, 1.0, m2f))
    kappa1 = 0.5 * _dot(kb, _axpy(1.0, m2e, 1.0, m2f))
    kappa2 = -0.5 * _dot(kb, _axpy(1.0, m1e, 1.0, m1f))
    tf_x_d2t = _cross(tf, d2t)
    te_x_d2t = _cross(te, d2t)
    tf_x_d1t = _cross(tf, d1t)
    te_x_d1t = _cross(te, d1t)
    dk1de = _axpy(-kappa1 / le, tt, 1.0 / le, tf_x_d2t)
    dk1df = _axpy(-kappa1 / lf, tt, -1.0 / lf, te_x_d2t)
    dk2de = _axpy(-kappa2 / le, tt, -1.0 / le, tf_x_d1t)
    dk2df = _axpy(-kappa2 / lf, tt, 1.0 / lf, te_x_d1t)
    kb_m1e, kb_m1f = _dot(kb, m1e), _dot(kb, m1f)
    kb_m2e, kb_m2f = _dot(kb, m2e), _dot(kb, m2f)
    dk1 = kappa1 - kappa_bar
    w1 = eb * dk1
    w2 = eb * kappa2
    w3 = gj * twist
    energy = 0.5 * eb * (dk1 * dk1 + kappa2 * kappa2) + 0.5 * gj * twist * twist
    # gradients of κ1, κ2 and the twist over the stencil, as (position blocks, θ_e, θ_f): rows 0, 1, 2 of
    # ``stencil[2]``, indexed in place (no view of each row made per node)
    for k in range(3):
        stencil[2, 0, k], stencil[2, 0, 4 + k], stencil[2, 0, 8 + k] = -dk1de[k], dk1de[k] - dk1df[k], dk1df[k]
        stencil[2, 1, k], stencil[2, 1, 4 + k], stencil[2, 1, 8 + k] = -dk2de[k], dk2de[k] - dk2df[k], dk2df[k]
        stencil[2, 2, k] = -0.5 / le * kb[k]
        stencil[2, 2, 8 + k] = 0.5 / lf * kb[k]
        stencil[2, 2, 4 + k] = -stencil[2, 2, k] - stencil[2, 2, 8 + k]
    stencil[2, 0, 3], stencil[2, 0, 7] = -0.5 * kb_m1e, -0.5 * kb_m1f
    stencil[2, 1, 3], stencil[2, 1, 7] = -0.5 * kb_m2e, -0.5 * kb_m2f
    stencil[2, 2, 3], stencil[2, 2, 7] = -1.0, 1.0
    for a in range(11):
        stencil[1, 0, a] = w1 * stencil[2, 0, a] + w2 * stencil[2, 1, a] + w3 * stencil[2, 2, a]
    if not accumulate_hessian:
        return energy
    # Second derivatives with respect to the edges e and f, weighted and summed over κ1 (w1), κ2 (w2), twist (w3):
    # the blocks ee, ff and ef, ``stencil[3]``, ``[4]`` and ``[5]``.
    le2, lf2, lelf = le * le, lf * lf, le * lf
    te_tt = _axpy(1.0, te, 1.0, tt)
    tf_tt = _axpy(1.0, tf, 1.0, tt)
    # the loop below reads its 3-vectors from rows of ``vectors``: a tuple indexed by a loop variable compiles to a
    # branch per read, and this loop is too large for LLVM to unroll them away; read from tuples, the rod's assembly
    # with its Hessian took about 1.6 times as long (the same values and arithmetic)
    v = vectors
    for row, vector in enumerate((tt, te, tf, kb, m1e, m2e, m1f, m2f, d1t, d2t, tf_x_d2t, te_x_d2t, tf_x_d1t,
                                  te_x_d1t, te_tt, tf_tt)):
        v[row, 0], v[row, 1], v[row, 2] = vector
    for i in range(3):
        for j in range(3):
            delta = 1.0 if i == j else 0.0
            ttij = v[_TT, i] * v[_TT, j]
            k1ee = ((2.0 * kappa1 * ttij - v[_TF_X_D2T, i] * v[_TT, j] - v[_TT, i] * v[_TF_X_D2T, j]) / le2
                    - kappa1 / (chi * le2) * (delta - v[_TE, i] * v[_TE, j])
                    + (v[_KB, i] * v[_M2E, j] + v[_M2E, i] * v[_KB, j]) / (4.0 * le2))
            k1ff = ((2.0 * kappa1 * ttij + v[_TE_X_D2T, i] * v[_TT, j] + v[_TT, i] * v[_TE_X_D2T, j]) / lf2
                    - kappa1 / (chi * lf2) * (delta - v[_TF, i] * v[_TF, j])
                    + (v[_KB, i] * v[_M2F, j] + v[_M2F, i] * v[_KB, j]) / (4.0 * lf2))
            k2ee = ((2.0 * kappa2 * ttij + v[_TF_X_D1T, i] * v[_TT, j] + v[_TT, i] * v[_TF_X_D1T, j]) / le2
                    - kappa2 / (chi * le2) * (delta - v[_TE, i] * v[_TE, j])
                    - (v[_KB, i] * v[_M1E, j] + v[_M1E, i] * v[_KB, j]) / (4.0 * le2))
            k2ff = ((2.0 * kappa2 * ttij - v[_TE_X_D1T, i] * v[_TT, j] - v[_TT, i] * v[_TE_X_D1T, j]) / lf2
                    - kappa2 / (chi * lf2) * (delta - v[_TF, i] * v[_TF, j])
                    - (v[_KB, i] * v[_M1F, j] + v[_M1F, i] * v[_KB, j]) / (4.0 * lf2))
            tee = -0.25 / le2 * (v[_KB, i] * v[_TE_TT, j] + v[_TE_TT, i] * v[_KB, j])
            tff = -0.25 / lf2 * (v[_KB, i] * v[_TF_TT, j] + v[_TF_TT, i] * v[_KB, j])
            # cross-product matrices [a]× have entries [a]×_ij = −ε_ijk a_k
            x_d2t = _cross_matrix_entry(v, _D2T, i, j)
            x_d1t = _cross_matrix_entry(v, _D1T, i, j)
            x_te = _cross_matrix_entry(v, _TE, i, j)
            k1ef = (-kappa1 / (chi * lelf) * (delta + v[_TE, i] * v[_TF, j])
                    + (2.0 * kappa1 * ttij - v[_TF_X_D2T, i] * v[_TT, j] + v[_TT, i] * v[_TE_X_D2T, j] - x_d2t)
                    / lelf)
            k2ef = (-kappa2 / (chi * lelf) * (delta + v[_TE, i] * v[_TF, j])
                    + (2.0 * kappa2 * ttij + v[_TF_X_D1T, i] * v[_TT, j] - v[_TT, i] * v[_TE_X_D1T, j] + x_d1t)
                    / lelf)
            tef = 0.5 / lelf * (2.0 / chi * x_te - v[_KB, i] * v[_TT, j])
            stencil[3, i, j] = w1 * k1ee + w2 * k2ee + w3 * tee
            stencil[4, i, j] = w1 * k1ff + w2 * k2ff + w3 * tff
            stencil[5, i, j] = w1 * k1ef + w2 * k2ef + w3 * tef
    # mixed position–twist-angle derivatives (the twist's own are zero)
    tf_x_m1e, tf_x_m1f, te_x_m1e, te_x_m1f = _cross(tf, m1e), _cross(tf, m1f), _cross(te, m1e), _cross(te, m1f)
    tf_x_m2e, tf_x_m2f, te_x_m2e, te_x_m2f = _cross(tf, m2e), _cross(tf, m2f), _cross(te, m2e), _cross(te, m2f)
    ce_the = _axpy(w1 / le, _axpy(0.5 * kb_m1e, tt, -1.0 / chi, tf_x_m1e),
                   w2 / le, _axpy(0.5 * kb_m2e, tt, -1.0 / chi, tf_x_m2e))
    ce_thf = _axpy(w1 / le, _axpy(0.5 * kb_m1f, tt, -1.0 / chi, tf_x_m1f),
                   w2 / le, _axpy(0.5 * kb_m2f, tt, -1.0 / chi, tf_x_m2f))
    cf_the = _axpy(w1 / lf, _axpy(0.5 * kb_m1e, tt, 1.0 / chi, te_x_m1e),
                   w2 / lf, _axpy(0.5 * kb_m2e, tt, 1.0 / chi, te_x_m2e))
    cf_thf = _axpy(w1 / lf, _axpy(0.5 * kb_m1f, tt, 1.0 / chi, te_x_m1f),
                   w2 / lf, _axpy(0.5 * kb_m2f, tt, 1.0 / chi, te_x_m2f))
    c_the2 = -0.5 * w1 * kb_m2e + 0.5 * w2 * kb_m1e
    c_thf2 = -0.5 * w1 * kb_m2f + 0.5 * w2 * kb_m1f
    for row, vector in enumerate((ce_the, cf_the, ce_thf, cf_thf)):
        v[_CE_THE + row, 0], v[_CE_THE + row, 1], v[_CE_THE + row, 2] = vector
    # chain rule from the edges e = x_i − x_{i−1}, f = x_{i+1} − x_i to the stencil's nodes
    for i in range(3):
        for j in range(3):
            ee, ff, ef, fe = stencil[3, i, j], stencil[4, i, j], stencil[5, i, j], stencil[5, j, i]
            stencil[0, i, j] = ee
            stencil[0, i, 4 + j] = -ee + ef
            stencil[0, i, 8 + j] = -ef
            stencil[0, 4 + i, j] = -ee + fe
            stencil[0, 4 + i, 4 + j] = ee - ef - fe + ff
            stencil[0, 4 + i, 8 + j] = ef - ff
            stencil[0, 8 + i, j] = -fe
            stencil[0, 8 + i, 4 + j] = fe - ff
            stencil[0, 8 + i, 8 + j] = ff
        for col, ce, cf in ((3, _CE_THE, _CF_THE), (7, _CE_THF, _CF_THF)):
            stencil[0, i, col] = stencil[0, col, i] = -v[ce, i]
            stencil[0, 4 + i, col] = stencil[0, col, 4 + i] = v[ce, i] - v[cf, i]
            stencil[0, 8 + i, col] = stencil[0, col, 8 + i] = v[cf, i]
    stencil[0, 3, 3] = c_the2
    stencil[0, 7, 7] = c_thf2
    stencil[0, 3, 7] = stencil[0, 7, 3] = 0.0
    for a in range(11):  # the lower triangle, which is all the band reads (linalg.scatter_contiguous)
        for b in range(a + 1):
            stencil[0, a, b] += eb * (stencil[2, 0, a] * stencil[2, 0, b] + stencil[2, 1, a] * stencil[2, 1, b]) \
                + gj * stencil[2, 2, a] * stencil[2, 2, b]
    return energy


@kernel
def _cross_matrix_entry(vectors, row, i, j):
    """Entry (i, j) of the matrix [a]× with [a]×·b = a × b, for a = ``vectors[row]``."""
    if i == j:
        return 0.0
    k = 3 - i - j
    sign = 1.0 if (j - i) % 3 == 1 else -1.0
    return -sign * vectors[row, k]


# The work arrays of one rod's assembly are views of one flat buffer (:func:`elastic_scratch`), passed in so that
# the assembly allocates nothing (a GPU thread has no heap to allocate from). One array rather than nine, so that
# the bundles Newton's levels pass on stay short.


@kernel(python=True)
def elastic_scratch_size(n_nodes):
    """Elements of :func:`rod3d_elastic_rod`'s work buffer for rods of ``n_nodes`` nodes (0 for 0 nodes)."""
    if n_nodes == 0:
        return 0
    n_edges = n_nodes - 1
    return 13 * n_edges + n_nodes + 6 * 11 * 11 + N_STENCIL_VECTORS * 3 + 7 * 7


@kernel(python=True, runtime=True)  # it allocates
def elastic_scratch(n_nodes):
    """:func:`rod3d_elastic_rod`'s work buffer for rods of ``n_nodes`` nodes (0: empty, for the planar model)."""
    return np.empty(elastic_scratch_size(n_nodes))


@kernel(python=True, inline=True, runtime=True)  # inlined, its views are its caller's; from Python, new ones
def elastic_views(buffer, n_nodes):
    """The work arrays in ``buffer`` (:func:`elastic_scratch`): the edges' tangents, reference directors and material
    directors m1, m2 (N − 1, 3), the reference twist (N,), the edge lengths (N − 1,), :func:`_bend_twist`'s stencil
    (6, 11, 11) and vectors (:data:`N_STENCIL_VECTORS`, 3), and a stretch Hessian (7, 7)."""
    n_edges = n_nodes - 1
    at = 0
    tangent = buffer[at:at + 3 * n_edges].reshape((n_edges, 3))
    at += 3 * n_edges
    director = buffer[at:at + 3 * n_edges].reshape((n_edges, 3))
    at += 3 * n_edges
    m1 = buffer[at:at + 3 * n_edges].reshape((n_edges, 3))
    at += 3 * n_edges
    m2 = buffer[at:at + 3 * n_edges].reshape((n_edges, 3))
    at += 3 * n_edges
    reference_twist = buffer[at:at + n_nodes]
    at += n_nodes
    lengths = buffer[at:at + n_edges]
    at += n_edges
    stencil = buffer[at:at + 6 * 11 * 11].reshape((6, 11, 11))
    at += 6 * 11 * 11
    vectors = buffer[at:at + N_STENCIL_VECTORS * 3].reshape((N_STENCIL_VECTORS, 3))
    at += N_STENCIL_VECTORS * 3
    stretch_hessian = buffer[at:at + 7 * 7].reshape((7, 7))
    return tangent, director, m1, m2, reference_twist, lengths, stencil, vectors, stretch_hessian


@kernel
def rod3d_elastic_rod(q, tangent_old, director_old, ref_twist_old, rest_length, stretch_stiffness, bend_stiffness,
                      twist_stiffness, voronoi_length, natural_curvature, force, band, accumulate_hessian, scratch):
    """Elastic energy of one rod [J]; adds −∇E to ``force`` (N, 4) and ∇²E to ``band`` (4N, 11).

    ``q`` (N, 4); the start-of-step frames: ``tangent_old`` and ``director_old`` (N − 1, 3), ``ref_twist_old`` (N);
    ``natural_curvature`` κ̄ of the rod; ``scratch`` the work buffer (:func:`elastic_scratch`).
    """
    n_nodes = q.shape[0]
    n_edges = n_nodes - 1
    energy = 0.0
    tangent, d1, m1, m2, ref_twist, lengths, stencil, vectors, stretch_hess = elastic_views(scratch, n_nodes)
    hess = stencil[0]
    stretch_hess[:, :] = 0.0  # the twist's rows and columns stay zero
    rod_frames(q, tangent_old, director_old, ref_twist_old, tangent, d1, ref_twist, m1, m2, lengths)
    for e in range(n_edges):
        length = lengths[e]
        t = _row(tangent, e)
        l0 = rest_length[e]
        ea = stretch_stiffness[e]
        tension = ea * (length / l0 - 1.0)
        energy += 0.5 * ea * l0 * (length / l0 - 1.0) ** 2
        for k in range(3):
            force[e, k] += tension * t[k]
            force[e + 1, k] -= tension * t[k]
        if accumulate_hessian:
            axial = ea / l0
            lateral = tension / length
            for i in range(3):
                for j in range(3):
                    kij = (axial - lateral) * t[i] * t[j] + (lateral if i == j else 0.0)
                    stretch_hess[i, j] = kij
                    stretch_hess[4 + i, 4 + j] = kij
                    stretch_hess[i, 4 + j] = -kij
                    stretch_hess[4 + i, j] = -kij
            scatter_contiguous(band, 4 * e, stretch_hess, 7)
    for i in range(1, n_edges):
        e = i - 1
        twist = q[i, 3] - q[e, 3] + ref_twist[i]
        energy += _bend_twist(_row(tangent, e), _row(tangent, i), lengths[e], lengths[i], _row(m1, e), _row(m2, e),
                              _row(m1, i), _row(m2, i), twist, natural_curvature,
                              bend_stiffness[i] / voronoi_length[i], twist_stiffness[i] / voronoi_length[i], stencil,
                              vectors, accumulate_hessian)
        for a in range(11):
            force[e + a // 4, a % 4] -= stencil[1, 0, a]
        if accumulate_hessian:
            scatter_contiguous(band, 4 * e, hess, 11)
    return energy


@kernel(python=True, runtime=True)  # it allocates
def rod3d_elastic(q, tangent_old, director_old, ref_twist_old, rest_length, stretch_stiffness, bend_stiffness,
                  twist_stiffness, voronoi_length, natural_curvature, force, band, accumulate_hessian):
    """Elastic energy of every rod, (R,); adds −∇E to ``force`` (R, N, 4) and ∇²E to ``band`` (R, 4N, 11).

    The start-of-step frames: ``tangent_old`` and ``director_old`` (R, N − 1, 3), ``ref_twist_old`` (R, N).
    """
    energy = np.zeros(q.shape[0])
    scratch = elastic_scratch(q.shape[1])
    for r in range(q.shape[0]):
        energy[r] = rod3d_elastic_rod(q[r], tangent_old[r], director_old[r], ref_twist_old[r], rest_length,
                                      stretch_stiffness, bend_stiffness, twist_stiffness, voronoi_length,
                                      natural_curvature[r], force[r], band[r], accumulate_hessian, scratch)
    return energy


@kernel(python=True)
def rod3d_update_frames(q, tangent_old, director_old, ref_twist_old, tangent, director, ref_twist, scratch):
    """Frames at the end of a step: writes ``tangent``, ``director`` (R, N − 1, 3) and ``ref_twist`` (R, N);
    ``scratch`` is the 3-D energy's work buffer (:func:`elastic_scratch`)."""
    n_rods, n_nodes = q.shape[0], q.shape[1]
    _, _, m1, m2, _, lengths, _, _, _ = elastic_views(scratch, n_nodes)
    for r in range(n_rods):
        rod_frames(q[r], tangent_old[r], director_old[r], ref_twist_old[r], tangent[r], director[r], ref_twist[r],
                   m1, m2, lengths)
