// Which character instance is visible at each pixel (overlap view, pass 1).
flat in int v_char;
flat in int v_copy;
out vec2 f_id;

void main() {
    f_id = vec2(float(v_char), float(v_copy));
}
