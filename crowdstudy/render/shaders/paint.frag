// The albedo of one texel of one character (linear RGB stored as its square root).
// Rules on the rest-pose position p (T-pose, pelvis at the origin, +y forward, left at -x)
// and the interpolated skin-weight regions: eyes, skin with lips and eyebrows, hair above a
// hairline, shirt with sleeves and neckline, trousers / shorts / skirt with hem and belt,
// shoes with soles. Boundaries are evaluated per texel: smooth at texture resolution.
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

vec3 eye_color(vec3 p) {
    vec3 centre = vec3(sign(p.x) * abs(u_eye.x), u_eye.y, u_eye.z);
    float k = normalize(p - centre).y;   // cosine of the angle from straight ahead
    vec3 sclera = vec3(0.70, 0.66, 0.62);
    vec3 iris = u_iris * (0.7 + 0.6 * vnoise(p * 2500.0));
    vec3 c = mix(sclera, iris * 0.55, smoothstep(0.905, 0.915, k));   // dark limbal ring
    c = mix(c, iris, smoothstep(0.925, 0.945, k));
    return mix(c, vec3(0.008), smoothstep(0.978, 0.984, k));          // pupil
}

void main() {
    vec3 p = v_rest;
    if (v_part > 0.5) {
        f_color = vec4(sqrt(eye_color(p)), EYE);
        return;
    }
    float ax = abs(p.x);
    float n1 = vnoise(p * 90.0);
    float n2 = vnoise(p * 420.0);
    vec3 c = u_skin * (0.95 + 0.07 * n1 + 0.03 * n2);
    float what = SKIN;
    float arm = v_regions.x, head = v_regions.w;
    vec3 q = p - vec3(0.0, u_eye.y, u_eye.z);   // from the eyes' height and depth
    if (head > 0.5) {
        float lx = ax / 0.024, lz = (q.z + 0.066) / 0.008;
        float lip = lx * lx + lz * lz;
        if (q.y > 0.0 && lip < 1.0) c = mix(c, u_lip, 0.6 * (1.0 - smoothstep(0.5, 1.0, lip)));
        float bx = ax - abs(u_eye.x);
        float bz = q.z - 0.020 - 0.005 * (1.0 - (bx / 0.022) * (bx / 0.022));
        float width = 0.0038 * (1.0 - 0.55 * smoothstep(-0.01, 0.024, bx));
        if (q.y > -0.03 && bx > -0.022 && bx < 0.024 && abs(bz) < width) c = u_brow * (0.85 + 0.3 * n2);
        float front = smoothstep(-0.115, -0.025, q.y);
        float line = mix(-0.078 - u_hairstyle.y, 0.056 - u_hairstyle.x, front);
        bool ear = ax > u_ear_ax && q.z < 0.032 && q.z > -0.06;
        bool hair = q.z > line && !ear && p.z > u_neck.z - 0.03;
        if (u_hairstyle.z > 0.5) hair = hair && q.z < 0.03 && front < 0.75;
        if (hair) {
            float strands = vnoise(vec3(atan(q.x, q.y + 0.07) * 70.0, q.z * 5.0, 0.5));
            c = u_hair * (0.85 + u_hairstyle.w * (strands - 0.5) + 0.12 * (n2 - 0.5));
            what = HAIR;
        }
    }
    bool torso = head < 0.5 && arm < 0.5 && p.z > u_waist;
    // the neckline: an opening around the neck, lower at the front (round or V); the
    // shirt covers the shoulders beyond it whatever their height
    float front_n = smoothstep(-0.01, 0.05, p.y - u_neck.y);
    float opening = 1.0 - smoothstep(0.055, 0.10, ax);
    float neckline = u_neck.z - 0.03 - opening * (u_neck_drop * front_n
                     + (u_vneck == 1 ? 0.07 * front_n * (1.0 - smoothstep(0.0, 0.07, ax)) : 0.0));
    if (opening <= 0.0) neckline = 10.0;
    float reach = ax - u_shoulder_ax;
    bool sleeve = arm >= 0.5 && reach < u_sleeve;
    if ((torso || sleeve) && p.z < neckline) {
        c = u_shirt * (0.94 + 0.09 * n1 + 0.04 * n2);
        what = SHIRT;
        if (sleeve && reach > u_sleeve - 0.012) c *= 0.82;   // hem of the sleeve
        if (p.z > neckline - 0.009) c *= 0.82;               // collar band
    }
    if (arm < 0.5 && head < 0.5 && p.z <= u_waist && p.z > u_trouser_end) {
        c = u_trousers * (0.9 + 0.12 * n1 + 0.1 * n2);
        what = TROUSERS;
        if (p.z < u_trouser_end + 0.012) c *= 0.85;
        if (u_belt == 1 && p.z > u_waist - 0.03) c = u_belt_color * (0.9 + 0.1 * n2);
    }
    if (arm < 0.5 && head < 0.5 && p.z < u_shoe_top) {
        c = u_shoes * (0.92 + 0.1 * n2);
        what = SHOES;
        if (p.z < u_floor + 0.016) c = u_sole;
    }
    f_color = vec4(sqrt(clamp(c, 0.0, 1.0)), what);
}
