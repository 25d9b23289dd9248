#version 330 core
// Copy one eye's image from the renderer's texture (left eye in x < W, right in x >= W) into the current
// viewport. At 1:1 each window pixel fetches exactly its texel (texelFetch: no filtering, and on llvmpipe ~6x
// faster than texture()), so the window shows the offscreen render pixel for pixel; a scaled frame (a monitor
// mode other than the frame size) is sampled bilinearly. u_mirror = 1 flips the image left-right within its
// viewport.
uniform sampler2D u_tex;
uniform vec4 u_vp;     // viewport x, y, w, h in window pixels
uniform ivec4 u_src;   // source rectangle x0, y0, w, h in texels
uniform int u_mirror;
uniform int u_scaled;
out vec4 f_color;
void main() {
    vec2 st = (gl_FragCoord.xy - u_vp.xy) / u_vp.zw;
    if (u_mirror == 1) st.x = 1.0 - st.x;
    vec3 c;
    if (u_scaled == 0) {
        ivec2 p = min(ivec2(st * vec2(u_src.zw)), u_src.zw - 1);
        c = texelFetch(u_tex, u_src.xy + p, 0).rgb;
    } else {
        c = texture(u_tex, (vec2(u_src.xy) + st * vec2(u_src.zw)) / vec2(textureSize(u_tex, 0))).rgb;
    }
    f_color = vec4(c, 1.0);
}
