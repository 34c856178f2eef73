// Fast approximate anti-aliasing of a finished (display-encoded) frame, after the idea of
// Lottes' FXAA: find pixels on a luma edge, walk along the edge to both of its ends, and
// blend each pixel with its neighbour across the edge in proportion to where the pixel
// lies on the staircase step (plus a sub-pixel blend for isolated specks). Two full-screen
// passes (ColorTargets.resolve): with FXAA_MARK defined, every pixel is copied and the
// edge pixels (5 taps: the centre and its 4 neighbours) get depth 0; then, where the
// depth test finds that mark, the filter: 9 unfiltered taps and a short walk (2 steps of
// 2 and 4 pixels each way, after the first). A rasteriser on the CPU shades a block of
// pixels whole, both sides of every branch, so skipping the unmarked blocks (about 7 in
// 10) by the depth test is what saves their shading; longer walks scored no better
// against the supersampled frames (`crowdstudy bench render --ssim`). The edges of the
// characters against each other and against the floor are what it smooths (their
// textures are filtered already).
uniform sampler2D u_color;   // the frame (RGBA8, bilinear, clamped)
uniform vec2 u_texel;        // 1 / frame size (pixels)
uniform float u_edge_min;    // skip regions darker in contrast than this (luma 0..1)
uniform float u_edge_rel;    // ... or than this fraction of the local maximum luma
uniform float u_subpix;      // weight of the sub-pixel blend (0 = off, 1 = strongest)

in vec2 v_uv;
out vec4 f_color;

const int STEPS = 2;
const float STEP_SIZE[STEPS] = float[](2.0, 4.0);

float luma_of(vec3 c) { return dot(c, vec3(0.299, 0.587, 0.114)); }
float luma_at(vec2 uv) { return luma_of(textureLod(u_color, uv, 0.0).rgb); }
float luma_px(ivec2 p) { return luma_of(texelFetch(u_color, p, 0).rgb); }

void main() {
    // the 3x3 neighbourhood read texel by texel (unfiltered: cheaper on a CPU rasteriser),
    // clamped at the frame's border
    ivec2 p = ivec2(gl_FragCoord.xy), top = textureSize(u_color, 0) - 1;
    ivec2 pn = min(p + ivec2(0, 1), top), ps = max(p - ivec2(0, 1), ivec2(0));
    ivec2 pe = min(p + ivec2(1, 0), top), pw = max(p - ivec2(1, 0), ivec2(0));
    vec4 centre = texelFetch(u_color, p, 0);
    float m = luma_of(centre.rgb);
    float n = luma_px(pn), s = luma_px(ps);
    float e = luma_px(pe), w = luma_px(pw);
    float lo = min(m, min(min(n, s), min(e, w)));
    float hi = max(m, max(max(n, s), max(e, w)));
    float range = hi - lo;
    bool edge = range >= max(u_edge_min, hi * u_edge_rel);
#ifdef FXAA_MARK
    // the first pass: every pixel as it is, and its depth 0 where the second pass is to
    // run (1 elsewhere)
    f_color = centre;
    gl_FragDepth = edge ? 0.0 : 1.0;
    return;
#endif
    if (!edge) {
        f_color = centre;
        return;
    }
    float ne = luma_px(ivec2(pe.x, pn.y)), nw = luma_px(ivec2(pw.x, pn.y));
    float se = luma_px(ivec2(pe.x, ps.y)), sw = luma_px(ivec2(pw.x, ps.y));

    // sub-pixel aliasing: how far the centre stands out of its 3x3 neighbourhood
    float mean = (2.0 * (n + s + e + w) + ne + nw + se + sw) / 12.0;
    float sub = clamp(abs(mean - m) / range, 0.0, 1.0);
    sub = sub * sub * (3.0 - 2.0 * sub);
    float sub_blend = sub * sub * u_subpix;

    // is the edge horizontal (luma changes along y) or vertical?
    float horiz = abs(n + s - 2.0 * m) * 2.0 + abs(ne + se - 2.0 * e) + abs(nw + sw - 2.0 * w);
    float vert = abs(e + w - 2.0 * m) * 2.0 + abs(ne + nw - 2.0 * n) + abs(se + sw - 2.0 * s);
    bool horizontal = horiz >= vert;

    // which side of the pixel the edge lies on: the steeper neighbour across it
    float l1 = horizontal ? s : w;
    float l2 = horizontal ? n : e;
    float g1 = abs(l1 - m), g2 = abs(l2 - m);
    float across = horizontal ? u_texel.y : u_texel.x;
    float side_luma;
    float gradient;
    if (g1 >= g2) {
        across = -across;
        side_luma = 0.5 * (l1 + m);
        gradient = g1;
    } else {
        side_luma = 0.5 * (l2 + m);
        gradient = g2;
    }

    // walk along the edge, on the edge line between the pixel and its neighbour
    vec2 uv = v_uv;
    vec2 along = horizontal ? vec2(u_texel.x, 0.0) : vec2(0.0, u_texel.y);
    if (horizontal) uv.y += 0.5 * across; else uv.x += 0.5 * across;
    float threshold = 0.25 * gradient;
    vec2 uv_neg = uv - along, uv_pos = uv + along;
    float d_neg = luma_at(uv_neg) - side_luma, d_pos = luma_at(uv_pos) - side_luma;
    bool done_neg = abs(d_neg) >= threshold, done_pos = abs(d_pos) >= threshold;
    for (int i = 0; i < STEPS && !(done_neg && done_pos); ++i) {
        if (!done_neg) {
            uv_neg -= along * STEP_SIZE[i];
            d_neg = luma_at(uv_neg) - side_luma;
            done_neg = abs(d_neg) >= threshold;
        }
        if (!done_pos) {
            uv_pos += along * STEP_SIZE[i];
            d_pos = luma_at(uv_pos) - side_luma;
            done_pos = abs(d_pos) >= threshold;
        }
    }
    float dist_neg = horizontal ? v_uv.x - uv_neg.x : v_uv.y - uv_neg.y;
    float dist_pos = horizontal ? uv_pos.x - v_uv.x : uv_pos.y - v_uv.y;
    bool neg_nearer = dist_neg < dist_pos;
    float dist = min(dist_neg, dist_pos);
    float span = dist_neg + dist_pos;
    // blend only when the luma at the nearer end crosses to the other side of the edge
    bool m_below = m - side_luma < 0.0;
    bool end_ok = ((neg_nearer ? d_neg : d_pos) < 0.0) != m_below;
    float edge_blend = end_ok ? 0.5 - dist / span : 0.0;

    float blend = max(edge_blend, sub_blend);
    vec2 shifted = v_uv;
    if (horizontal) shifted.y += blend * across; else shifted.x += blend * across;
    f_color = vec4(textureLod(u_color, shifted, 0.0).rgb, 1.0);
}
