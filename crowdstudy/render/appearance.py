"""What each character wears, and its albedo texture painted on the body's UVs.

:func:`assign_appearance` draws, per character and from its own seeded generator: skin
tone (from the MakeHuman ancestry blend of the body record, or the palette for other
bodies), hair colour and style (fringe, nape length, a bald crown for some older men;
greying with age), eyebrows, iris, shirt colour, sleeve length (short or to the wrist),
neckline (round or V), trousers / shorts / skirt, belt, shoes (trainers or boots) and
soles. Shirt and trouser colours come from :func:`~crowdstudy.render.palette.assign_colors`
(neighbours never share them; no clothing colour lies within
:data:`~crowdstudy.render.palette.MIN_SKIN_DELTA_E` of a skin tone).

:func:`paint_textures` rasterises every textured character in texture space (shaders
``paint.vert`` / ``paint.frag``): each texel gets the rest-pose position of the surface
point it shows and the rules decide its colour there, so collar, cuffs, hems, hairline,
lips and brows are smooth curves at texture resolution. Every texel outside the UV islands
then takes the colour of the nearest painted texel (:func:`fill_from_nearest`), so neither
filtering nor a decimated level of detail whose triangles reach past an island's edge ever
shows a background colour.
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib

import numpy as np

from crowdstudy.body.loading import body_key
from crowdstudy.body.skeleton import JOINT_INDEX
from crowdstudy.errors import InvalidInputError
from crowdstudy.render.garments import surface_codes
from crowdstudy.render.palette import (
    HAIR,
    SHIRTS,
    SHOES,
    SKIN_TONES,
    TROUSER_FAMILIES,
    TROUSERS,
    family_of,
    srgb_to_linear,
)

__all__ = [
    "Appearance",
    "assign_appearance",
    "paint_textures",
    "RACE_SKIN",
    "TEXTURE_SIZE",
    "TEXTURE_ARRAY_BUDGET",
    "skin_tone",
    "HAIR_STYLE_SHARES",
    "material_alpha",
    "nearest_painted",
    "fill_from_nearest",
    "texture_size",
]

#: sRGB skin tone of each MakeHuman ancestry (african, asian, caucasian), blended in linear RGB
RACE_SKIN = ((92, 58, 40), (206, 160, 122), (222, 176, 148))
#: iris colours (sRGB): dark brown, brown, hazel, green, blue, grey-blue
IRIS = ((45, 28, 18), (84, 52, 30), (110, 82, 45), (80, 100, 60), (70, 105, 150), (100, 115, 125))
SOLES = ((235, 235, 230), (30, 30, 32), (150, 110, 70))
BELTS = ((40, 28, 20), (20, 20, 22), (95, 60, 35))
TEXTURE_SIZE = 1024
#: painted layers kept in memory across renderers of the same characters (the stimulus set
#: renders every crowd from four viewpoints, Baseline and Ours with the same looks)
_PAINT_CACHE_BYTES = 512 * 2**20
_PAINTED: collections.OrderedDict = collections.OrderedDict()
_NEAREST: dict = {}


#: bytes the albedo texture array (one layer per character, mipmaps included) may take:
#: Mesa's llvmpipe refuses an array of 2 GiB or more (GL_OUT_OF_MEMORY), which 400
#: characters at 1024^2 texels reach
TEXTURE_ARRAY_BUDGET = 1536 * 2**20


def texture_size(height: int, n_characters: int = 1) -> int:
    """Texture side for an image ``height`` pixels tall: 1024 from 720p up, else 512 or 256
    (a character never covers more texels of its texture than pixels on screen there),
    halved while ``n_characters`` layers would exceed :data:`TEXTURE_ARRAY_BUDGET` (a
    crowd of 1,000 gets 512, 5,000 get 128: each character then covers few pixels)."""
    size = TEXTURE_SIZE if height >= 720 else 512 if height >= 360 else 256
    while size > 64 and _array_bytes(size, n_characters) > TEXTURE_ARRAY_BUDGET:
        size //= 2
    return size


def _check_allocated(ctx, tex, layers: int, size: int) -> None:
    """Raise (and release ``tex``) when the driver refused the texture array: a refused array
    reads as zeros, and every character would be drawn black."""
    error = ctx.error
    if error != "GL_NO_ERROR":
        tex.release()
        raise InvalidInputError(
            f"paint_textures: the GL driver could not hold {layers} layers of {size}^2 texels "
            f"({_array_bytes(size, layers) / 2**30:.1f} GiB with mipmaps; {error}); "
            f"use texture_size(height, n_characters), which keeps within "
            f"{TEXTURE_ARRAY_BUDGET / 2**30:.1f} GiB"
        )


def _array_bytes(size: int, layers: int) -> int:
    """RGBA8 bytes of a mipmapped texture array of ``layers`` layers ``size`` texels square."""
    return layers * size * size * 4 * 4 // 3


@dataclasses.dataclass(frozen=True)
class Appearance:
    """One character's looks. Colours are linear RGB (3,) floats; lengths metres."""

    skin: tuple
    hair: tuple
    brow: tuple
    iris: tuple
    lip: tuple
    shirt: tuple
    trousers: tuple
    shoes: tuple
    sole: tuple
    belt_color: tuple
    sleeve: float  # beyond the shoulder joint; >= 1 means to the wrist
    neck_drop: float
    vneck: bool
    legwear: str  # "trousers", "shorts" or "skirt"
    hem: float  # m above the knee joint (shorts, skirt) or above the ankle (trousers)
    belt: bool
    boots: bool
    hairstyle: tuple  # fringe drop, nape drop, bald crown (0/1), strand contrast
    hair_volume: float  # m the hair stands off the scalp
    denim: bool = False  # the trousers are denim (a twill weave)
    hair_style: str = "none"  # the hair's geometry (crowdstudy.render.hair.STYLES)


def _lin(rgb) -> tuple:
    return tuple(float(v) for v in srgb_to_linear(np.asarray(rgb, dtype=np.float64)))


def skin_tone(record: dict, rng: np.random.Generator, palette_index: int) -> np.ndarray:
    """Linear RGB skin of a body record: the ancestry blend of a MakeHuman record (blended
    in sRGB, where a half-and-half mix looks half-way; +-5 % individual lightness), else the
    palette tone ``palette_index``."""
    race = record.get("race") if record.get("model") == "makehuman" else None
    if race is None:
        return srgb_to_linear(np.asarray(SKIN_TONES[palette_index], dtype=np.float64))
    w = np.asarray(race, dtype=np.float64)
    w = w / w.sum()
    srgb = (w @ np.asarray(RACE_SKIN, dtype=np.float64)) * float(np.clip(rng.normal(1.0, 0.05), 0.88, 1.12))
    return srgb_to_linear(np.clip(srgb, 0.0, 255.0))


def assign_appearance(records: list[dict], choice: np.ndarray, seed: int) -> list[Appearance]:
    """Appearances of N characters (see the module docstring); same inputs, same result.

    ``choice``: (N, 5) palette indices from :func:`~crowdstudy.render.palette.assign_colors`
    (skin, hair, shirt, trousers, shoes; neighbours already differ)."""
    choice = np.asarray(choice)
    if choice.shape != (len(records), 5):
        raise InvalidInputError(
            f"choice: expected shape ({len(records)}, 5) (assign_colors' palette indices), got {choice.shape}"
        )
    out = []
    for i, rec in enumerate(records):
        rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, i, 7])
        female = rec.get("sex") == "female"
        age = float(rec.get("age", 30.0))
        skin = skin_tone(rec, rng, int(choice[i, 0]))
        hair = srgb_to_linear(np.asarray(HAIR[choice[i, 1]], dtype=np.float64))
        grey = np.clip((age - 45.0) / 30.0, 0.0, 0.9) * rng.random()
        hair = (1 - grey) * hair + grey * srgb_to_linear(np.array([175.0, 172.0, 168.0]))
        race = np.asarray(rec.get("race", [0.0, 0.0, 1.0]), dtype=np.float64)
        light_eyes = race[-1] / max(race.sum(), 1e-9) > 0.6 and rng.random() < 0.5
        iris = IRIS[int(rng.integers(2, 6)) if light_eyes else int(rng.integers(0, 3))]
        long_sleeves = rng.random() < 0.45
        legwear = "trousers"
        r = rng.random()
        if female and r < 0.15:
            legwear = "skirt"
        elif r > 0.82:
            legwear = "shorts"
        hem = {
            "trousers": float(0.0 if rng.random() < 0.7 else rng.uniform(0.03, 0.06)),
            "shorts": float(rng.uniform(0.03, 0.09)),
            "skirt": float(rng.uniform(-0.04, 0.06)),
        }[legwear]
        bald = (not female) and age > 40 and rng.random() < 0.35
        style = (
            float(rng.uniform(0.0, 0.025) if female else rng.uniform(-0.012, 0.01)),
            float(rng.uniform(0.015, 0.05) if female else rng.uniform(-0.005, 0.012)),
            1.0 if bald else 0.0,
            0.35,
        )
        out.append(
            Appearance(
                skin=tuple(skin),
                hair=tuple(hair),
                brow=tuple(0.65 * hair + 0.02),
                iris=_lin(iris),
                lip=tuple(np.clip(skin * np.array([0.95, 0.55, 0.55]), 0, 1)),
                shirt=_lin(SHIRTS[choice[i, 2]]),
                trousers=_lin(TROUSERS[choice[i, 3]]),
                shoes=_lin(SHOES[choice[i, 4]]),
                sole=_lin(SOLES[int(rng.integers(len(SOLES)))]),
                belt_color=_lin(BELTS[int(rng.integers(len(BELTS)))]),
                sleeve=10.0 if long_sleeves else float(rng.uniform(0.07, 0.15)),
                neck_drop=float(rng.uniform(0.015, 0.05)),
                vneck=bool(rng.random() < 0.3),
                legwear=legwear,
                hem=hem,
                belt=bool(legwear != "skirt" and rng.random() < 0.45),
                boots=bool(rng.random() < 0.15),
                hairstyle=style,
                hair_volume=float(rng.uniform(0.008, 0.02) if female else rng.uniform(0.003, 0.009)),
                denim=family_of(TROUSER_FAMILIES, int(choice[i, 3])) == "denim",
                hair_style="none" if bald else _hair_style(rng, female),
            )
        )
    return out


#: hair styles (crowdstudy.render.hair.STYLES) and their shares among women and men;
#: "none": the painted scalp alone (cropped or shaved hair)
HAIR_STYLE_SHARES = {
    "female": {"long": 0.35, "bob": 0.2, "ponytail": 0.15, "bun": 0.1, "short": 0.15, "none": 0.05},
    "male": {"short": 0.5, "none": 0.38, "long": 0.04, "ponytail": 0.04, "bob": 0.04},
}


def _hair_style(rng: np.random.Generator, female: bool) -> str:
    """A hair style drawn with :data:`HAIR_STYLE_SHARES` (the character's last draw: the
    draws before it are those of earlier versions)."""
    shares = HAIR_STYLE_SHARES["female" if female else "male"]
    names = list(shares)
    p = np.array([shares[k] for k in names])
    return names[int(rng.choice(len(names), p=p / p.sum()))]


def _landmarks(body) -> dict:
    """Rest-pose positions the paint rules measure from."""
    J = JOINT_INDEX
    joints = np.asarray(body.rest_joints, dtype=np.float64)
    surf = body.surface
    verts = np.asarray(body.rest_vertices, dtype=np.float64)
    eye_v = verts[np.unique(surf.vertex[surf.part == 1])]
    left = eye_v[eye_v[:, 0] < 0]
    eye = left.mean(axis=0) if len(left) else joints[J["head"]] + np.array([-0.032, 0.07, 0.08])
    head_w = np.asarray(body.weights)[:, J["head"]]
    skull = verts[(head_w > 0.9) & (np.abs(verts[:, 2] - eye[2] - 0.045) < 0.006) & (verts[:, 1] < eye[1] - 0.03)]
    ear_ax = float(np.abs(skull[:, 0]).max()) + 0.004 if len(skull) else 0.075
    return {
        "neck": joints[J["neck"]],
        "eye": eye,
        "shoulder_ax": float(abs(joints[J["left_shoulder"], 0])),
        "wrist_ax": float(abs(joints[J["left_wrist"], 0])),
        "knee_z": float(joints[J["left_knee"], 2]),
        "ankle_z": float(joints[J["left_ankle"], 2]),
        "floor": float(verts[:, 2].min()),
        "waist": float(joints[J["pelvis"], 2] + 0.7 * (joints[J["spine1"], 2] - joints[J["pelvis"], 2])),
        "ear_ax": ear_ax,
    }


def _uniforms(look: Appearance, marks: dict) -> dict:
    shoe_top = marks["ankle_z"] + (0.09 if look.boots else 0.012)
    if look.legwear == "trousers":
        end = max(shoe_top + 0.004, marks["ankle_z"] + look.hem)
    else:
        end = marks["knee_z"] + look.hem
    return {
        "u_skin": look.skin,
        "u_hair": look.hair,
        "u_brow": look.brow,
        "u_shirt": look.shirt,
        "u_trousers": look.trousers,
        "u_shoes": look.shoes,
        "u_sole": look.sole,
        "u_iris": look.iris,
        "u_lip": look.lip,
        "u_belt_color": look.belt_color,
        "u_sleeve": float(min(look.sleeve, marks["wrist_ax"] - marks["shoulder_ax"] - 0.015)),
        "u_neck_drop": look.neck_drop,
        "u_vneck": int(look.vneck),
        "u_trouser_end": float(end),
        "u_waist": marks["waist"],
        "u_shoe_top": float(shoe_top),
        "u_floor": marks["floor"],
        "u_belt": int(look.belt),
        "u_denim": int(look.denim),
        "u_hairstyle": look.hairstyle,
        "u_neck": tuple(marks["neck"]),
        "u_eye": tuple(marks["eye"]),
        "u_shoulder_ax": marks["shoulder_ax"],
        "u_ear_ax": marks["ear_ax"],
    }


def _regions(weights: np.ndarray) -> np.ndarray:
    """(V, 4) summed skin weights: arms (collar excluded), legs, feet, head and neck."""
    w = np.asarray(weights, dtype=np.float64)
    return np.stack(
        [
            w[:, 16:24].sum(axis=1),
            w[:, [1, 2, 4, 5]].sum(axis=1),
            w[:, [7, 8, 10, 11]].sum(axis=1),
            w[:, [12, 15]].sum(axis=1),
        ],
        axis=1,
    ).astype(np.float32)


def paint_textures(ctx, bodies: list, looks: list[Appearance], program, *, size: int = TEXTURE_SIZE):
    """Paint every textured character.

    Returns ``(texture, codes)``: a ``moderngl`` RGBA8 texture array, layer i = character
    i's albedo (sqrt of linear RGB; alpha: the material the character shader lights, see
    :func:`material_alpha`), mipmapped, and per character the (R,) code of each
    render vertex (None for characters without a :class:`~crowdstudy.body.model.Surface`,
    whose layer stays empty). ``program``: the compiled paint program (paint.vert /
    paint.frag)."""
    import moderngl

    n = len(bodies)
    textured = [i for i, b in enumerate(bodies) if getattr(b, "surface", None) is not None]
    layer_size = size if textured else 1
    _ = ctx.error  # clear an earlier error: the next check is this array's
    tex = ctx.texture_array((layer_size, layer_size, max(n, 1)), 4)
    _check_allocated(ctx, tex, n, layer_size)
    codes: list = [None] * n
    if not textured:
        return tex, codes
    color = ctx.texture((size, size), 4)
    fbo = ctx.framebuffer(color_attachments=[color])
    cache: dict = {}
    try:
        fbo.use()
        ctx.viewport = (0, 0, size, size)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        for i in textured:
            body, look = bodies[i], looks[i]
            surf = body.surface
            key = id(surf)
            memo = (body_key(body.record), look, size)
            if memo in _PAINTED:
                filled, codes[i] = _PAINTED[memo]
                _PAINTED.move_to_end(memo)
                tex.write(filled, viewport=(0, 0, i, size, size, 1))
                continue
            if key not in cache:
                static = np.concatenate(
                    [surf.uv, _regions(np.asarray(body.weights)[surf.vertex]), surf.part[:, None].astype(np.float32)],
                    axis=1,
                ).astype(np.float32)
                cache[key] = (ctx.buffer(static.tobytes()), ctx.buffer(surf.faces.astype(np.uint32).tobytes()))
            vbo_static, ibo = cache[key]
            rest = np.asarray(body.rest_vertices, dtype=np.float32)[surf.vertex]
            vbo_rest = ctx.buffer(np.ascontiguousarray(rest).tobytes())
            vao = ctx.vertex_array(
                program,
                [(vbo_static, "2f 4f 1f", "in_uv", "in_regions", "in_part"), (vbo_rest, "3f", "in_rest")],
                index_buffer=ibo,
                index_element_size=4,
            )
            for name, value in _uniforms(look, _landmarks(body)).items():
                if name in program:
                    program[name].value = value
            fbo.clear(0.0, 0.0, 0.0, 0.0)
            vao.render(moderngl.TRIANGLES)
            image = np.frombuffer(fbo.read(components=4), np.uint8).reshape(size, size, 4)
            layout = (hashlib.sha1(np.ascontiguousarray(surf.uv).tobytes()).hexdigest(), size)
            if layout not in _NEAREST:
                _NEAREST[layout] = nearest_painted(image[..., 3] > 0)
            filled = fill_from_nearest(image, _NEAREST[layout])
            codes[i] = surface_codes(filled, surf.uv)
            filled[..., 3] = material_alpha(filled[..., 3])
            data = filled.tobytes()
            _PAINTED[memo] = (data, codes[i])
            while sum(len(v[0]) for v in _PAINTED.values()) > _PAINT_CACHE_BYTES:
                _PAINTED.popitem(last=False)
            tex.write(data, viewport=(0, 0, i, size, size, 1))
            vao.release()
            vbo_rest.release()
    finally:
        for vbo_static, ibo in cache.values():
            vbo_static.release()
            ibo.release()
        fbo.release()
        color.release()
    # clear what the painting left: on Mesa, moderngl's framebuffer creation above leaves a
    # GL_INVALID_OPERATION (the layers are painted all the same); the check below is the mipmaps'
    _ = ctx.error
    tex.build_mipmaps()
    _check_allocated(ctx, tex, n, size)
    tex.filter = (moderngl.LINEAR_MIPMAP_NEAREST, moderngl.LINEAR)
    # clamp, never wrap: charts touch the texture's edges (the back of the head), and a
    # wrapped lookup there blends in the opposite edge's colour (the arm's skin)
    tex.repeat_x = tex.repeat_y = False
    return tex, codes


def material_alpha(what: np.ndarray) -> np.ndarray:
    """The albedo's alpha for the character shader: 0 cloth and shoes, 128 skin (and eyes),
    255 hair (so a texel filtered across a hem blends skin and cloth, never hair);
    ``what``: the painter's alpha (paint.frag's codes, 8 bit)."""
    code = np.rint(np.asarray(what, dtype=np.float64) / 255.0 * 10.0)  # as garments.surface_codes
    out = np.zeros(code.shape, np.uint8)
    out[(code == 10) | (code == 5)] = 128  # skin, eye
    out[code == 9] = 255  # hair
    return out


def nearest_painted(painted: np.ndarray) -> np.ndarray:
    """(H * W,) flat index of the nearest painted texel of every texel (itself if painted);
    ``painted`` (H, W) bool. The same for every character of a template: computed once."""
    from scipy.ndimage import distance_transform_edt

    if not painted.any():
        raise InvalidInputError("paint_textures: the body's UV layout painted no texel")
    # scipy's stub does not tie the result to return_indices (here: the indices alone)
    iy, ix = distance_transform_edt(~painted, return_distances=False, return_indices=True)  # pyright: ignore[reportGeneralTypeIssues]
    return (iy * painted.shape[1] + ix).reshape(-1)


def fill_from_nearest(image: np.ndarray, nearest: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8 -> every texel given the colour and code of ``nearest`` (see
    :func:`nearest_painted`)."""
    return image.reshape(-1, 4)[nearest].reshape(image.shape).copy()
