"""Diverse skin tones and clothing colours, assigned so no two neighbours look identical.

Colours are given in sRGB (0..255) and converted to linear RGB for shading. Each character
gets six colours, one per body region of :data:`REGIONS`: skin, hair, shirt, sleeve
(forearm: skin for short sleeves, the shirt for long ones), trousers, shoes.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = [
    "REGIONS",
    "MIN_SKIN_DELTA_E",
    "srgb_to_lab",
    "SKIN_TONES",
    "HAIR",
    "SHIRTS",
    "TROUSERS",
    "SHOES",
    "assign_colors",
    "srgb_to_linear",
]

REGIONS = ("skin", "hair", "shirt", "sleeve", "trousers", "shoes")

#: smallest CIE76 colour difference between any clothing colour and any skin tone (a shirt
#: close to the skin reads as a bare torso); tests/test_appearance.py checks the palettes.
MIN_SKIN_DELTA_E = 15.0

# A wide range of human skin tones, from very light to very dark.
SKIN_TONES = (
    (255, 224, 196),
    (241, 194, 160),
    (234, 189, 157),
    (224, 172, 135),
    (198, 145, 107),
    (176, 122, 86),
    (160, 106, 72),
    (141, 85, 54),
    (115, 70, 44),
    (92, 56, 36),
    (70, 44, 30),
    (229, 184, 143),
)
HAIR = (
    (25, 20, 18),
    (44, 32, 25),
    (72, 50, 34),
    (104, 72, 46),
    (150, 110, 65),
    (196, 160, 105),
    (130, 60, 35),
    (150, 150, 150),
    (60, 45, 38),
)
SHIRTS = (
    (200, 40, 45),
    (40, 90, 170),
    (245, 245, 240),
    (30, 30, 35),
    (60, 140, 80),
    (240, 190, 40),
    (130, 60, 140),
    (240, 120, 40),
    (90, 170, 200),
    (170, 170, 175),
    (120, 25, 45),
    (235, 150, 170),
    (25, 60, 100),
    (110, 120, 60),
    (200, 90, 110),
    (80, 180, 160),
    (70, 70, 80),
    (190, 210, 90),
)
TROUSERS = (
    (45, 60, 95),
    (60, 85, 130),
    (25, 25, 30),
    (90, 90, 95),
    (150, 150, 120),
    (70, 80, 50),
    (110, 125, 150),
    (200, 195, 185),
)
SHOES = ((235, 235, 230), (20, 20, 22), (120, 120, 125), (150, 40, 35), (40, 60, 110))


def srgb_to_lab(rgb) -> np.ndarray:
    """(..., 3) sRGB 0..255 -> CIE L*a*b* (D65)."""
    c = srgb_to_linear(rgb)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = c @ m.T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16.0 / 116.0)
    return np.stack(
        [116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]), 200.0 * (f[..., 1] - f[..., 2])], axis=-1
    )


def srgb_to_linear(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) sRGB in 0..255 -> linear RGB in 0..1."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _neighbour_pairs(positions: np.ndarray, radius: float, period: float | None) -> list[set[int]]:
    d = positions[:, None, :] - positions[None, :, :]
    if period:
        d[..., 0] -= period * np.round(d[..., 0] / period)
    dist = np.linalg.norm(d, axis=-1)
    np.fill_diagonal(dist, np.inf)
    return [set(np.flatnonzero(row < radius).tolist()) for row in dist]


def assign_colors(
    positions: np.ndarray, seed: int, *, radius: float = 0.9, period: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Colours of N characters; characters closer than ``radius`` never share a shirt or
    trouser colour.

    Each character's colours are drawn from its own generator (``seed``, index); positions
    only decide which draws must be repaired: a character whose shirt (or trousers)
    matches a neighbour of lower index redraws among the colours its neighbours do not
    use. To give a corrected crowd the colours of its Baseline, pass the Baseline's
    positions (the renderer's ``color_positions``).

    Args:
        positions: (N, 2) float, metres; floor positions (periodic along x when ``period``).
        seed: int; the same seed gives the same colours.

    Returns:
        ``(linear, choice)``: linear RGB (N, 6, 3) float32 in the order of :data:`REGIONS`,
        and the palette indices (N, 5) int (skin, hair, shirt, trousers, shoes).
    """
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 2 or len(pos) == 0:
        raise InvalidInputError(f"positions: expected shape (N, 2) with N >= 1, got {pos.shape}")
    n = len(pos)
    palettes = (SKIN_TONES, HAIR, SHIRTS, TROUSERS, SHOES)
    rngs = [np.random.default_rng([int(seed) & 0xFFFFFFFF, i]) for i in range(n)]
    choice = np.array([[int(rng.integers(len(p))) for p in palettes] for rng in rngs], dtype=np.int64)
    long_sleeves = np.array([rng.random() < 0.4 for rng in rngs])
    neigh = _neighbour_pairs(pos, radius, period)
    for i in range(n):
        for slot in (2, 3):  # shirt, trousers
            taken = {int(choice[j, slot]) for j in neigh[i] if j < i}
            if int(choice[i, slot]) in taken:
                free = [c for c in range(len(palettes[slot])) if c not in taken]
                choice[i, slot] = int(rngs[i].choice(free)) if free else choice[i, slot]
    srgb = np.zeros((n, 6, 3))
    for i in range(n):
        skin, hair, shirt = SKIN_TONES[choice[i, 0]], HAIR[choice[i, 1]], SHIRTS[choice[i, 2]]
        srgb[i] = (skin, hair, shirt, shirt if long_sleeves[i] else skin, TROUSERS[choice[i, 3]], SHOES[choice[i, 4]])
    return srgb_to_linear(srgb).astype(np.float32), choice
