"""Cameras: the study's viewpoints V1..V4 framing the whole crowd area, and a free camera.

A viewpoint (``design.viewpoints``) gives the azimuth (deg, direction from the area centre
to the camera, from +x towards +y), the elevation above the horizon (deg) and the vertical
field of view (deg). The distance is the smallest one at which the whole crowd box
(the floor area extruded to body height) fits the image with a small margin.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["Camera", "look_at", "perspective", "frame_viewpoint", "free_camera", "DEFAULT_BODY_HEIGHT"]

#: Height of the box framed by the viewpoint cameras (m): tall adults and raised arms.
DEFAULT_BODY_HEIGHT = 1.95


def look_at(
    eye: np.ndarray | tuple[float, ...], target: np.ndarray | tuple[float, ...], up=(0.0, 0.0, 1.0)
) -> np.ndarray:
    """(4, 4) world-to-camera matrix (OpenGL convention: the camera looks down -z)."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-8:  # looking straight along `up`: pick another up vector
        s = np.cross(f, (0.0, 1.0, 0.0))
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """(4, 4) OpenGL projection matrix; ``fov_y_deg`` vertical field of view in degrees."""
    f = 1.0 / math.tan(math.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = f / aspect, f
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


@dataclasses.dataclass(frozen=True)
class Camera:
    """A pinhole camera. ``eye``, ``target``: (3,) metres; ``fov``: vertical, degrees."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    fov: float = 45.0
    near: float = 0.1
    far: float = 100.0
    name: str = "free"

    def view(self) -> np.ndarray:
        return look_at(self.eye, self.target)

    def projection(self, aspect: float) -> np.ndarray:
        return perspective(self.fov, aspect, self.near, self.far)

    def view_projection(self, aspect: float) -> np.ndarray:
        """(4, 4) world-to-clip matrix."""
        return self.projection(aspect) @ self.view()

    def project(self, points: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates of world points.

        Args:
            points: (..., 3) metres.
        Returns:
            ``(pixels (..., 2) float [x right, y down], in_front (...,) bool)``.
        """
        p = np.asarray(points, dtype=np.float64)
        clip = np.concatenate([p, np.ones(p.shape[:-1] + (1,))], axis=-1) @ self.view_projection(width / height).T
        w = clip[..., 3]
        ndc = clip[..., :2] / np.where(np.abs(w) < 1e-12, 1e-12, w)[..., None]
        px = np.stack([(ndc[..., 0] + 1) * 0.5 * width, (1 - ndc[..., 1]) * 0.5 * height], axis=-1)
        return px, w > 0


def _box_corners(extent: tuple[float, float], height: float) -> np.ndarray:
    w, d = extent
    return np.array([[sx * w / 2, sy * d / 2, z] for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, height)])


def frame_viewpoint(
    viewpoint, extent: tuple[float, float], aspect: float, *, height: float = DEFAULT_BODY_HEIGHT, margin: float = 0.94
) -> Camera:
    """The camera of a design viewpoint framing the box ``extent`` x [0, ``height``].

    Args:
        viewpoint: a :class:`crowdstudy.design.Viewpoint` (azimuth, elevation, fov in degrees).
        extent: (width along x, depth along y) of the area centred on the origin, metres.
        aspect: image width / height.
        margin: the box fills at most this fraction of the image half-extent (NDC).
    """
    for name in ("azimuth", "elevation", "fov"):
        if not hasattr(viewpoint, name):
            raise InvalidInputError(f"viewpoint: expected a design Viewpoint with {name!r}, got {viewpoint!r}")
    az, el = math.radians(viewpoint.azimuth), math.radians(viewpoint.elevation)
    direction = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    corners = _box_corners(extent, height)
    target = np.array([0.0, 0.0, height * 0.4])
    proj = perspective(viewpoint.fov, aspect, 0.05, 1000.0)

    def fits(dist: float, tgt: np.ndarray) -> tuple[bool, np.ndarray]:
        eye = tgt + dist * direction
        clip = np.c_[corners, np.ones(len(corners))] @ (proj @ look_at(eye, tgt)).T
        if np.any(clip[:, 3] <= 0.05):
            return False, np.zeros(4)
        ndc = clip[:, :2] / clip[:, 3:4]
        lo, hi = ndc.min(axis=0), ndc.max(axis=0)
        return bool(np.all(lo >= -margin) and np.all(hi <= margin)), np.r_[lo, hi]

    def solve(tgt: np.ndarray) -> float:
        lo, hi = 0.1, 1000.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if fits(mid, tgt)[0] else (mid, hi)
        return hi

    dist = solve(target)
    # Re-centre the box in the image once (move the target along the camera's up/right), then refit.
    eye = target + dist * direction
    view = look_at(eye, target)
    _, box = fits(dist, target)
    centre_ndc = 0.5 * (box[:2] + box[2:])
    depth = dist
    tan_y = math.tan(math.radians(viewpoint.fov) / 2)
    shift = view[0, :3] * centre_ndc[0] * depth * tan_y * aspect + view[1, :3] * centre_ndc[1] * depth * tan_y
    target = target + shift
    dist = solve(target)
    eye = target + dist * direction
    return Camera(
        eye=(float(eye[0]), float(eye[1]), float(eye[2])),
        target=(float(target[0]), float(target[1]), float(target[2])),
        fov=float(viewpoint.fov),
        near=max(0.05, dist * 0.02),
        far=dist + 60.0,
        name=getattr(viewpoint, "id", "viewpoint"),
    )


def free_camera(eye, target, fov: float = 45.0) -> Camera:
    """A camera at ``eye`` (3,) looking at ``target`` (3,), metres; ``fov`` vertical degrees."""
    e, t = (np.asarray(v, dtype=np.float64).reshape(-1) for v in (eye, target))
    if e.shape != (3,) or t.shape != (3,) or not (np.all(np.isfinite(e)) and np.all(np.isfinite(t))):
        raise InvalidInputError(f"free camera: eye and target must be 3 finite numbers, got {eye!r}, {target!r}")
    if np.linalg.norm(e - t) < 1e-6:
        raise InvalidInputError("free camera: eye and target coincide")
    if not 1.0 <= fov <= 170.0:
        raise InvalidInputError(f"free camera: fov must be in [1, 170] degrees, got {fov!r}")
    dist = float(np.linalg.norm(e - t))
    return Camera(
        eye=(float(e[0]), float(e[1]), float(e[2])),
        target=(float(t[0]), float(t[1]), float(t[2])),
        fov=float(fov),
        near=max(0.02, dist * 0.01),
        far=dist + 80.0,
        name="free",
    )
