// Floor, venue and walls: world-space triangles with a normal, a colour and a pattern id.
// Pattern (in_color.a): 0 plain, 1 floor tiles, 2 emissive, 3 + phase (phase in [0, 1)) a
// figure of the surrounding audience, standing on z = 0, that bobs on the beat: a vertex
// at height z rises by u_bob_amplitude * min(z / 1.7 m, 1) * (0.5 - 0.5 cos(2 pi (beat + phase))).
// VERTEX_LIT (the venue's cut-away elements: hall walls, stage, fittings, audience figures):
// lit per vertex, without shadows, like the region-coloured mannequins (llvmpipe shades
// every MSAA sample, so per-pixel lighting of a thousand small figures would cost several
// times the crowd); the floor and the corridor's walls are lit per pixel.
uniform mat4 u_view_proj;
uniform float u_beat;            // beats elapsed since frame 0 (tempo * time)
uniform float u_bob_amplitude;   // m
in vec3 in_position;
in vec3 in_normal;
in vec4 in_color;      // linear RGB, pattern id in alpha
out vec3 v_world;
out vec3 v_normal;
flat out vec4 v_color;
#ifdef VERTEX_LIT
uniform vec4 u_pool;
uniform vec2 u_pool_fade;
out vec3 v_diffuse;
out vec3 v_add;

// the pool of light on the crowd: 1 inside the rectangle u_pool (x0, y0, x1, y1, m), down
// to u_pool_fade.y at u_pool_fade.x metres beyond it (no pool when u_pool_fade.x <= 0)
float pool_factor(vec3 p) {
    if (u_pool_fade.x <= 0.0) return 1.0;
    vec2 d = max(max(u_pool.xy - p.xy, p.xy - u_pool.zw), vec2(0.0));
    return mix(1.0, u_pool_fade.y, smoothstep(0.0, u_pool_fade.x, length(d)));
}
#endif

void main() {
    vec3 p = in_position;
    if (in_color.a >= 2.5) {
        float phase = fract(in_color.a);
        p.z += u_bob_amplitude * min(p.z / 1.7, 1.0) * (0.5 - 0.5 * cos(6.28318531 * (u_beat + phase)));
    }
    v_world = p;
    v_normal = in_normal;
    v_color = in_color;
#ifdef VERTEX_LIT
    light_terms(p, in_normal, 1, v_diffuse, v_add);
    float pool = pool_factor(p);
    if (in_color.a >= 2.5) pool *= mix(0.45, 1.0, smoothstep(0.0, 0.6, p.z));  // figures: darker feet, grounded
    v_diffuse *= pool;
    v_add *= pool;
#endif
    gl_Position = u_view_proj * vec4(p, 1.0);
}
