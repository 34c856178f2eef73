"""Paper Fig. 2: body meshes and their capsule proxies (one capsule per bone) in three poses.

Top row: the open body model (a female and a male body from ``sample_bodies``-like
records); bottom row: the 24 capsules fitted to each (``Body.capsules``), posed with the
same joint rotations (rest T-pose, a walking step, arms raised as in a concert). The title
of each body gives the volume IoU of its capsule union against its mesh
(``crowdstudy.body.capsules.capsule_mesh_iou``); the JSON sidecar lists the IoU of a
sample of bodies (12 in the full configuration, 4 with ``--quick``).

    .venv/bin/python paper_figs/fig2_capsules.py            # paper_figs/out/fig2_capsules.png
    .venv/bin/python paper_figs/fig2_capsules.py --quick    # smaller sample, coarser voxels
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from figstyle import apply_style, figure_args, out_path, save_figure  # noqa: E402

SEED = 2


def poses() -> dict[str, np.ndarray]:
    """Named (24, 3) axis-angle poses (joint 0 global), hand-set for the figure."""
    from crowdstudy.body.skeleton import JOINT_INDEX as J

    rest = np.zeros((24, 3))
    walk = np.zeros((24, 3))
    walk[J["left_hip"]] = (0.45, 0, 0)  # left leg forward
    walk[J["right_hip"]] = (-0.3, 0, 0)  # right leg back ...
    walk[J["right_knee"]] = (-0.55, 0, 0)  # ... knee bent
    walk[J["left_knee"]] = (-0.1, 0, 0)
    walk[J["left_shoulder"]] = (0.0, -1.25, -0.25)  # arms down and swinging
    walk[J["right_shoulder"]] = (0.0, 1.25, -0.25)
    walk[J["left_elbow"]] = (0, 0, 0.3)
    walk[J["right_elbow"]] = (0, 0, -0.2)
    walk[J["spine2"]] = (0, 0, 0.08)
    cheer = np.zeros((24, 3))
    cheer[J["left_shoulder"]] = (0, 0.95, 0)  # arms up
    cheer[J["right_shoulder"]] = (0, -1.2, 0.2)
    cheer[J["left_elbow"]] = (0, 0.5, 0.4)
    cheer[J["right_elbow"]] = (0, -0.3, -0.6)
    cheer[J["left_hip"]] = (0.25, 0, -0.08)
    cheer[J["left_knee"]] = (-0.45, 0, 0)
    cheer[J["right_hip"]] = (0.1, 0, 0.05)
    cheer[J["right_knee"]] = (-0.2, 0, 0)
    cheer[J["spine1"]] = (0, 0.1, 0.15)
    cheer[J["neck"]] = (-0.25, 0, 0)
    return {"rest pose": rest, "walking": walk, "concert": cheer}


def _capsule_mesh(a, b, r):
    import trimesh

    axis = b - a
    length = float(np.linalg.norm(axis))
    mesh = trimesh.creation.capsule(height=max(length, 1e-6), radius=r, count=[10, 10])
    z = np.array([0.0, 0.0, 1.0])
    d = axis / length if length > 1e-9 else z
    v = np.cross(z, d)
    s, c = np.linalg.norm(v), float(z @ d)
    if s < 1e-9:
        rot = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        rot = np.eye(3) + k + k @ k * ((1 - c) / s**2)
    return mesh.vertices @ rot.T + 0.5 * (a + b), np.asarray(mesh.faces)


def _draw(ax, parts, azimuth_deg: float = -25.0):
    """Painter's-algorithm drawing of shaded triangle soups: parts = [(verts, faces, rgb)]."""
    from matplotlib.collections import PolyCollection

    az = np.radians(azimuth_deg)
    to_viewer = np.array([np.sin(az), np.cos(az), 0.0])  # the camera stands in front (+y)
    right = np.cross(-to_viewer, [0.0, 0.0, 1.0])  # screen right (the body's left)
    light = np.array([0.3, 0.8, 0.6])
    light /= np.linalg.norm(light)
    polys, colours, depth = [], [], []
    for verts, faces, rgb in parts:
        tri = verts[faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
        facing = n @ to_viewer > 0.0
        tri, n = tri[facing], n[facing]
        shade = 0.35 + 0.65 * np.clip(n @ light, 0.0, 1.0)
        polys.append(np.stack([tri @ right, tri[..., 2]], axis=-1))
        colours.append(np.clip(np.asarray(rgb)[None, :] * shade[:, None], 0, 1))
        depth.append((tri @ to_viewer).mean(axis=1))
    polys, colours, depth = np.concatenate(polys), np.concatenate(colours), np.concatenate(depth)
    order = np.argsort(depth)  # far triangles first
    ax.add_collection(PolyCollection(polys[order], facecolors=colours[order], edgecolors="none"))
    pts = polys.reshape(-1, 2)
    ax.set_xlim(pts[:, 0].min() - 0.05, pts[:, 0].max() + 0.05)
    ax.set_ylim(-0.02, pts[:, 1].max() + 0.05)
    ax.set_aspect("equal")
    ax.axis("off")


def main(argv=None) -> int:
    args = figure_args(__doc__.splitlines()[0], argv)
    apply_style()
    import matplotlib.pyplot as plt

    import crowdstudy.body as cb
    from crowdstudy.body.capsules import capsule_mesh_iou, posed_capsules

    resolution = 0.015 if args.quick else 0.008
    records = [
        {"model": "open", "sex": "female", "height": 1.63, "shape": [0.4, 0.0]},
        {"model": "open", "sex": "male", "height": 1.76, "shape": [0.8, 0.5]},
    ]
    bodies = [cb.load_body(r) for r in records]
    ious = [capsule_mesh_iou(b, resolution=resolution)["iou"] for b in bodies]
    sample = cb.sample_bodies(4 if args.quick else 12, seed=SEED)
    sample_iou = [capsule_mesh_iou(cb.load_body(r), resolution=resolution)["iou"] for r in sample]

    pose_set = poses()
    palette = plt.get_cmap("tab20")
    fig, axes = plt.subplots(2, len(pose_set), figsize=(11, 7.2))
    for col, (name, pose) in enumerate(pose_set.items()):
        mesh_parts, capsule_parts = [], []
        for k, body in enumerate(bodies):
            shift = np.array([0.95 * k - 0.475, 0.0, body.pelvis_height])
            verts, _ = body.pose(pose, shift)
            skin = np.array([0.93, 0.78, 0.66]) if body.record["sex"] == "female" else np.array([0.80, 0.66, 0.55])
            mesh_parts.append((verts, np.asarray(body.faces), skin))
            start, end = posed_capsules(body, pose, shift)
            for j in range(24):
                cv, cf = _capsule_mesh(start[j], end[j], float(body.capsules.radius[j]))
                capsule_parts.append((cv, cf, np.array(palette(j % 20)[:3])))
        _draw(axes[0, col], mesh_parts)
        _draw(axes[1, col], capsule_parts)
        axes[0, col].set_title(name)
    for row, label in enumerate(("body meshes", "capsule proxies (24 per body)")):
        axes[row, 0].text(
            -0.08,
            0.5,
            label,
            transform=axes[row, 0].transAxes,
            fontsize=10,
            weight="bold",
            rotation=90,
            va="center",
            ha="right",
        )
    fig.suptitle(
        f"Capsule fit, volume IoU: female {ious[0]:.2f}, male {ious[1]:.2f}; "
        f"{len(sample_iou)} sampled bodies {min(sample_iou):.2f}-{max(sample_iou):.2f} "
        f"(mean {np.mean(sample_iou):.2f})",
        fontsize=10,
    )
    path = out_path("fig2_capsules", args)
    save_figure(
        fig,
        path,
        seed=SEED,
        records=records,
        iou=ious,
        sample_records=sample,
        sample_iou=sample_iou,
        voxel_resolution=resolution,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
