// Pattern ids: see static.vert. The floor tiles (0.5 m, thin joints, a tone per tile) are
// box-filtered over the pixel's footprint (fwidth of the tile coordinates): the joints
// by the exact integral of the periodic joint function, the per-tile tone faded to its
// mean as tiles shrink below a few pixels, so the pattern fades smoothly to its mean at
// the horizon instead of aliasing into moire.
// u_pool: the pool of light on the crowd (x0, y0, x1, y1 in metres); u_pool_fade: (fade
// distance in metres, factor outside; fade <= 0: no pool).
// VERTEX_LIT: the lighting comes from the vertex shader (see static.vert).
uniform vec4 u_pool;
uniform vec2 u_pool_fade;
in vec3 v_world;
in vec3 v_normal;
flat in vec4 v_color;
out vec4 f_color;

const float JOINT = 0.03;   // joint width, fraction of a tile

// integral over [0, x] of the joint indicator (1 where fract(x) > 1 - JOINT)
vec2 joint_integral(vec2 x) {
    return floor(x) * JOINT + max(fract(x) - (1.0 - JOINT), 0.0);
}

float tile_shade(vec2 u, vec2 w) {   // u: tile coordinates, w: their footprint
    w = max(w, vec2(1e-4));
    vec2 joint = (joint_integral(u + 0.5 * w) - joint_integral(u - 0.5 * w)) / w;
    float j = 1.0 - (1.0 - joint.x) * (1.0 - joint.y);
    float tone = fract(sin(dot(floor(u), vec2(12.9898, 78.233))) * 43758.5453);
    tone = mix(tone, 0.5, smoothstep(0.15, 0.5, max(w.x, w.y)));
    return (0.93 + 0.07 * tone) * (1.0 - 0.25 * j);
}

#ifndef VERTEX_LIT
float pool_factor(vec3 p) {   // as in static.vert
    if (u_pool_fade.x <= 0.0) return 1.0;
    vec2 d = max(max(u_pool.xy - p.xy, p.xy - u_pool.zw), vec2(0.0));
    return mix(1.0, u_pool_fade.y, smoothstep(0.0, u_pool_fade.x, length(d)));
}
#else
in vec3 v_diffuse;
in vec3 v_add;
#endif

void main() {
    vec3 albedo = v_color.rgb;
    float pattern = v_color.a;
    vec2 tiles = v_world.xy / 0.5;
    vec2 footprint = fwidth(tiles);          // outside any branch: derivatives stay defined
    if (pattern > 1.5 && pattern < 2.5) {   // emissive: lamps, screens, signs
        f_color = vec4(to_display(albedo), 1.0);
        return;
    }
    if (pattern > 0.5 && pattern < 1.5) albedo *= tile_shade(tiles, footprint);
#ifdef VERTEX_LIT
    f_color = vec4(to_display(albedo * v_diffuse + v_add), 1.0);
#else
    vec3 diffuse, add;
#ifdef FLOOR
    floor_terms(v_world, diffuse, add);      // horizontal ground: cheaper terms
#else
    light_terms(v_world, v_normal, 1, diffuse, add);
#endif
    float pool = pool_factor(v_world);
    f_color = vec4(to_display(albedo * diffuse * pool + add * pool), 1.0);
#endif
}
