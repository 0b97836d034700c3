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
from numba import njit

from .rod_planar import scatter_contiguous


@njit(cache=True, inline="always")
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def _parallel_transport(u, t1, t2):
    """Transport vector u from tangent t1 to tangent t2 (rotation about t1 × t2)."""
    b = _cross(t1, t2)
    nb = math.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    if nb < 1e-15:
        return u.copy()
    b = b / nb
    n1 = _cross(t1, b)
    n2 = _cross(t2, b)
    return np.dot(u, t1) * t2 + np.dot(u, n1) * n2 + np.dot(u, b) * b


@njit(cache=True)
def _rotate(v, axis, angle):
    c = math.cos(angle)
    s = math.sin(angle)
    return v * c + _cross(axis, v) * s + axis * (np.dot(axis, v) * (1.0 - c))


@njit(cache=True)
def _signed_angle(u, v, axis):
    w = _cross(u, v)
    angle = math.atan2(math.sqrt(np.dot(w, w)), np.dot(u, v))
    return -angle if np.dot(axis, w) < 0.0 else angle


@njit(cache=True)
def rod_frames(qr, tangent_old, director_old, ref_twist_old, tangent, director1, director2, ref_twist, m1, m2):
    """Frames of one rod at coordinates ``qr`` (N, 4), transported from the start-of-step frame."""
    n_edges = qr.shape[0] - 1
    for e in range(n_edges):
        d = qr[e + 1, :3] - qr[e, :3]
        t = d / math.sqrt(np.dot(d, d))
        tangent[e] = t
        a1 = _parallel_transport(director_old[e], tangent_old[e], t)
        a1 = a1 - np.dot(a1, t) * t
        a1 = a1 / math.sqrt(np.dot(a1, a1))
        a2 = _cross(t, a1)
        director1[e] = a1
        director2[e] = a2
        c = math.cos(qr[e, 3])
        s = math.sin(qr[e, 3])
        m1[e] = c * a1 + s * a2
        m2[e] = -s * a1 + c * a2
    ref_twist[0] = 0.0
    ref_twist[n_edges] = 0.0
    for i in range(1, n_edges):
        u = _parallel_transport(director1[i - 1], tangent[i - 1], tangent[i])
        u = _rotate(u, tangent[i], ref_twist_old[i])
        ref_twist[i] = ref_twist_old[i] + _signed_angle(u, director1[i], tangent[i])


@njit(cache=True)
def _cross_matrix(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


@njit(cache=True)
def _assemble_stencil(out, dee, dff, def_, dthe2, dthf2, de_the, de_thf, df_the, df_thf):
    """11×11 second derivative over (x_{i−1}, θ_e, x_i, θ_f, x_{i+1}) from derivatives w.r.t. e and f."""
    out[:, :] = 0.0
    dfe = def_.T
    out[0:3, 0:3] = dee
    out[0:3, 4:7] = -dee + def_
    out[0:3, 8:11] = -def_
    out[4:7, 0:3] = -dee + dfe
    out[4:7, 4:7] = dee - def_ - dfe + dff
    out[4:7, 8:11] = def_ - dff
    out[8:11, 0:3] = -dfe
    out[8:11, 4:7] = dfe - dff
    out[8:11, 8:11] = dff
    out[3, 3] = dthe2
    out[7, 7] = dthf2
    out[0:3, 3] = -de_the
    out[4:7, 3] = de_the - df_the
    out[8:11, 3] = df_the
    out[3, 0:3] = out[0:3, 3]
    out[3, 4:7] = out[4:7, 3]
    out[3, 8:11] = out[8:11, 3]
    out[0:3, 7] = -de_thf
    out[4:7, 7] = de_thf - df_thf
    out[8:11, 7] = df_thf
    out[7, 0:3] = out[0:3, 7]
    out[7, 4:7] = out[4:7, 7]
    out[7, 8:11] = out[8:11, 7]


@njit(cache=True)
def _bend_twist(te, tf, le, lf, m1e, m2e, m1f, m2f, ref_twist, theta_e, theta_f, kappa_bar, eb, gj, grad, hess,
                work, accumulate_hessian):
    """Bending and twisting energy at one interior node; writes its gradient (11,) and Hessian (11, 11)."""
    identity = np.eye(3)
    chi = 1.0 + np.dot(te, tf)
    kb = 2.0 * _cross(te, tf) / chi
    tilde_t = (te + tf) / chi
    tilde_d1 = (m1e + m1f) / chi
    tilde_d2 = (m2e + m2f) / chi
    kappa1 = 0.5 * np.dot(kb, m2e + m2f)
    kappa2 = -0.5 * np.dot(kb, m1e + m1f)
    dk1de = (-kappa1 * tilde_t + _cross(tf, tilde_d2)) / le
    dk1df = (-kappa1 * tilde_t - _cross(te, tilde_d2)) / lf
    dk2de = (-kappa2 * tilde_t - _cross(tf, tilde_d1)) / le
    dk2df = (-kappa2 * tilde_t + _cross(te, tilde_d1)) / lf
    g1 = np.zeros(11)
    g2 = np.zeros(11)
    g1[0:3] = -dk1de
    g1[4:7] = dk1de - dk1df
    g1[8:11] = dk1df
    g1[3] = -0.5 * np.dot(kb, m1e)
    g1[7] = -0.5 * np.dot(kb, m1f)
    g2[0:3] = -dk2de
    g2[4:7] = dk2de - dk2df
    g2[8:11] = dk2df
    g2[3] = -0.5 * np.dot(kb, m2e)
    g2[7] = -0.5 * np.dot(kb, m2f)
    twist = theta_f - theta_e + ref_twist
    gt = np.zeros(11)
    gt[0:3] = -0.5 / le * kb
    gt[8:11] = 0.5 / lf * kb
    gt[4:7] = -(gt[0:3] + gt[8:11])
    gt[3] = -1.0
    gt[7] = 1.0
    dk1 = kappa1 - kappa_bar
    energy = 0.5 * eb * (dk1 * dk1 + kappa2 * kappa2) + 0.5 * gj * twist * twist
    grad[:] = eb * (dk1 * g1 + kappa2 * g2) + gj * twist * gt
    if not accumulate_hessian:
        return energy
    le2 = le * le
    lf2 = lf * lf
    tt = np.outer(tilde_t, tilde_t)
    i_te = identity - np.outer(te, te)
    i_tf = identity - np.outer(tf, tf)
    i_tetf = identity + np.outer(te, tf)

    # κ1
    tf_c_d2t_o_tt = np.outer(_cross(tf, tilde_d2), tilde_t)
    te_c_d2t_o_tt = np.outer(_cross(te, tilde_d2), tilde_t)
    kb_o_d2e = np.outer(kb, m2e)
    kb_o_d2f = np.outer(kb, m2f)
    d2k1de2 = ((2.0 * kappa1 * tt - tf_c_d2t_o_tt - tf_c_d2t_o_tt.T) / le2 - kappa1 / (chi * le2) * i_te
               + (kb_o_d2e + kb_o_d2e.T) / (4.0 * le2))
    d2k1df2 = ((2.0 * kappa1 * tt + te_c_d2t_o_tt + te_c_d2t_o_tt.T) / lf2 - kappa1 / (chi * lf2) * i_tf
               + (kb_o_d2f + kb_o_d2f.T) / (4.0 * lf2))
    d2k1dedf = (-kappa1 / (chi * le * lf) * i_tetf
                + (2.0 * kappa1 * tt - tf_c_d2t_o_tt + te_c_d2t_o_tt.T - _cross_matrix(tilde_d2)) / (le * lf))
    d2k1de_the = (0.5 * np.dot(kb, m1e) * tilde_t - _cross(tf, m1e) / chi) / le
    d2k1de_thf = (0.5 * np.dot(kb, m1f) * tilde_t - _cross(tf, m1f) / chi) / le
    d2k1df_the = (0.5 * np.dot(kb, m1e) * tilde_t + _cross(te, m1e) / chi) / lf
    d2k1df_thf = (0.5 * np.dot(kb, m1f) * tilde_t + _cross(te, m1f) / chi) / lf
    _assemble_stencil(work, d2k1de2, d2k1df2, d2k1dedf, -0.5 * np.dot(kb, m2e), -0.5 * np.dot(kb, m2f),
                      d2k1de_the, d2k1de_thf, d2k1df_the, d2k1df_thf)
    hess[:, :] = eb * (np.outer(g1, g1) + dk1 * work)

    # κ2
    tf_c_d1t_o_tt = np.outer(_cross(tf, tilde_d1), tilde_t)
    te_c_d1t_o_tt = np.outer(_cross(te, tilde_d1), tilde_t)
    kb_o_d1e = np.outer(kb, m1e)
    kb_o_d1f = np.outer(kb, m1f)
    d2k2de2 = ((2.0 * kappa2 * tt + tf_c_d1t_o_tt + tf_c_d1t_o_tt.T) / le2 - kappa2 / (chi * le2) * i_te
               - (kb_o_d1e + kb_o_d1e.T) / (4.0 * le2))
    d2k2df2 = ((2.0 * kappa2 * tt - te_c_d1t_o_tt - te_c_d1t_o_tt.T) / lf2 - kappa2 / (chi * lf2) * i_tf
               - (kb_o_d1f + kb_o_d1f.T) / (4.0 * lf2))
    d2k2dedf = (-kappa2 / (chi * le * lf) * i_tetf
                + (2.0 * kappa2 * tt + tf_c_d1t_o_tt - te_c_d1t_o_tt.T + _cross_matrix(tilde_d1)) / (le * lf))
    d2k2de_the = (0.5 * np.dot(kb, m2e) * tilde_t - _cross(tf, m2e) / chi) / le
    d2k2de_thf = (0.5 * np.dot(kb, m2f) * tilde_t - _cross(tf, m2f) / chi) / le
    d2k2df_the = (0.5 * np.dot(kb, m2e) * tilde_t + _cross(te, m2e) / chi) / lf
    d2k2df_thf = (0.5 * np.dot(kb, m2f) * tilde_t + _cross(te, m2f) / chi) / lf
    _assemble_stencil(work, d2k2de2, d2k2df2, d2k2dedf, 0.5 * np.dot(kb, m1e), 0.5 * np.dot(kb, m1f),
                      d2k2de_the, d2k2de_thf, d2k2df_the, d2k2df_thf)
    hess[:, :] += eb * (np.outer(g2, g2) + kappa2 * work)

    # twist
    te_p = np.outer(kb, te + tilde_t)
    tf_p = np.outer(kb, tf + tilde_t)
    d2m_de2 = -0.25 / le2 * (te_p + te_p.T)
    d2m_df2 = -0.25 / lf2 * (tf_p + tf_p.T)
    d2m_dedf = 0.5 / (le * lf) * (2.0 / chi * _cross_matrix(te) - np.outer(kb, tilde_t))
    zero = np.zeros(3)
    _assemble_stencil(work, d2m_de2, d2m_df2, d2m_dedf, 0.0, 0.0, zero, zero, zero, zero)
    hess[:, :] += gj * (np.outer(gt, gt) + twist * work)
    return energy


@njit(cache=True)
def rod3d_elastic(q, tangent_old, director_old, ref_twist_old, rest_length, stretch_stiffness, bend_stiffness,
                  twist_stiffness, voronoi_length, natural_curvature, force, band, accumulate_hessian):
    """Elastic energy of every rod, (R,); adds −∇E to ``force`` (R, N, 4) and ∇²E to ``band`` (R, 11, 4N).

    The start-of-step frames: ``tangent_old`` and ``director_old`` (R, N − 1, 3), ``ref_twist_old`` (R, N).
    """
    n_rods, n_nodes = q.shape[0], q.shape[1]
    n_edges = n_nodes - 1
    energy = np.zeros(n_rods)
    tangent = np.empty((n_edges, 3))
    d1 = np.empty((n_edges, 3))
    d2 = np.empty((n_edges, 3))
    m1 = np.empty((n_edges, 3))
    m2 = np.empty((n_edges, 3))
    ref_twist = np.empty(n_nodes)
    lengths = np.empty(n_edges)
    grad = np.empty(11)
    hess = np.empty((11, 11))
    work = np.empty((11, 11))
    stretch_hess = np.zeros((7, 7))
    for r in range(n_rods):
        qr = q[r]
        rod_frames(qr, tangent_old[r], director_old[r], ref_twist_old[r], tangent, d1, d2, ref_twist, m1, m2)
        for e in range(n_edges):
            d = qr[e + 1, :3] - qr[e, :3]
            length = math.sqrt(np.dot(d, d))
            lengths[e] = length
            t = tangent[e]
            l0 = rest_length[e]
            ea = stretch_stiffness[e]
            tension = ea * (length / l0 - 1.0)
            energy[r] += 0.5 * ea * l0 * (length / l0 - 1.0) ** 2
            force[r, e, :3] += tension * t
            force[r, e + 1, :3] -= tension * t
            if accumulate_hessian:
                k = ea / l0 * np.outer(t, t) + tension / length * (np.eye(3) - np.outer(t, t))
                stretch_hess[0:3, 0:3] = k
                stretch_hess[4:7, 4:7] = k
                stretch_hess[0:3, 4:7] = -k
                stretch_hess[4:7, 0:3] = -k
                scatter_contiguous(band[r], 4 * e, stretch_hess, 7)
        for i in range(1, n_edges):
            e = i - 1
            energy[r] += _bend_twist(tangent[e], tangent[i], lengths[e], lengths[i], m1[e], m2[e], m1[i], m2[i],
                                     ref_twist[i], qr[e, 3], qr[i, 3], natural_curvature[r],
                                     bend_stiffness[i] / voronoi_length[i], twist_stiffness[i] / voronoi_length[i],
                                     grad, hess, work, accumulate_hessian)
            for a in range(11):
                force[r, e + a // 4, a % 4] -= grad[a]
            if accumulate_hessian:
                scatter_contiguous(band[r], 4 * e, hess, 11)
    return energy


@njit(cache=True)
def rod3d_update_frames(q, tangent_old, director_old, ref_twist_old, tangent, director, ref_twist):
    """Frames at the end of a step: writes ``tangent``, ``director`` (R, N − 1, 3) and ``ref_twist`` (R, N)."""
    n_rods, n_nodes = q.shape[0], q.shape[1]
    d2 = np.empty((n_nodes - 1, 3))
    m1 = np.empty((n_nodes - 1, 3))
    m2 = np.empty((n_nodes - 1, 3))
    for r in range(n_rods):
        rod_frames(q[r], tangent_old[r], director_old[r], ref_twist_old[r], tangent[r], director[r], d2,
                   ref_twist[r], m1, m2)
