"""Beats of a dance take from its vertical bounce, time-warping to a tempo, and bounce phase.

A dancer's pelvis goes down and up with the music: the bounce. :func:`beat_curve` turns a
take's pelvis height into a *bounce index* per frame, increasing at a constant rate, whose
integer values fall on the bounce's low points (the "down" on the beat):

1. the bounce period is the strongest autocorrelation peak (refined by a parabola through
   it) of the band-passed (0.6 to 4 Hz) pelvis height between 0.28 s and 1.5 s, unless the
   clip's metadata sets it by hand (``bounce_period``: takes performed without music, or
   whose bounce is weaker than their arm rhythm);
2. the phase is that of the height's Fourier coefficient at that period over the whole
   take (``pi`` at the low points); :func:`~crowdstudy.motion.mocap_library.dance_loop` then shifts the beat grid so the
   take's prominent low points (:func:`low_points`) fall on beats on average
   (:func:`beat_offset`), which also holds when the dancer bounces on every beat but the
   period found spans two.

A constant rate keeps the warp a plain change of speed (no local accelerations that the
take did not have). ``beats_per_bounce`` (:func:`beats_per_bounce`: 0.5, 1, 2 or 4)
converts bounces to beats with the smallest change of tempo.

:func:`warp_to_tempo` resamples a take on a beat grid: output frame ``u`` shows the take
at the time whose beat index is ``u * bpm / 60 / fps``, so every low point of the bounce
lands on a beat. :func:`bounce_phase` measures it on a whole crowd: the phase of each
dancer's pelvis height at the beat frequency, and their circular spread.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip

__all__ = [
    "BeatCurve",
    "beat_curve",
    "beats_per_bounce",
    "warp_to_tempo",
    "low_points",
    "beat_offset",
    "bounce_phase",
    "circular_spread",
]

_BAND = (0.6, 4.0)  # Hz, the bounce band
_PERIOD_RANGE = (0.28, 1.5)  # s, bounce periods searched
_RATE_LIMITS = (0.7, 1.4)  # phase rate, relative to the median


@dataclasses.dataclass(frozen=True)
class BeatCurve:
    """Bounce index per frame of a take (``bounces[i]`` at frame ``i``; integers at the low
    points), its mean period (s) and how it was found ("autocorrelation" or "metadata")."""

    bounces: np.ndarray
    period: float
    method: str
    strength: float


def _bandpass(x: np.ndarray, fps: float, lo: float, hi: float) -> np.ndarray:
    from scipy.signal import butter, sosfiltfilt

    nyq = 0.5 * fps
    sos = butter(2, [lo / nyq, min(hi / nyq, 0.95)], btype="band", output="sos")
    pad = min(len(x) - 1, int(3 * fps))
    return sosfiltfilt(sos, x - x.mean(), padlen=pad)


def beat_curve(height: np.ndarray, fps: float, *, period: float | None = None) -> BeatCurve:
    """The bounce index per frame of a pelvis-height signal ``height`` (T,) metres at ``fps``.

    ``period`` (s) sets the bounce period by hand (clip metadata); otherwise it is the
    autocorrelation peak (see the module docstring). ``strength`` is the normalised
    autocorrelation at the period (0..1; below about 0.3 the bounce is weak).
    """
    z = np.asarray(height, dtype=np.float64)
    if z.ndim != 1 or len(z) < int(2 * fps):
        raise InvalidInputError(f"beat_curve: expected a 1-D height signal of at least 2 s, got shape {z.shape}")
    band = _bandpass(z, fps, *_BAND)
    ac = np.correlate(band, band, "full")[len(band) - 1 :]
    ac = ac / max(ac[0], 1e-18)
    lags = np.arange(len(ac)) / fps
    ok = (lags >= _PERIOD_RANGE[0]) & (lags <= min(_PERIOD_RANGE[1], 0.5 * lags[-1]))
    peak = np.zeros_like(ok)
    peak[1:-1] = (ac[1:-1] >= ac[:-2]) & (ac[1:-1] >= ac[2:])
    cand = np.flatnonzero(ok & peak)
    if period is not None:
        found, method = float(period), "metadata"
        if not np.isfinite(found) or found <= 0:
            raise InvalidInputError(f"bounce_period: expected a positive number of seconds, got {period!r}")
    else:
        k = int(cand[np.argmax(ac[cand])]) if cand.size else int(np.flatnonzero(ok)[np.argmax(ac[ok])])
        y0, y1, y2 = ac[max(k - 1, 0)], ac[k], ac[min(k + 1, len(ac) - 1)]
        den = y0 - 2.0 * y1 + y2
        shift = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        found, method = float((k + np.clip(shift, -0.5, 0.5)) / fps), "autocorrelation"
    strength = float(np.interp(found, lags, ac))
    t = np.arange(len(z)) / fps
    coef = np.sum(band * np.exp(-2j * np.pi * t / found))
    phi = float(np.angle(coef))  # band ~ cos(2 pi t / P + phi)
    bounces = t / found + phi / (2.0 * np.pi) - 0.5
    bounces = bounces - np.floor(bounces[0])
    return BeatCurve(bounces=bounces, period=found, method=method, strength=strength)


def beats_per_bounce(period: float, bpm: float, choices: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0)) -> float:
    """Beats per bounce (from ``choices``) that bring a bounce of ``period`` s closest to ``bpm``
    (smallest tempo change in log ratio)."""
    natural = 60.0 / float(period)
    return float(min(choices, key=lambda k: abs(np.log(bpm / (natural * k)))))


def warp_to_tempo(
    clip: MotionClip, beats: np.ndarray, bpm: float, fps: float, *, name: str | None = None
) -> MotionClip:
    """``clip`` resampled at ``fps`` on the beat grid of ``bpm``.

    Args:
        clip: a non-looping take; beats: (T,) its beat index per frame, increasing.
        bpm, fps: the target tempo and frame rate.

    Returns a non-looping clip whose frame ``u`` shows the take at beat ``beats[0] + u *
    bpm / 60 / fps`` (whole beats at multiples of ``fps * 60 / bpm`` frames); meta gains
    ``bpm`` and ``tempo_ratio`` (played / natural speed, the take's mean).
    """
    b = np.asarray(beats, dtype=np.float64)
    if b.shape != (clip.n_frames,) or np.any(np.diff(b) <= 0):
        raise InvalidInputError(
            f"warp_to_tempo: beats must be ({clip.n_frames},) and increasing for clip {clip.name!r}"
        )
    start = float(np.ceil(b[0] - 1e-9))
    n_out = int(np.floor((b[-1] - start) * 60.0 / bpm * fps + 1e-9)) + 1
    target = start + np.arange(n_out) * bpm / 60.0 / fps
    t_src = np.interp(target, b, np.arange(clip.n_frames) / clip.fps)
    rot, root = clip.sample(t_src)
    natural = (b[-1] - b[0]) / (clip.n_frames - 1) * clip.fps * 60.0  # beats per minute in the take
    return dataclasses.replace(
        clip,
        name=name or clip.name,
        fps=float(fps),
        joint_rotations=rot,
        root_translation=root,
        meta={**clip.meta, "bpm": float(bpm), "tempo_ratio": float(bpm / natural)},
    )


def circular_spread(phases: np.ndarray) -> dict:
    """``{"resultant": R, "circular_sd": sqrt(-2 ln R) rad, "mean": angle}`` of phases (rad)."""
    ph = np.asarray(phases, dtype=np.float64)
    m = np.mean(np.exp(1j * ph))
    r = float(np.abs(m))
    return {"resultant": r, "circular_sd": float(np.sqrt(-2.0 * np.log(max(r, 1e-12)))), "mean": float(np.angle(m))}


def low_points(height: np.ndarray, fps: float) -> np.ndarray:
    """Times (s) of the low points of a bounce: minima of the height (T,) band-passed to
    0.6-4 Hz, with a prominence of at least half its standard deviation, 0.25 s apart."""
    from scipy.signal import find_peaks

    band = _bandpass(np.asarray(height, dtype=np.float64), fps, *_BAND)
    lows, _ = find_peaks(-band, prominence=0.5 * band.std() + 1e-12, distance=max(1, int(0.25 * fps)))
    return lows / float(fps)


def beat_offset(lows: np.ndarray, beat_period: float) -> float:
    """The offset ``c`` (beats) that puts the low points ``lows`` (s) on the beats of the
    beat index ``t / beat_period + c`` on average (circular mean)."""
    lows = np.asarray(lows, dtype=np.float64)
    if lows.size == 0:
        return 0.0
    mean = np.angle(np.mean(np.exp(2j * np.pi * lows / float(beat_period))))
    return float(-mean / (2.0 * np.pi))


def bounce_phase(heights: np.ndarray, fps: float, bpm: float) -> dict:
    """When each dancer's bounce bottoms out, against the beat.

    Args:
        heights: (T, N) pelvis heights (m) of N dancers; fps: frames per second; bpm: tempo.

    Every low point of a dancer's bounce (minima of the height band-passed to 0.6-4 Hz,
    with a prominence of at least half its standard deviation, 0.25 s apart) gets the beat
    phase ``2 pi (t bpm / 60 mod 1)``: 0 when it falls on a beat. A dancer's phase is the
    circular mean of its low points' phases, its ``consistency`` their resultant length
    (1: every low at the same point of the beat; near 0: drifting across it).

    Returns ``{"phase": (N,) rad, "consistency": (N,), "lows": (N,) counts, "resultant",
    "circular_sd", "mean"}``: the last three are the spread of all low points of all
    dancers pooled (1 and 0 rad when the whole crowd bottoms out on the beat).
    """
    z = np.asarray(heights, dtype=np.float64)
    if z.ndim != 2 or z.shape[0] < int(2 * fps):
        raise InvalidInputError(f"bounce_phase: expected heights of shape (T, N) with at least 2 s, got {z.shape}")
    n = z.shape[1]
    phase, consistency, counts, pooled = np.zeros(n), np.zeros(n), np.zeros(n, dtype=np.int64), []
    for i in range(n):
        lows = low_points(z[:, i], fps)
        theta = 2.0 * np.pi * np.mod(lows * bpm / 60.0, 1.0)
        counts[i] = len(lows)
        if len(lows):
            m = np.mean(np.exp(1j * theta))
            phase[i], consistency[i] = float(np.angle(m)), float(np.abs(m))
            pooled.append(theta)
    spread = (
        circular_spread(np.concatenate(pooled))
        if pooled
        else {"resultant": 0.0, "circular_sd": float("inf"), "mean": 0.0}
    )
    return {"phase": phase, "consistency": consistency, "lows": counts, **spread}
