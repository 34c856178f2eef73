// The albedo of one texel of one character (linear RGB stored as its square root).
// Rules on the rest-pose position p (T-pose, pelvis at the origin, +y forward, left at -x)
// and the interpolated skin-weight regions: eyes, skin with lips and eyebrows, hair above a
// hairline, shirt with sleeves and neckline, trousers / shorts / skirt with hem and belt,
// shoes with soles.
// Every boundary is a level set of a smooth function f of the rest position (inside where
// f > 0) and is anti-aliased in texture space: a layer covers a texel by
// clamp(0.5 + f / fwidth(f)), the fraction of the texel's footprint inside, so a hem, a
// cuff or a neckline is a smooth curve at any magnification, never a staircase of texels.
// The alpha channel names what covers most of the texel (render/garments.py reads it back).
uniform vec3 u_skin;
uniform vec3 u_hair;
uniform vec3 u_brow;
uniform vec3 u_shirt;
uniform vec3 u_trousers;
uniform vec3 u_shoes;
uniform vec3 u_sole;
uniform vec3 u_iris;
uniform vec3 u_lip;
uniform vec3 u_belt_color;
uniform float u_sleeve;       // m beyond the shoulder joint the sleeve reaches
uniform float u_neck_drop;    // m the neckline drops at the front
uniform int u_vneck;
uniform float u_trouser_end;  // z (m) of the trouser / skirt hem
uniform float u_waist;        // z of the waistband
uniform float u_shoe_top;     // z of the shoes' top edge
uniform float u_floor;        // z of the soles
uniform int u_belt;
uniform vec4 u_hairstyle;     // fringe drop, nape drop, bald crown (0/1), strand contrast
uniform int u_denim;          // 1: the trousers are denim (a diagonal twill)
uniform vec3 u_neck;          // neck joint
uniform vec3 u_eye;           // centre of the left eyeball (x < 0); the right one mirrors x
uniform float u_shoulder_ax;  // |x| of the shoulder joints
uniform float u_ear_ax;       // |x| beyond which the side of the head is ear (kept skin)
// the alpha channel names what a texel shows (render/garments.py reads it back):
const float SKIN = 1.0, HAIR = 0.9, SHIRT = 0.8, TROUSERS = 0.7, SHOES = 0.6, EYE = 0.5;
in vec3 v_rest;
in vec4 v_regions;
in float v_part;
out vec4 f_color;

float hash(vec3 p) {
    p = fract(p * 0.3183099 + 0.1);
    p *= 17.0;
    return fract(p.x * p.y * p.z * (p.x + p.y + p.z));
}

float vnoise(vec3 x) {
    vec3 i = floor(x);
    vec3 f = fract(x);
    f = f * f * (3.0 - 2.0 * f);
    return mix(mix(mix(hash(i), hash(i + vec3(1, 0, 0)), f.x),
                   mix(hash(i + vec3(0, 1, 0)), hash(i + vec3(1, 1, 0)), f.x), f.y),
               mix(mix(hash(i + vec3(0, 0, 1)), hash(i + vec3(1, 0, 1)), f.x),
                   mix(hash(i + vec3(0, 1, 1)), hash(i + vec3(1, 1, 1)), f.x), f.y), f.z);
}

// the part of the texel where f > 0 (f smooth over the texel): 0..1
float cover(float f) {
    return clamp(0.5 + f / max(fwidth(f), 1e-7), 0.0, 1.0);
}

vec3 eye_color(vec3 p) {
    vec3 centre = vec3(sign(p.x) * abs(u_eye.x), u_eye.y, u_eye.z);
    float k = normalize(p - centre).y;   // cosine of the angle from straight ahead
    vec3 sclera = vec3(0.70, 0.66, 0.62);
    vec3 iris = u_iris * (0.7 + 0.6 * vnoise(p * 2500.0));
    vec3 c = mix(sclera, iris * 0.55, smoothstep(0.905, 0.915, k));   // dark limbal ring
    c = mix(c, iris, smoothstep(0.925, 0.945, k));
    return mix(c, vec3(0.008), smoothstep(0.978, 0.984, k));          // pupil
}

// the face's features on the skin: lips and eyebrows
vec3 face(vec3 p, vec3 q, vec3 c, float n2, float head) {
    float ax = abs(p.x);
    float lx = ax / 0.024, lz = (q.z + 0.066) / 0.008;
    float lip = lx * lx + lz * lz;
    c = mix(c, u_lip, 0.6 * (1.0 - smoothstep(0.5, 1.0, lip)) * smoothstep(-0.004, 0.004, q.y) * step(0.5, head));
    float bx = ax - abs(u_eye.x);
    float bz = q.z - 0.020 - 0.005 * (1.0 - (bx / 0.022) * (bx / 0.022));
    float width = 0.0038 * (1.0 - 0.55 * smoothstep(-0.01, 0.024, bx));
    float brow = cover(width - abs(bz)) * cover(bx + 0.022) * cover(0.024 - bx) * cover(q.y + 0.03);
    return mix(c, u_brow * (0.85 + 0.3 * n2), brow * step(0.5, head));
}

// how much of the texel is hair (the hairline: low at the nape, at the fringe in front)
float hair_cover(vec3 p, vec3 q, float head) {
    float ax = abs(p.x);
    float front = smoothstep(-0.115, -0.025, q.y);
    float line = mix(-0.078 - u_hairstyle.y, 0.056 - u_hairstyle.x, front);
    float ear = cover(ax - u_ear_ax) * cover(0.032 - q.z) * cover(q.z + 0.06);
    float h = cover(q.z - line) * (1.0 - ear) * cover(p.z - u_neck.z + 0.03) * cover(head - 0.5);
    float bald = cover(0.03 - q.z) * cover(0.75 - front);   // a bald crown
    if (u_hairstyle.z > 0.5) h *= bald;
    return h;
}

// the shirt's neckline: a smooth surface of the rest position, 4 cm under the neck joint at
// the back, lower at the front (a scoop of u_neck_drop m; a V for a V-neck). Not the skin
// weights: those are linear per triangle, and their level sets zig-zag along the mesh.
// Returns (coverage of the shirt's top, of its collar band).
vec2 neckline(vec3 p, float head) {
    vec2 d = vec2(p.x, p.y - u_neck.y);
    float front = smoothstep(0.0, 0.9, d.y / max(length(d), 1e-4));
    float ax = abs(p.x);
    float v = u_vneck == 1 ? 0.07 * front * max(0.0, 1.0 - ax / 0.065) : 0.0;
    float z_front = u_neck.z - 0.04 - u_neck_drop * front * front - v;
    // beyond the neck the cut rises, a little past the sides of the neck (the ears, at
    // |x| < 0.09, stay above it), then out of the way over the shoulders and sleeves
    float z_line = z_front + 0.06 * smoothstep(0.06, 0.11, ax) + 0.4 * smoothstep(0.12, 0.16, ax);
    float top = cover(z_line - p.z);
    float band = cover(p.z - z_line + 0.009);
    return vec2(top, band);
}

void main() {
    vec3 p = v_rest;
    if (v_part > 0.5) {
        f_color = vec4(sqrt(eye_color(p)), EYE);
        return;
    }
    float n1 = vnoise(p * 90.0);
    float n2 = vnoise(p * 420.0);
    vec3 c = u_skin * (0.95 + 0.07 * n1 + 0.03 * n2);
    float arm = v_regions.x, head = v_regions.w;
    vec3 q = p - vec3(0.0, u_eye.y, u_eye.z);   // from the eyes' height and depth
    // no branches around cover(): its derivatives need every texel of a 2x2 quad
    c = face(p, q, c, n2, head);
    // each layer: its coverage of the texel, painted over what lies below it
    float hair = hair_cover(p, q, head);
    float strands = vnoise(vec3(atan(q.x, q.y + 0.07) * 70.0, q.z * 5.0, 0.5));
    c = mix(c, u_hair * (0.85 + u_hairstyle.w * (strands - 0.5) + 0.12 * (n2 - 0.5)), hair);
    float on_arm = cover(arm - 0.5);
    float trunk = cover(0.5 - arm) * cover(0.5 - head);   // neither arm nor head
    float reach = abs(p.x) - u_shoulder_ax;
    vec2 neck = neckline(p, head);
    float torso = cover(p.z - u_waist);
    float shirt = ((1.0 - on_arm) * torso + on_arm * cover(u_sleeve - reach)) * neck.x;
    vec3 cloth = u_shirt * (0.94 + 0.09 * n1 + 0.04 * n2);
    cloth *= 1.0 - 0.18 * on_arm * cover(reach - u_sleeve + 0.012);   // the sleeve's hem
    cloth *= 1.0 - 0.18 * neck.y;                                      // the collar band
    c = mix(c, cloth, shirt);
    float legs = trunk * cover(u_waist - p.z) * cover(p.z - u_trouser_end);
    vec3 tr = u_trousers * (0.9 + 0.12 * n1 + 0.1 * n2);
    if (u_denim == 1) {   // a diagonal twill and faded thighs
        float twill = 0.5 + 0.5 * sin((p.z + 0.7 * p.x + 0.7 * p.y) * 2200.0);
        tr *= (0.93 + 0.1 * twill) * (1.0 + 0.18 * smoothstep(0.0, 0.25, p.z - u_trouser_end) * (n1 - 0.3));
    }
    tr *= 1.0 - 0.15 * cover(u_trouser_end + 0.012 - p.z);           // the hem
    if (u_belt == 1) tr = mix(tr, u_belt_color * (0.9 + 0.1 * n2), cover(p.z - u_waist + 0.03));
    c = mix(c, tr, legs);
    float shoe = trunk * cover(u_shoe_top - p.z);
    c = mix(c, mix(u_shoes * (0.92 + 0.1 * n2), u_sole, cover(u_floor + 0.016 - p.z)), shoe);
    // what covers most of the texel
    float what = SKIN;
    if (hair > 0.5) what = HAIR;
    if (shirt > 0.5) what = SHIRT;
    if (legs > 0.5) what = TROUSERS;
    if (shoe > 0.5) what = SHOES;
    f_color = vec4(sqrt(clamp(c, 0.0, 1.0)), what);
}
