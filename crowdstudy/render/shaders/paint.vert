// Paints one character's albedo texture: the body is rasterised in texture space
// (position = its UV), each texel receives the rest-pose position of the surface point it
// shows, and paint.frag decides skin, clothing, hair, face and eyes from that position.
in vec2 in_uv;
in vec3 in_rest;         // rest position, m (T-pose, pelvis at the origin, facing +y)
in vec4 in_regions;      // summed skin weights: arm, leg, foot, head
in float in_part;        // 1 = eyeball
out vec3 v_rest;
out vec4 v_regions;
out float v_part;

void main() {
    v_rest = in_rest;
    v_regions = in_regions;
    v_part = in_part;
    gl_Position = vec4(in_uv * 2.0 - 1.0, 0.0, 1.0);
}
