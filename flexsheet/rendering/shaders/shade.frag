#version 330 core
// Lambert shading lit from the eye (u_shading = 1) or flat colour (u_shading = 0, used by the measurements).
in vec3 v_normal;
in vec3 v_world;
in float v_valid;
uniform vec3 u_eye;
uniform vec3 u_color;
uniform int u_shading;
out vec4 f_color;
void main() {
    float k = 1.0;
    if (u_shading == 1) {
        vec3 n = normalize(v_normal);
        k = 0.25 + 0.75 * abs(dot(n, normalize(u_eye - v_world)));
    }
    f_color = vec4(u_color * k, 1.0);
}
