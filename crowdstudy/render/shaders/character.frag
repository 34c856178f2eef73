// u_colors: RGBA32F, width 6 (colour regions), one row per character (linear RGB albedo).
uniform sampler2D u_colors;
in vec4 v_scores_a;
in vec2 v_scores_b;
in vec3 v_diffuse;
in vec3 v_add;
flat in int v_char;
out vec4 f_color;

void main() {
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
