"""The damping study of paper Fig. 4: recovery after a blocking collision.

One character stands still (its animation: the rest pose at the origin, facing +y). It
starts ``push`` metres behind its animation, held back by a static obstacle (a sampled
plane in front of its body) while the controller pulls it forward; at ``release_time`` the
obstacle disappears and the character returns to its animation. The global position
(pelvis y) over time shows how the damping d of Eq. 4 shapes the recovery: d = 0 overshoots
and oscillates, the paper's d = 0.006 returns smoothly, a large d lags behind.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["damping_study", "recovery_metrics"]


def recovery_metrics(
    time: np.ndarray, position: np.ndarray, target: float, release_time: float, tolerance: float = 0.02
) -> dict:
    """Return time, overshoot and oscillation count of a recovery curve.

    Args:
        time: (S,) s; position: (S,) m (pelvis y); target: m; release_time: s.
        tolerance: m, the band around the target that counts as "returned".

    Returns:
        dict: ``return_time`` s after the release at which the curve enters the band and
        stays in it (inf if never), ``overshoot`` m (largest excursion past the target after
        the release, >= 0), ``crossings`` (sign changes of position - target after release),
        ``error_at_1s`` m (|position - target| one second after the release).
    """
    time = np.asarray(time, np.float64)
    err = np.asarray(position, np.float64) - float(target)
    after = time >= release_time
    e = err[after]
    t = time[after] - release_time
    outside = np.nonzero(np.abs(e) > tolerance)[0]
    if len(outside) == 0:
        ret = 0.0
    elif outside[-1] == len(e) - 1:
        ret = float("inf")
    else:
        ret = float(t[outside[-1] + 1])
    signs = np.sign(e[np.abs(e) > 1e-3])
    crossings = int(np.count_nonzero(np.diff(signs))) if len(signs) > 1 else 0
    at1 = float(np.abs(np.interp(1.0, t, e))) if len(t) else float("nan")
    return {
        "return_time": ret,
        "overshoot": float(max(e.max(initial=0.0), 0.0)),
        "crossings": crossings,
        "error_at_1s": at1,
    }


def _default_body():
    from crowdstudy.body import load_body
    from crowdstudy.body.shapes import sample_bodies

    return load_body(sample_bodies(2, 0)[1])


def damping_study(
    dampings=(0.0, 0.006, 0.06),
    *,
    release_time: float = 3.5,
    duration: float = 6.0,
    push: float = 0.25,
    body=None,
    config=None,
    device: str | None = None,
) -> dict:
    """Recovery curves for several damping values d (Fig. 4).

    Args:
        dampings: values of d (J s^2) to simulate.
        release_time: s, when the obstacle is removed.
        duration: s simulated.
        push: m, how far behind its animation the character is held.
        body: a body model (rest_joints, capsules); default a sampled male body.
        config: base :class:`PhysicsConfig` (its ``control.damping`` is replaced); default
            :meth:`PhysicsConfig.paper_controller`, the paper's joint-space controller.
        device: Warp device.

    Returns:
        dict with ``time`` (S,) s, ``target`` (pelvis y of the animation, m),
        ``position`` {d: (S,) pelvis y, m}, ``metrics`` {d: :func:`recovery_metrics`},
        ``release_time``, ``push``.
    """
    from crowdstudy.physics.config import PhysicsConfig
    from crowdstudy.physics.corrector import CrowdCorrector

    if not dampings:
        raise InvalidInputError("dampings: expected at least one value")
    if not 0 < release_time < duration:
        raise InvalidInputError(f"release_time: expected 0 < release_time < duration, got {release_time!r}")
    body = body or _default_body()
    base = config or PhysicsConfig.paper_controller()
    rest = np.asarray(body.rest_joints)
    caps = body.capsules
    pelvis_h = float(
        getattr(body, "pelvis_height", 0.0) or -(np.minimum(caps.start[:, 2], caps.end[:, 2]) - caps.radius).min()
    )
    rot = np.zeros((1, rest.shape[0], 3))
    root = np.array([[0.0, 0.0, pelvis_h]])
    # obstacle: a sampled plane just in front of the torso of the held-back character
    front = float(np.max(np.maximum(caps.start[:, 1], caps.end[:, 1]) + caps.radius)) - push
    xs = np.arange(-0.35, 0.35 + 1e-9, 0.03)
    zs = np.arange(0.3, pelvis_h + 0.9, 0.03)
    gx, gz = np.meshgrid(xs, zs)
    points = np.stack([gx.ravel(), np.full(gx.size, front + 0.01), gz.ravel()], 1)
    out: dict = {"release_time": release_time, "push": push, "target": 0.0, "position": {}, "metrics": {}}
    steps_per_frame = 2
    fps = 1.0 / (base.solver.dt * steps_per_frame)
    n_frames = int(round(duration * fps))
    for d in dampings:
        cfg = base.with_values({"control.damping": float(d)})
        corr = CrowdCorrector([body], config=cfg, device=device, fps=fps, static_points=points)
        corr.reset(rot, root)
        # start held back: place the bodies `push` behind the animation
        st = corr.state.x.numpy()
        st[:, 1] -= push
        corr.state.x.assign(corr.solver.wp.array(st, dtype=corr.solver.wp.vec3, device=corr.model.device))
        ys = np.empty(n_frames)
        for f in range(n_frames):
            corr.pipeline.static_enabled = (f / fps) < release_time
            _, r = corr.step(rot[0][None], root)
            ys[f] = r[0, 1]
        out["position"][float(d)] = ys
    out["time"] = (np.arange(n_frames) + 1) / fps
    for d, ys in out["position"].items():
        out["metrics"][d] = recovery_metrics(out["time"], ys, 0.0, release_time)
    return out
