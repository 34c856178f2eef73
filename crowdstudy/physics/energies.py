"""Reference (numpy, float64) energies with analytic gradients and Hessians.

These restate, term by term, what the Warp kernels assemble; the tests check them against
finite differences and the kernels against them. Increments per body are ``(dx, dw)``:
``x <- x + dx`` (m) and ``R <- exp([dw]x) R`` (rad, world frame); gradients are ordered
``[dx, dw]`` per body, Hessians accordingly.

Notation: ``a(M) = (M12 - M21, M20 - M02, M01 - M10)`` so that ``tr([e]x M) = e . a(M)``;
then ``d/dw tr(exp([w]x) R C) = a(R C)`` at w = 0 and the second derivative is
``sym(R C) - tr(R C) Id`` (symmetrised).
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.capsules import closest_points_on_segments
from crowdstudy.body.rotations import skew

__all__ = [
    "foot_planted_weight",
    "foot_anchor_update",
    "foot_anchor_energy",
    "vee_asym",
    "inertia_energy",
    "gravity_energy",
    "ball_joint_energy",
    "control_energy",
    "root_translation_energy",
    "contact_energy",
]


def vee_asym(m: np.ndarray) -> np.ndarray:
    """a(M) for a (3, 3) matrix (see module docstring)."""
    return np.array([m[1, 2] - m[2, 1], m[2, 0] - m[0, 2], m[0, 1] - m[1, 0]])


def _sym(m):
    return 0.5 * (m + m.T)


def inertia_energy(x, R, x_pred, R_pred, mass, J, h):
    """E = m/(2h^2) |x - x~|^2 + 1/(2h^2) tr((R - R~) J (R - R~)^T).

    Args: x, x_pred (3,) m; R, R_pred (3, 3); mass kg; J (3, 3) kg m^2 body-frame second
    moment; h s. Returns ``(E J, gradient (6,), Hessian (6, 6))`` (exact).
    """
    B = R @ J @ R_pred.T
    e = 0.5 * mass / h**2 * np.sum((x - x_pred) ** 2) + (np.trace(J) - np.trace(B)) / h**2
    g = np.concatenate([mass / h**2 * (x - x_pred), -vee_asym(B) / h**2])
    H = np.zeros((6, 6))
    H[:3, :3] = mass / h**2 * np.eye(3)
    H[3:, 3:] = (np.trace(B) * np.eye(3) - _sym(B)) / h**2
    return e, g, H


def gravity_energy(x, mass, gravity=9.81):
    """E = m g z. Returns ``(E, gradient (6,), Hessian (6, 6) = 0)``."""
    g = np.zeros(6)
    g[2] = mass * gravity
    return mass * gravity * x[2], g, np.zeros((6, 6))


def ball_joint_energy(xa, Ra, pa, xb, Rb, pb, k):
    """Soft ball joint E = k/2 |x_a + R_a p_a - x_b - R_b p_b|^2 between a (parent) and b.

    Returns ``(E, gradient (12,) [a; b], Gauss-Newton Hessian k J^T J (12, 12))``; exact
    when the joint is closed (C = 0).
    """
    ra, rb = Ra @ pa, Rb @ pb
    c = xa + ra - xb - rb
    jac = np.hstack([np.eye(3), -skew(ra), -np.eye(3), skew(rb)])
    return 0.5 * k * c @ c, k * jac.T @ c, k * jac.T @ jac


def control_energy(Rp, Rc, target, damp_ref, k, dh2):
    """Eq. 4 on the joint rotation R = Rp^T Rc (Rp = Id for the root's absolute rotation):
    E = k/2 |R - target|_F^2 + dh2/2 |R - damp_ref|_F^2 with dh2 = d / h^2 and
    damp_ref = R_old + R^ - R^_old.

    Returns ``(E, gradient (6,) [dw_parent; dw_child], Gauss-Newton Hessian (6, 6))``, the
    Hessian ``2 (k + dh2) [[I, -I], [-I, I]]`` (exact at zero residual).
    """
    rel = Rp.T @ Rc
    e = 0.5 * k * np.sum((rel - target) ** 2) + 0.5 * dh2 * np.sum((rel - damp_ref) ** 2)
    res = k * (rel - target) + dh2 * (rel - damp_ref)
    gc = vee_asym(Rc @ res.T @ Rp.T)
    c = 2.0 * (k + dh2)
    H = np.block([[c * np.eye(3), -c * np.eye(3)], [-c * np.eye(3), c * np.eye(3)]])
    return e, np.concatenate([-gc, gc]), H


def root_translation_energy(x, x_old, target, target_old, k, dh2):
    """E = k/2 |x - x^|^2 + dh2/2 |x - x_old - x^ + x^_old|^2 (m). Returns (E, g (3,), H (3, 3))."""
    a, b = x - target, x - x_old - target + target_old
    return 0.5 * k * a @ a + 0.5 * dh2 * b @ b, k * a + dh2 * b, (k + dh2) * np.eye(3)


def foot_planted_weight(target, target_old, h, planted_speed):
    """Anchor weight w of a foot body: 1 while the animation's foot moves slower than
    ``planted_speed`` m/s horizontally, 0 above twice that, linear in between.
    target, target_old: (3,) m; h: s."""
    speed = np.linalg.norm((np.asarray(target) - target_old)[:2]) / h
    return float(np.clip(2.0 - speed / planted_speed, 0.0, 1.0))


def foot_anchor_update(x_old, target_old, offset, w, slip):
    """Lagged stance anchor: the new horizontal offset (3,) m (z = 0) of a foot body from its
    animation target. Free foot (w = 0): follows the body; planted: kept, but dragged along
    so that |x_old - target_old - offset| <= slip (m, = max force / stiffness)."""
    rel = np.asarray(x_old, np.float64) - target_old
    rel[2] = 0.0
    if w <= 0:
        return rel
    d = rel - offset
    n = np.linalg.norm(d)
    return offset + d * (1.0 - slip / n) if n > slip else np.asarray(offset, np.float64)


def foot_anchor_energy(x, x_old, target, target_old, offset, w, k, c, h, kt, dh2):
    """Stance-foot anchor of a foot body, horizontal (P = diag(1, 1, 0)), weight w:
    E = w (k/2 |P(x - x^ - o)|^2 + c/(2h) |P(x - x_old - x^ + x^_old)|^2)
        - w (kt/2 |P(x - x^)|^2 + dh2/2 |P(x - x_old - x^ + x^_old)|^2)
    (the second line removes the body's horizontal tracking coupling while planted).
    x, x_old, target, target_old, offset: (3,) m; k N/m; c N s/m; kt N/m; dh2 N/m.
    Returns (E, g (3,), H (3, 3))."""
    P = np.diag([1.0, 1.0, 0.0])
    e = P @ (x - target - offset)
    ea = P @ (x - target)
    dv = P @ (x - x_old - target + target_old)
    energy = w * (0.5 * k * e @ e + 0.5 * c / h * dv @ dv - 0.5 * kt * ea @ ea - 0.5 * dh2 * dv @ dv)
    grad = w * (k * e + c / h * dv - kt * ea - dh2 * dv)
    return energy, grad, w * (k + c / h - kt - dh2) * P


def contact_energy(xa, Ra, seg_a, ra, xb, Rb, seg_b, rb, k, stiffening=0.0):
    """Penalty (k/2) depth^2 between capsule a and capsule b (depth = r_a + r_b - distance),
    plus k depth^3 / (3 d0) with ``stiffening`` = d0 > 0 (m; the inter-body contacts'
    ``PhysicsConfig.contacts.stiffening_depth``).

    Args: x (3,) m, R (3, 3), seg (2, 3) segment end points in the body frame (m), r m, k N/m.
    Returns ``(E, gradient (12,), Gauss-Newton Hessian phi''(d) u u^T (12, 12), depth)``, zero
    when the capsules are apart.
    """
    a0, a1 = xa + Ra @ seg_a[0], xa + Ra @ seg_a[1]
    b0, b1 = xb + Rb @ seg_b[0], xb + Rb @ seg_b[1]
    s, t, dist = closest_points_on_segments(a0, a1, b0, b1)
    depth = ra + rb - float(dist)
    if depth <= 0:
        return 0.0, np.zeros(12), np.zeros((12, 12)), depth
    ca, cb = a0 + s * (a1 - a0), b0 + t * (b1 - b0)
    n = (ca - cb) / max(float(dist), 1e-12)
    u = np.concatenate([-n, -np.cross(ca - xa, n), n, np.cross(cb - xb, n)])
    cubic = depth / stiffening if stiffening > 0 else 0.0
    energy = k * depth**2 * (0.5 + cubic / 3.0)
    return energy, k * depth * (1.0 + cubic) * u, k * (1.0 + 2.0 * cubic) * np.outer(u, u), depth
