"""How crowded a crowd is: the local density the physics sizes its contact proxies by.

A character's local density is k / (pi r_k^2), r_k the horizontal distance from its root
to its k-th nearest neighbour's (characters per m^2), taken over sampled frames and its
median kept; a crowd's density is the median of its characters'. Measured on the
animation itself, so the study's cells, a stadium floor and a user's own crowd are
treated alike, whatever their meta says. A periodic scene (the corridor) measures across
its seam along x. The measure runs a little below a design's nominal density on a small
floor: the characters at its edges have fewer neighbours.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config import PhysicsConfig

__all__ = ["local_density", "crowd_density", "crowd_config"]

NEIGHBOURS = 4  # k: the ring of nearest neighbours a character's room is judged by
SAMPLES = 60  # frames sampled at most (evenly) per animation


def local_density(root_xy: np.ndarray, *, k: int = NEIGHBOURS, period: float | None = None) -> np.ndarray:
    """(N,) characters per m^2 around each character: the median over frames of
    k / (pi r_k^2).

    Args:
        root_xy: (T, N, 2) m, the characters' root positions on the floor (x, y).
        k: neighbours counted (fewer when the crowd has fewer than k + 1 characters).
        period: m, the scene's period along x (None: not periodic).

    A crowd of one has no neighbour: its density is 0.
    """
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  (compiled, not in the stubs)

    xy = np.asarray(root_xy, np.float64)
    if xy.ndim != 3 or xy.shape[2] != 2 or xy.shape[0] < 1:
        raise InvalidInputError(f"root_xy: expected (T, N, 2) floor positions, got shape {xy.shape}")
    if not np.all(np.isfinite(xy)):
        raise InvalidInputError("root_xy: expected finite positions")
    if int(k) < 1:
        raise InvalidInputError(f"k: expected at least 1 neighbour, got {k!r}")
    if period is not None and not period > 0:
        raise InvalidInputError(f"period: expected a positive length or None, got {period!r}")
    n = xy.shape[1]
    k = min(int(k), n - 1)
    if k < 1:
        return np.zeros(n)
    density = np.empty((xy.shape[0], n))
    for f, pts in enumerate(xy):
        if period is not None:
            # a torus along x only: y spread over a box far larger than the crowd
            span = float(np.ptp(pts[:, 1])) + 1.0
            x = np.mod(pts[:, 0], period)
            x[x >= period] = 0.0  # mod of a tiny negative x rounds up to the period
            pts = np.column_stack([x, pts[:, 1] - pts[:, 1].min()])
            tree = cKDTree(pts, boxsize=[period, 4.0 * span])
        else:
            tree = cKDTree(pts)
        dist, _ = tree.query(pts, k + 1)
        r_k = np.maximum(dist[:, -1], 1e-3)  # two roots in one place: 1 mm
        density[f] = k / (np.pi * r_k**2)
    return np.median(density, axis=0)


def crowd_density(anim, *, k: int = NEIGHBOURS, samples: int = SAMPLES) -> float:
    """Characters per m^2: the median of the characters' :func:`local_density` over
    ``samples`` frames of ``anim`` (a :class:`~crowdstudy.scene.CrowdAnimation`)."""
    if int(samples) < 1:
        raise InvalidInputError(f"samples: expected at least 1 frame, got {samples!r}")
    root = np.asarray(anim.root_translation, np.float64)
    frames = np.unique(np.linspace(0, root.shape[0] - 1, min(int(samples), root.shape[0])).round().astype(int))
    return float(np.median(local_density(root[frames, :, :2], k=k, period=anim.periodic_length)))


def crowd_config(anim, config: PhysicsConfig | None = None) -> tuple[PhysicsConfig, float, float | None]:
    """The configuration ``anim``'s crowd is corrected with, as
    :func:`~crowdstudy.physics.corrector.correct` uses it: ``(config.for_density(density),
    density, profile weight)``, the density its :func:`crowd_density` (characters per m^2)
    and the weight None when no field of ``config`` follows the density profile
    (``config.follows_profile``; ``config`` None: the defaults)."""
    config = PhysicsConfig() if config is None else config
    if not isinstance(config, PhysicsConfig):
        raise InvalidInputError(f"config: expected a PhysicsConfig, got {type(config).__name__}")
    density = crowd_density(anim)
    weight = config.profile_weight(density) if config.follows_profile else None
    return config.for_density(density), density, weight
