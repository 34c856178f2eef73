in vec3 v_world;
in vec3 v_normal;
flat in vec4 v_color;
out vec4 f_color;

void main() {
    vec3 albedo = v_color.rgb;
    if (v_color.a > 0.5) {   // floor tiles: 0.5 m tiles with thin joints and a slight tone variation
        vec2 cell = floor(v_world.xy / 0.5);
        vec2 f = fract(v_world.xy / 0.5);
        float joint = step(0.97, max(f.x, f.y));
        float tone = fract(sin(dot(cell, vec2(12.9898, 78.233))) * 43758.5453);
        albedo *= (0.93 + 0.07 * tone) * (1.0 - 0.25 * joint);
    }
    vec3 diffuse, add;
#ifdef FLOOR
    floor_terms(v_world, diffuse, add);      // horizontal ground: cheaper terms
#else
    light_terms(v_world, v_normal, 1, diffuse, add);
#endif
    f_color = vec4(to_display(albedo * diffuse + add), 1.0);
}
