"""The output stage of :func:`~crowdstudy.physics.corrector.correct`, a few characters at a time.

Every step of the output stage (:mod:`crowdstudy.physics.finish`: the loop's closing, the
low-pass of the deviation, the planted feet; :mod:`crowdstudy.physics.speed_limit`: the
re-timed fast joints) works on each character alone. The one quantity shared across the
crowd is the speed limit, the input crowd's fastest joint plus a margin, which a first pass
finds. :func:`finish_crowd` then runs the steps on blocks of ``OUTPUT_CHUNK`` characters,
on :func:`~crowdstudy.warp_runtime.host_threads` threads, and writes each block into the
output. Each block's result is the same whichever thread computes it and however many there
are, so the same input still gives the same bytes.

Working on blocks keeps the temporaries small. The whole crowd's forward kinematics of a 20 s
clip of 1,000 characters would need 2.2 GB of global rotations for each of the output and
the input, and fresh memory is expensive on a virtual machine (each page is zeroed when it
is first touched).
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor, as_completed

import numpy as np

from crowdstudy.body.skeleton import PARENTS, forward_kinematics
from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.physics.config_sections import OutputConfig
from crowdstudy.physics.finish import close_loop, lock_planted_feet, smooth_deviation
from crowdstudy.physics.speed_limit import SpeedLimitReport, fastest_reference_joint, limit_joint_speed
from crowdstudy.warp_runtime import host_threads

__all__ = ["OUTPUT_CHUNK", "crowd_speed_limit", "finish_crowd"]

#: characters per block of the output stage
OUTPUT_CHUNK = 16


def _blocks(n: int, chunk: int) -> list[tuple[int, int]]:
    return [(c0, min(n, c0 + chunk)) for c0 in range(0, n, chunk)]


def _map(fn, items, threads: int, bar=None) -> list:
    """``[fn(item) for item in items]`` on up to ``threads`` threads, in order; ``bar`` (a
    tqdm bar or None) advances as each item finishes."""

    def tick(result):
        if bar is not None:
            bar.update(1)
        return result

    if threads <= 1 or len(items) < 2:
        return [tick(fn(item)) for item in items]
    with ThreadPoolExecutor(min(threads, len(items))) as pool:
        futures = [pool.submit(fn, item) for item in items]
        for _ in as_completed(futures):
            tick(None)
        return [future.result() for future in futures]


def crowd_speed_limit(
    ref_rot: np.ndarray,
    ref_root: np.ndarray,
    rest_joints: np.ndarray,
    fps: float,
    margin: float,
    *,
    periodic_length: float | None = None,
    chunk: int = OUTPUT_CHUNK,
    threads: int = 1,
) -> float:
    """The limit :func:`~crowdstudy.physics.speed_limit.limit_joint_speed` takes by default,
    found block by block: the input crowd's fastest joint over its own steps (the seam of a
    loop not counted), m/s, plus ``margin`` m/s."""

    def fastest(block):
        c0, c1 = block
        _, pos = forward_kinematics(rest_joints[None, c0:c1], ref_rot[:, c0:c1], ref_root[:, c0:c1], parents=PARENTS)
        return fastest_reference_joint(pos, fps, periodic_length)

    return max(_map(fastest, _blocks(ref_rot.shape[1], chunk), threads)) + float(margin)


def _merge(reports: list[tuple[int, SpeedLimitReport]], limit: float) -> SpeedLimitReport:
    return SpeedLimitReport(
        limit_m_s=float(limit),
        fast_samples=sum(r.fast_samples for _, r in reports),
        characters=tuple(c0 + c for c0, r in reports for c in r.characters),
        rounds=max(r.rounds for _, r in reports),
        max_speed_before_m_s=max(r.max_speed_before_m_s for _, r in reports),
        max_speed_after_m_s=max(r.max_speed_after_m_s for _, r in reports),
        unresolved=sum(r.unresolved for _, r in reports),
    )


@dataclasses.dataclass(frozen=True)
class _BlockStage:
    """The output stage of one block of characters ``(c0, c1)``, as :func:`finish_crowd`
    calls it on each block (any thread): reads the simulated and input poses, writes the
    block's rows of ``out_rot`` and ``out_root``, returns ``(c0, speed report or None)``."""

    sim_rot: np.ndarray  # (warmup + T + blend, N, J, 3) rad
    sim_root: np.ndarray  # (warmup + T + blend, N, 3) m
    ref_rot: np.ndarray  # (T, N, J, 3) rad, float64
    ref_root: np.ndarray  # (T, N, 3) m, float64
    rest: np.ndarray  # (N, J, 3) m, float64
    fps: float
    cfg: OutputConfig
    hold: float  # cfg.hold, resolved for the dense end of the profile
    limit: float | None  # m/s, the joint speed limit (crowd_speed_limit), None when off
    n_frames: int
    warmup: int
    blend: int
    looped: bool
    periodic_length: float | None
    out_rot: np.ndarray  # (T, N, J, 3), written
    out_root: np.ndarray  # (T, N, 3), written

    def __call__(self, bounds: tuple[int, int]) -> tuple[int, SpeedLimitReport | None]:
        cfg = self.cfg
        c0, c1 = bounds
        rot = np.asarray(self.sim_rot[:, c0:c1], np.float64)
        root = np.asarray(self.sim_root[:, c0:c1], np.float64)
        r_rot, r_root, r_rest = self.ref_rot[:, c0:c1], self.ref_root[:, c0:c1], self.rest[c0:c1]
        if self.looped:
            rot, root = close_loop(rot, root, self.n_frames, self.warmup, self.blend)
        rot, root = smooth_deviation(
            rot,
            root,
            r_rot,
            r_root,
            cfg.smoothing * self.fps,
            periodic=self.looped,
            root_sigma_frames=cfg.smoothing_root * self.fps,
            hold=self.hold,
        )
        # the input's kinematics, once for the foot lock and the speed limit
        r_fk = (
            forward_kinematics(r_rest[None], r_rot, r_root, parents=PARENTS)
            if cfg.foot_lock or self.limit is not None
            else None
        )
        if cfg.foot_lock:
            rot = lock_planted_feet(
                rot,
                root,
                r_rot,
                r_root,
                r_rest,
                self.fps,
                planted_speed=cfg.foot_lock_speed,
                periodic=self.looped,
                ref_kinematics=r_fk,
            )
        report = None
        if self.limit is not None:
            rot, report = limit_joint_speed(
                rot,
                root,
                r_rot,
                r_root,
                r_rest,
                self.fps,
                limit=self.limit,
                periodic=self.looped,
                periodic_length=self.periodic_length,
                ref_kinematics=r_fk,
            )
        self.out_rot[:, c0:c1] = rot
        self.out_root[:, c0:c1] = root
        return c0, report


def finish_crowd(
    sim_rot: np.ndarray,
    sim_root: np.ndarray,
    ref_rot: np.ndarray,
    ref_root: np.ndarray,
    rest_joints: np.ndarray,
    fps: float,
    config: PhysicsConfig,
    *,
    warmup: int = 0,
    blend: int = 0,
    looped: bool = False,
    periodic_length: float | None = None,
    chunk: int = OUTPUT_CHUNK,
    threads: int | None = None,
    progress: bool = False,
) -> tuple[np.ndarray, np.ndarray, SpeedLimitReport | None]:
    """The simulated poses -> the "Ours" animation.

    Args:
        sim_rot: (warmup + T + blend, N, J, 3) rad, the simulated joint rotations (any float
            dtype); sim_root: (warmup + T + blend, N, 3) m.
        ref_rot: (T, N, J, 3) rad, the input; ref_root: (T, N, 3) m.
        rest_joints: (N, J, 3) m.
        fps: Hz.
        config: the physics configuration: its ``output`` section (``smoothing``,
            ``smoothing_root``, ``hold``, ``foot_lock``, ``foot_lock_speed``, ``speed_limit``,
            ``speed_limit_margin``); a ``hold`` that follows the density profile (None) is
            taken at its dense end (:meth:`~crowdstudy.physics.config.PhysicsConfig.for_dense_crowd`;
            :func:`~crowdstudy.physics.corrector.correct` passes a configuration resolved
            for its crowd).
        warmup, blend, looped: the loop's frames simulated before and after the clip
            (:func:`~crowdstudy.physics.finish.close_loop`); ``looped``: the clip is periodic.
        periodic_length: m, the scene's period along x, or None.
        chunk: characters per block (the result does not depend on it).
        threads: host threads (None: :func:`~crowdstudy.warp_runtime.host_threads`).
        progress: a tqdm bar over the blocks on stderr.

    Returns:
        ``(rot (T, N, J, 3), root (T, N, 3), speed report or None)``, float64. The report is
        for the whole crowd, as one call of
        :func:`~crowdstudy.physics.speed_limit.limit_joint_speed` would give it.
    """
    ref_rot = np.asarray(ref_rot, np.float64)
    ref_root = np.asarray(ref_root, np.float64)
    rest = np.asarray(rest_joints, np.float64)
    n_frames, n_chars = ref_rot.shape[:2]
    total = warmup + n_frames + blend
    if sim_rot.shape != (total,) + ref_rot.shape[1:] or sim_root.shape != (total, n_chars, 3):
        raise InvalidInputError(
            f"sim_rot, sim_root: expected {(total,) + ref_rot.shape[1:]} and "
            f"{(total, n_chars, 3)} (warmup + T + blend frames), got {sim_rot.shape} and "
            f"{sim_root.shape}"
        )
    if rest.shape != (n_chars,) + ref_rot.shape[2:]:
        raise InvalidInputError(f"rest_joints: expected {(n_chars,) + ref_rot.shape[2:]}, got {rest.shape}")
    if chunk < 1:
        raise InvalidInputError(f"chunk: expected a positive number of characters, got {chunk!r}")
    threads = host_threads() if threads is None else max(1, int(threads))
    out_cfg = config.for_dense_crowd().output
    if out_cfg.hold is None:  # for_density sets every field the profile sets
        raise RuntimeError("output.hold: not resolved for a density")
    limit = None
    if out_cfg.speed_limit:
        limit = crowd_speed_limit(
            ref_rot,
            ref_root,
            rest,
            fps,
            out_cfg.speed_limit_margin,
            periodic_length=periodic_length,
            chunk=chunk,
            threads=threads,
        )
    out_rot = np.empty(ref_rot.shape)
    out_root = np.empty(ref_root.shape)
    block = _BlockStage(
        sim_rot,
        sim_root,
        ref_rot,
        ref_root,
        rest,
        fps,
        out_cfg,
        out_cfg.hold,
        limit,
        n_frames,
        warmup,
        blend,
        looped,
        periodic_length,
        out_rot,
        out_root,
    )

    blocks = _blocks(n_chars, chunk)
    bar = None
    if progress:
        from crowdstudy.progress import progress_bar

        bar = progress_bar(total=len(blocks), desc="output stage", unit="block", leave=False)
    try:
        done = _map(block, blocks, threads, bar)
    finally:
        if bar is not None:
            bar.close()
    report = _merge(done, limit) if limit is not None else None
    return out_rot, out_root, report
