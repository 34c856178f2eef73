// Soft lighting in linear RGB: a key light with a filtered shadow map, hemisphere ambient,
// a faint rim and specular, distance fog; ACES-like tone curve, gamma 2 output.
// light_terms() returns colour = albedo * diffuse + add. Textured characters evaluate it
// per pixel with the shadow factor interpolated from the vertices (shadow_factor(), 4 taps
// per vertex of a dense mesh: soft edges without 4 lookups per MSAA sample); the region-
// coloured mannequins per vertex; the floor and the corridor's walls per pixel; the venue's
// cut-away elements per vertex, without shadows (static.vert).
uniform vec3 u_light_dir;        // unit vector towards the key light
uniform vec3 u_light_color;
uniform vec3 u_sky_color;
uniform vec3 u_ground_color;
uniform vec3 u_eye;
uniform vec3 u_fog_color;
uniform float u_fog_density;
uniform int u_use_shadows;
uniform mat4 u_light_view_proj;
uniform sampler2DShadow u_shadow;
uniform float u_shadow_texel;

float shadow_factor(vec3 world, vec3 normal, int taps) {
#ifdef UNSHADOWED
    return 1.0;   // ground no character shadow can reach: no texture lookup at all
#endif
    if (u_use_shadows == 0) return 1.0;
    vec4 lp = u_light_view_proj * vec4(world + normal * 0.02, 1.0);
    vec3 c = lp.xyz / lp.w * 0.5 + 0.5;
    if (c.x < 0.0 || c.x > 1.0 || c.y < 0.0 || c.y > 1.0 || c.z > 1.0) return 1.0;
    float z = c.z - 0.0015;
    if (taps <= 1) return texture(u_shadow, vec3(c.xy, z));
    float o = 1.5 * u_shadow_texel;
    return 0.25 * (texture(u_shadow, vec3(c.xy + vec2(-o, -o), z)) + texture(u_shadow, vec3(c.xy + vec2(o, -o), z)) +
                   texture(u_shadow, vec3(c.xy + vec2(-o, o), z)) + texture(u_shadow, vec3(c.xy + vec2(o, o), z)));
}

void light_terms_shadowed(vec3 world, vec3 normal, float sh, out vec3 diffuse, out vec3 add) {
    vec3 n = normalize(normal);
    vec3 v = normalize(u_eye - world);
    if (dot(n, v) < 0.0) n = -n;   // thin or back-facing geometry: light the visible side
    float ndl = max(dot(n, u_light_dir), 0.0);
    vec3 ambient = mix(u_ground_color, u_sky_color, 0.5 + 0.5 * n.z);
    float rim = pow(1.0 - max(dot(n, v), 0.0), 3.0) * 0.12;
    vec3 h = normalize(u_light_dir + v);
    float spec = pow(max(dot(n, h), 0.0), 24.0) * 0.05 * sh;
    float fog = exp(-u_fog_density * length(u_eye - world));
    diffuse = (ambient + u_light_color * ndl * sh) * fog;
    add = (rim + spec) * u_light_color * fog + u_fog_color * (1.0 - fog);
}

void light_terms(vec3 world, vec3 normal, int taps, out vec3 diffuse, out vec3 add) {
    vec3 n = normalize(normal);
    float sh = dot(n, u_light_dir) > -0.05 ? shadow_factor(world, n, taps) : 0.0;
    light_terms_shadowed(world, normal, sh, diffuse, add);
}

// The floor (normal +z, matte): the same terms without rim and specular.
void floor_terms(vec3 world, out vec3 diffuse, out vec3 add) {
    float ndl = max(u_light_dir.z, 0.0);
    float sh = shadow_factor(world, vec3(0.0, 0.0, 1.0), 1);
    float fog = exp(-u_fog_density * length(u_eye - world));
    diffuse = (u_sky_color + u_light_color * ndl * sh) * fog;
    add = u_fog_color * (1.0 - fog);
}

// Characters, per pixel, by material: the weights of skin and of hair (cloth the rest):
// skin: wrapped diffuse (the terminator softened over ~40 degrees) with a warm tint where
//       the wrap reaches past it (light scattered under the skin), a tighter specular;
// hair: a Kajiya-Kay highlight along strands running down the head (anisotropic);
// cloth: matte, a faint broad sheen.
void character_terms(vec3 world, vec3 normal, float sh, float skin, float hair, out vec3 diffuse, out vec3 add) {
    vec3 n = normalize(normal);
    vec3 v = normalize(u_eye - world);
    if (dot(n, v) < 0.0) n = -n;
    float nl = dot(n, u_light_dir);
    float wrap = 0.3 * skin;
    float lambert = max(nl, 0.0);
    float wrapped = max((nl + wrap) / (1.0 + wrap), 0.0);
    vec3 scatter = vec3(0.0);
    if (wrap > 0.0) scatter = vec3(0.12, 0.03, 0.01) * max(wrapped - lambert, 0.0) * 1.5;
    vec3 ambient = mix(u_ground_color, u_sky_color, 0.5 + 0.5 * n.z);
    float rim = pow(1.0 - max(dot(n, v), 0.0), 3.0) * mix(0.08, 0.14, skin);
    vec3 h = normalize(u_light_dir + v);
    float nh = max(dot(n, h), 0.0);
    float spec = mix(pow(nh, 12.0) * 0.015, pow(nh, 48.0) * 0.09, skin);   // cloth / skin
    vec3 t = vec3(0.0, 0.0, 1.0) - n * n.z;                                // hair: strands downwards
    float th = dot(normalize(t + vec3(1e-4)), h);
    spec = mix(spec, pow(sqrt(max(1.0 - th * th, 0.0)), 64.0) * 0.12, hair);
    float fog = exp(-u_fog_density * length(u_eye - world));
    diffuse = (ambient + u_light_color * (mix(lambert, wrapped, skin) + scatter) * sh) * fog;
    add = (rim + spec * sh) * u_light_color * fog + u_fog_color * (1.0 - fog);
}
