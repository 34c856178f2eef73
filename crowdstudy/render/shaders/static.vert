// Floor, stage and walls: world-space triangles with a normal, a colour and a pattern id.
uniform mat4 u_view_proj;
in vec3 in_position;
in vec3 in_normal;
in vec4 in_color;      // linear RGB, pattern id in alpha (0 plain, 1 floor tiles)
out vec3 v_world;
out vec3 v_normal;
flat out vec4 v_color;

void main() {
    v_world = in_position;
    v_normal = in_normal;
    v_color = in_color;
    gl_Position = u_view_proj * vec4(in_position, 1.0);
}
