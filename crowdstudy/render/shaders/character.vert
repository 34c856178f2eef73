// Linear blend skinning on the GPU (vertex pulling of the per-character rest shape).
// u_bones: RGBA32F, width 3 * 24 (the three rows of each bone's 3x4 skinning matrix),
//          one row per character; the only per-frame upload.
// u_rest:  RGBA32F, rest position (xyz) then rest normal (xyz) of every vertex of every
//          member of this template group, 2 texels per vertex, row-major in u_rest_width.
uniform sampler2D u_bones;
uniform sampler2D u_rest;
uniform int u_rest_width;
uniform int u_n_vertices;
uniform int u_n_characters;
uniform float u_period;   // periodic scenes: the copy length (m), 0 otherwise
uniform mat4 u_view_proj;
uniform int u_textured;   // 1: the group is drawn with per-character textures
// TEXTURED_ONLY / REGIONS_ONLY: a variant compiled for one kind of group (llvmpipe runs
// both sides of a branch on a uniform, so the other kind's code would cost every sample)
#if defined(TEXTURED_ONLY)
#define IS_TEXTURED true
#elif defined(REGIONS_ONLY)
#define IS_TEXTURED false
#else
#define IS_TEXTURED (u_textured == 1)
#endif

in ivec4 in_joints;
in vec4 in_weights;
in vec4 in_scores_a;   // colour-region scores: skin, hair, shirt, sleeve
in vec2 in_scores_b;   //                       trousers, shoes
in vec3 in_material;   // textured groups: texture coordinates, part (1 = eye)
// per instance
in int in_char;
in int in_member;
in float in_shift;

out vec3 v_world;
out vec3 v_normal;
#ifdef LIT
out vec3 v_diffuse;
out vec3 v_add;
#endif
out vec4 v_scores_a;
out vec2 v_scores_b;
out vec3 v_material;
out float v_shadow;
flat out int v_char;
flat out int v_copy;
flat out int v_layer;     // the albedo layer: periodic copies wear other characters' clothes
flat out float v_shift;

vec4 rest_texel(int idx) {
    return texelFetch(u_rest, ivec2(idx % u_rest_width, idx / u_rest_width), 0);
}

void main() {
    int base = (in_member * u_n_vertices + gl_VertexID) * 2;
    vec4 p = vec4(rest_texel(base).xyz, 1.0);
    vec3 n = rest_texel(base + 1).xyz;
    vec4 r0 = vec4(0.0), r1 = vec4(0.0), r2 = vec4(0.0);
    for (int k = 0; k < 4; ++k) {
        float w = in_weights[k];
        int j = in_joints[k] * 3;
        r0 += w * texelFetch(u_bones, ivec2(j, in_char), 0);
        r1 += w * texelFetch(u_bones, ivec2(j + 1, in_char), 0);
        r2 += w * texelFetch(u_bones, ivec2(j + 2, in_char), 0);
    }
    vec3 world = vec3(dot(r0, p), dot(r1, p), dot(r2, p)) + vec3(in_shift, 0.0, 0.0);
    v_world = world;
    v_normal = vec3(dot(r0.xyz, n), dot(r1.xyz, n), dot(r2.xyz, n));
    v_scores_a = in_scores_a;
    v_scores_b = in_scores_b;
    v_material = in_material;
#ifdef LIT
    if (IS_TEXTURED) {   // lit per pixel; only the shadow lookup per vertex
        vec3 n = normalize(v_normal);
        v_shadow = dot(n, u_light_dir) > -0.05 ? shadow_factor(world, n, 4) : 0.0;
        v_diffuse = vec3(0.0);
        v_add = vec3(0.0);
    } else {
        v_shadow = 1.0;
        light_terms(world, v_normal, 4, v_diffuse, v_add);
    }
#else
    v_shadow = 1.0;
#endif
    v_char = in_char;
    v_shift = in_shift;
    v_copy = int(floor(in_shift * 1000.0 + 0.5));
    // copy k of a periodic crowd is dressed as character (i + 17 k) mod N: the repeated
    // crowd does not read as clones (the motion repeats, the people do not)
    int k = u_period > 0.0 ? int(floor(in_shift / u_period + 0.5)) : 0;
    v_layer = ((in_char + 17 * k) % u_n_characters + u_n_characters) % u_n_characters;
    gl_Position = u_view_proj * vec4(world, 1.0);
}
