// Overlap view, pass 2 (no depth test): marks the pixels where a surface fragment of
// character A lies inside a capsule of another character B, and the pixel's visible
// surface (pass 1) belongs to A (same periodic copy) or to B: the interpenetration is
// drawn through the two bodies that cause it, but never through a third body or the floor.
uniform sampler2D u_ids;        // RG32F: visible character index (-1 none), copy code
uniform sampler2D u_capsules;   // RGBA32F, width 48: (a.xyz, radius), (b.xyz, owner) per capsule, row = character
uniform sampler2D u_candidates; // R32F, width K + 1: count, then flat capsule indices (owner * 24 + bone)
uniform sampler2D u_bodies;     // RGBA32F, width 2: the box (lo.xyz), (hi.xyz) around each character's capsules
uniform sampler2D u_owners;     // RGBA32F: owner count (-1: scan all), then per owner (lo.xyz, first), (hi.xyz, last)
uniform float u_period;         // periodic length along x (0 = not periodic)
uniform float u_tolerance;      // metres: a point counts as inside when deeper than this

in vec3 v_world;
flat in int v_char;
flat in int v_copy;
flat in float v_shift;
out vec4 f_mask;

float segment_distance(vec3 p, vec3 a, vec3 b) {
    vec3 ab = b - a;
    float t = clamp(dot(p - a, ab) / max(dot(ab, ab), 1e-12), 0.0, 1.0);
    return length(p - (a + t * ab));
}

// whether p lies outside the box [lo, hi] (m), the box moved by whole periods to p's side
bool outside_box(vec3 p, vec3 lo, vec3 hi) {
    if (u_period > 0.0) p.x -= u_period * floor((p.x - 0.5 * (lo.x + hi.x)) / u_period + 0.5);
    return any(lessThan(p, lo)) || any(greaterThan(p, hi));
}

// whether p lies deeper than u_tolerance inside one of the candidates [first, last) of the
// fragment's character (those of owner `only` unless `any_owner`)
bool inside_any(vec3 p, int first, int last, bool any_owner, int only) {
    for (int i = first; i < last; ++i) {
        int ci = int(texelFetch(u_candidates, ivec2(i + 1, v_char), 0).r + 0.5);
        int owner = ci / 24;
        if (!any_owner && owner != only) continue;
        int bone = ci - owner * 24;
        vec4 a = texelFetch(u_capsules, ivec2(bone * 2, owner), 0);
        vec4 b = texelFetch(u_capsules, ivec2(bone * 2 + 1, owner), 0);
        vec3 off = vec3(0.0);
        if (u_period > 0.0) {
            float dx = p.x - 0.5 * (a.x + b.x);
            off.x = u_period * floor(dx / u_period + 0.5);
        }
        if (segment_distance(p, a.xyz + off, b.xyz + off) < a.w - u_tolerance) return true;
    }
    return false;
}

void main() {
    vec2 vis = texelFetch(u_ids, ivec2(gl_FragCoord.xy), 0).rg;
    int vis_char = int(vis.r + 0.5);
    if (vis.r < -0.5) discard;
    bool self_visible = (vis_char == v_char) && (int(vis.g + 0.5) == v_copy);
    vec3 p = v_world - vec3(v_shift, 0.0, 0.0);
    int count = int(texelFetch(u_candidates, ivec2(0, v_char), 0).r + 0.5);
    int first = 0, last = count;
#ifndef OVERLAP_SCAN_ALL
    // a hidden fragment can only be marked by a capsule of the visible character: the
    // candidates are sorted by id (owner * 24 + bone), so bisect to that owner's <= 24
    // entries instead of scanning them all (the same capsules tested, the same mask)
    if (!self_visible) {
        // a hidden fragment can only be marked inside the visible character: outside the
        // box around its capsules, it is inside none of them
        if (outside_box(p, texelFetch(u_bodies, ivec2(0, vis_char), 0).xyz,
                        texelFetch(u_bodies, ivec2(1, vis_char), 0).xyz)) discard;
        int target = vis_char * 24;
        int a = 0, b = count;
        while (a < b) {
            int m = (a + b) / 2;
            if (int(texelFetch(u_candidates, ivec2(m + 1, v_char), 0).r + 0.5) < target) a = m + 1; else b = m;
        }
        first = a;
        last = min(count, a + 24);
    }
#endif
#ifndef OVERLAP_SCAN_ALL
    // the visible surface of the fragment's own character: visit only the owners whose box
    // (their candidate capsules, widened by the radii) holds the point
    float owners = texelFetch(u_owners, ivec2(0, v_char), 0).r;  // -1: too many, scan the list
    if (self_visible && owners > -0.5) {
        int n_owners = int(owners + 0.5);
        for (int k = 0; k < n_owners; ++k) {
            vec4 lo = texelFetch(u_owners, ivec2(1 + 2 * k, v_char), 0);
            vec4 hi = texelFetch(u_owners, ivec2(2 + 2 * k, v_char), 0);
            if (outside_box(p, lo.xyz, hi.xyz)) continue;
            if (inside_any(p, int(lo.w + 0.5), int(hi.w + 0.5), true, -1)) {
                f_mask = vec4(1.0);
                return;
            }
        }
        discard;
    }
#endif
    if (inside_any(p, first, last, self_visible, vis_char)) {
        f_mask = vec4(1.0);
        return;
    }
    discard;
}
