"""Skin tones and clothing colours, assigned so no two neighbours look identical.

Colours are given in sRGB (0..255) and converted to linear RGB for shading. Each character
gets six colours, one per body region of :data:`REGIONS`: skin, hair, shirt, sleeve
(forearm: skin for short sleeves, the shirt for long ones), trousers, shoes.

The clothes follow what a concert crowd wears: mostly dark and muted, with some colour.
Each palette is a set of colour *families*, each with its share of the crowd, split evenly
between the family's shades (:data:`SHIRT_FAMILIES`, :data:`TROUSER_FAMILIES`,
:data:`SHOE_FAMILIES`; a character draws its colours from these weights):

=========  ======  ==========  ======  ======  ======
shirts     share   trousers    share   shoes   share
=========  ======  ==========  ======  ======  ======
black      22 %    denim       45 %    black   40 %
charcoal   12 %    black       25 %    white   35 %
white      12 %    grey        10 %    brown   12 %
navy       10 %    khaki       10 %    grey     8 %
grey        8 %    olive        5 %    colour   5 %
olive       8 %    navy         5 %
brown       7 %
burgundy    5 %
denim       4 %
colour     12 %
=========  ======  ==========  ======  ======  ======

"colour" is a muted red, mustard, teal, purple, royal blue, green and a dusty pink. No
clothing colour lies within :data:`MIN_SKIN_DELTA_E` of a skin tone, and the shades of
one family differ by a visible step (CIE76 at least 5), so two neighbours in black still
read as two people.
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
    "SHIRT_FAMILIES",
    "TROUSER_FAMILIES",
    "SHOE_FAMILIES",
    "SHIRTS",
    "TROUSERS",
    "SHOES",
    "family_of",
    "palette_weights",
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
#: family -> (share of the crowd, sRGB shades)
SHIRT_FAMILIES = {
    "black": (0.22, ((16, 16, 18), (30, 29, 32), (44, 42, 46))),
    "charcoal": (0.12, ((60, 61, 65), (76, 76, 80))),
    "white": (0.12, ((238, 238, 234), (212, 214, 212))),
    "navy": (0.10, ((26, 34, 60), (40, 50, 84))),
    "grey": (0.08, ((118, 119, 123), (152, 152, 155))),
    "olive": (0.08, ((70, 76, 46), (96, 102, 66), (56, 70, 56))),
    "brown": (0.07, ((96, 88, 76), (124, 108, 92), (40, 34, 32))),
    "burgundy": (0.05, ((90, 26, 36), (112, 38, 52))),
    "denim": (0.04, ((76, 100, 138), (112, 136, 170))),
    "colour": (
        0.12,
        ((170, 46, 44), (190, 150, 40), (34, 108, 112), (96, 62, 130), (38, 92, 160), (56, 128, 76), (200, 96, 130)),
    ),
}
TROUSER_FAMILIES = {
    "denim": (0.45, ((28, 38, 64), (46, 64, 98), (72, 96, 134), (108, 132, 166))),
    "black": (0.25, ((18, 18, 21), (36, 36, 40))),
    "grey": (0.10, ((66, 66, 70), (108, 108, 112))),
    "khaki": (0.10, ((134, 128, 96), (120, 112, 80))),
    "olive": (0.05, ((72, 78, 52),)),
    "navy": (0.05, ((34, 34, 58),)),
}
SHOE_FAMILIES = {
    "black": (0.40, ((20, 20, 22), (44, 42, 42))),
    "white": (0.35, ((232, 232, 228), (200, 202, 200))),
    "brown": (0.12, ((40, 34, 32), (124, 108, 92))),
    "grey": (0.08, ((118, 118, 124),)),
    "colour": (0.05, ((150, 40, 35), (40, 60, 110))),
}


def _flat(families: dict) -> tuple:
    return tuple(c for _, shades in families.values() for c in shades)


#: every shade of each palette, family by family (the palette indices of :func:`assign_colors`)
SHIRTS = _flat(SHIRT_FAMILIES)
TROUSERS = _flat(TROUSER_FAMILIES)
SHOES = _flat(SHOE_FAMILIES)


def palette_weights(families: dict) -> np.ndarray:
    """(K,) probability of each shade of a palette: its family's share split evenly."""
    w = [share / len(shades) for share, shades in families.values() for _ in shades]
    return np.asarray(w, dtype=np.float64) / float(sum(w))


def family_of(families: dict, index: int) -> str:
    """The family of shade ``index`` of a palette (e.g. ``family_of(TROUSER_FAMILIES, i)``)."""
    k = int(index)
    for name, (_, shades) in families.items():
        if k < len(shades):
            return name
        k -= len(shades)
    raise InvalidInputError(f"index: expected a shade of the palette (< {len(_flat(families))}), got {index}")


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

    Each character's colours are drawn from its own generator (``seed``, index), clothes
    with the families' shares (see the module docstring); positions
    only decide which draws must be repaired: a character whose shirt (or trousers)
    matches a neighbour of lower index redraws (with the same weights) among the colours
    its neighbours do not use. To give a corrected crowd the colours of its Baseline, pass the Baseline's
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
    weights = (
        np.full(len(SKIN_TONES), 1.0 / len(SKIN_TONES)),
        np.full(len(HAIR), 1.0 / len(HAIR)),
        palette_weights(SHIRT_FAMILIES),
        palette_weights(TROUSER_FAMILIES),
        palette_weights(SHOE_FAMILIES),
    )
    rngs = [np.random.default_rng([int(seed) & 0xFFFFFFFF, i]) for i in range(n)]
    choice = np.array([[int(rng.choice(len(w), p=w)) for w in weights] for rng in rngs], dtype=np.int64)
    long_sleeves = np.array([rng.random() < 0.4 for rng in rngs])
    neigh = _neighbour_pairs(pos, radius, period)
    for i in range(n):
        for slot in (2, 3):  # shirt, trousers
            taken = {int(choice[j, slot]) for j in neigh[i] if j < i}
            if int(choice[i, slot]) in taken:
                free = np.array([c for c in range(len(palettes[slot])) if c not in taken])
                if len(free):
                    w = weights[slot][free]
                    choice[i, slot] = int(free[rngs[i].choice(len(free), p=w / w.sum())])
    srgb = np.zeros((n, 6, 3))
    for i in range(n):
        skin, hair, shirt = SKIN_TONES[choice[i, 0]], HAIR[choice[i, 1]], SHIRTS[choice[i, 2]]
        srgb[i] = (skin, hair, shirt, shirt if long_sleeves[i] else skin, TROUSERS[choice[i, 3]], SHOES[choice[i, 4]])
    return srgb_to_linear(srgb).astype(np.float32), choice
