// Region-coloured bodies: u_colors, RGBA32F, width 6 (colour regions), one row per character
// (linear RGB albedo), lit per vertex (v_diffuse, v_add), the region chosen per pixel.
// Textured bodies: u_albedo, one layer per character on the body's UVs (sqrt of linear RGB;
// alpha: the material, 0 cloth, 0.5 skin, 1 hair), lit per pixel by material
// (character_terms in lighting.glsl) with the shadow factor interpolated from the vertices
// (v_shadow); cloth with a procedural fold relief (bump from screen-space derivatives).
uniform sampler2D u_colors;
uniform sampler2DArray u_albedo;
uniform int u_textured;
// TEXTURED_ONLY / REGIONS_ONLY: a variant compiled for one kind of group (llvmpipe runs
// both sides of a branch on a uniform, so the other kind's code would cost every sample)
#if defined(TEXTURED_ONLY)
#define IS_TEXTURED true
#elif defined(REGIONS_ONLY)
#define IS_TEXTURED false
#else
#define IS_TEXTURED (u_textured == 1)
#endif
in vec3 v_world;
in vec3 v_normal;
in vec4 v_scores_a;
in vec2 v_scores_b;
in vec3 v_material;
in float v_shadow;
in vec3 v_diffuse;
in vec3 v_add;
flat in int v_char;
flat in int v_layer;
out vec4 f_color;

// value noise on the texture's coordinates (fixed to the body: folds do not swim)
float cloth_hash(vec2 p) {
    return fract(sin(dot(p, vec2(127.1, 311.7))) * 43758.5453);
}

float cloth_noise(vec2 x) {
    vec2 i = floor(x), f = fract(x);
    f = f * f * (3.0 - 2.0 * f);
    return mix(mix(cloth_hash(i), cloth_hash(i + vec2(1, 0)), f.x),
               mix(cloth_hash(i + vec2(0, 1)), cloth_hash(i + vec2(1, 1)), f.x), f.y);
}

// the normal bent by the slope of a height field h (m) given per pixel: bump mapping from
// screen-space derivatives (Mikkelsen 2010), no tangent frame needed
vec3 bumped(vec3 n, float h) {
    vec3 dpdx = dFdx(v_world), dpdy = dFdy(v_world);
    vec3 r1 = cross(dpdy, n), r2 = cross(n, dpdx);
    float det = dot(dpdx, r1);
    vec3 grad = sign(det) * (dFdx(h) * r1 + dFdy(h) * r2);
    vec3 b = abs(det) * n - grad;
    float len = length(b);
    return len > 1e-12 ? b / len : n;   // edge-on (det = 0): the plain normal
}

void main() {
    if (IS_TEXTURED) {
        vec4 texel = texture(u_albedo, vec3(v_material.xy, float(v_layer)));
        vec3 albedo = texel.rgb * texel.rgb;   // the layers store sqrt(linear): cheap, close to sRGB
        // alpha: the material (0 cloth, 0.5 skin, 1 hair: a texel blended across a hem or a
        // hairline stays between its two sides). Cloth gets folds: soft ridges about
        // 3-6 cm apart, a few millimetres deep, faded out with distance (no shimmer)
        float cloth = 1.0 - smoothstep(0.1, 0.4, texel.a);
        float hair = smoothstep(0.6, 0.9, texel.a);
        float near = 1.0 - smoothstep(4.0, 9.0, length(u_eye - v_world));
        vec2 uv = v_material.xy;   // no branch: the derivatives need every pixel of a 2x2 quad
        float folds = cloth_noise(uv * vec2(28.0, 60.0)) + 0.5 * cloth_noise(uv * 110.0 + 7.0);
        // the relief is continuous everywhere (a step in it at a hem would be a ridge of
        // highlights); the bent normal is blended in on cloth only
        vec3 n0 = normalize(v_normal);
        vec3 n = normalize(mix(n0, bumped(n0, 0.0035 * near * folds), cloth));
        vec3 diffuse, add;
        character_terms(v_world, n, v_shadow, max(1.0 - cloth - hair, 0.0), hair, diffuse, add);
        f_color = vec4(to_display(albedo * diffuse + add), 1.0);
        return;
    }
    // the region with the highest interpolated score: smooth collar, cuff, waist and hair lines
    int region = 0;
    float best = v_scores_a.x;
    if (v_scores_a.y > best) { best = v_scores_a.y; region = 1; }
    if (v_scores_a.z > best) { best = v_scores_a.z; region = 2; }
    if (v_scores_a.w > best) { best = v_scores_a.w; region = 3; }
    if (v_scores_b.x > best) { best = v_scores_b.x; region = 4; }
    if (v_scores_b.y > best) { region = 5; }
    vec3 albedo = texelFetch(u_colors, ivec2(region, v_char), 0).rgb;
    f_color = vec4(to_display(albedo * v_diffuse + v_add), 1.0);
}
