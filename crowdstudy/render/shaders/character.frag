// Region-coloured bodies: u_colors, RGBA32F, width 6 (colour regions), one row per character
// (linear RGB albedo), lit per vertex (v_diffuse, v_add), the region chosen per pixel.
// Textured bodies: u_albedo, one layer per character on the body's UVs (sqrt of linear RGB),
// lit per pixel with the shadow factor interpolated from the vertices (v_shadow).
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

void main() {
    if (IS_TEXTURED) {
        vec3 albedo = texture(u_albedo, vec3(v_material.xy, float(v_layer))).rgb;
        albedo = albedo * albedo;   // the layers store sqrt(linear): cheap, close to sRGB
        vec3 diffuse, add;
        light_terms_shadowed(v_world, v_normal, v_shadow, diffuse, add);
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
