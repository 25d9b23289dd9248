#version 330 core
// Per-vertex image correction (Furukawa et al. §III-C, eqs 1-6) and projection into the projector image.
// Mirrors flexsheet/rendering/correction.py exactly (same validity rules); tests/unit/rendering/test_stereo_renderer.py checks that
// both agree within 1e-6 m through transform feedback. Units m, display frame.

in vec3 in_pos;
in vec3 in_normal;

uniform int u_mode;          // 0 none, 1 flat, 2 four_triangle, 3 fine
uniform vec3 u_eye;          // V
uniform vec3 u_proj;         // P (light source)
uniform vec3 u_ro;           // imaginary screen point
uniform vec3 u_no;           // imaginary screen normal (unit, toward the user)
uniform float u_min_cos;
// flat
uniform vec3 u_rs;
uniform vec3 u_ns;           // unit
// four triangles: fan (u_q, u_c[i], u_c[(i+1)%4]), unit normals toward the user, usable flags
uniform vec3 u_q;
uniform vec3 u_c[4];
uniform vec3 u_tn[4];
uniform int u_usable[4];
// fine: the pushed sheet's depth table (flexsheet/model/sheet_model.py SampledShape; numpy twin in correction.py):
// w (m, along -normal) at u_i = -a + i*du, v_j = -b + j*dv in texel (i, j) of u_wtex (R32F, nu x nv), bilinear
uniform vec3 u_o;
uniform vec3 u_n;
uniform vec3 u_eu;
uniform vec3 u_ev;
uniform float u_a;
uniform float u_b;
uniform sampler2D u_wtex;
uniform ivec2 u_wn;          // (nu, nv)
// projector
uniform mat3 u_Kp;           // intrinsics, px
uniform mat3 u_Rp;           // columns: projector x, y, z axes in the display frame
uniform vec2 u_size;         // (W, H) px
uniform float u_D[5];        // OpenCV distortion k1, k2, p1, p2, k3 (display.yaml projector.D)
uniform int u_distort;       // 0: pinhole (D = 0)
uniform float u_near;
uniform float u_far;

out vec3 v_corrected;
out float v_valid;
out vec3 v_normal;
out vec3 v_world;
out vec2 v_pixel;            // projector pixel (transform feedback: tests compare it with cv2.projectPoints)

// w, dw/du, dw/dv of the depth table: bilinear between the four texels around (u, v), clamped onto the sheet
// (texelFetch: exact float32 samples, no filtering hardware's reduced-precision weights)
vec3 membrane(float u, float v) {
    float du = 2.0 * u_a / float(u_wn.x - 1);
    float dv = 2.0 * u_b / float(u_wn.y - 1);
    float x = (clamp(u, -u_a, u_a) + u_a) / du;
    float y = (clamp(v, -u_b, u_b) + u_b) / dv;
    int i = clamp(int(floor(x)), 0, u_wn.x - 2);
    int j = clamp(int(floor(y)), 0, u_wn.y - 2);
    float tx = x - float(i);
    float ty = y - float(j);
    float w00 = texelFetch(u_wtex, ivec2(i, j), 0).r;
    float w10 = texelFetch(u_wtex, ivec2(i + 1, j), 0).r;
    float w01 = texelFetch(u_wtex, ivec2(i, j + 1), 0).r;
    float w11 = texelFetch(u_wtex, ivec2(i + 1, j + 1), 0).r;
    float w = (1.0 - ty) * ((1.0 - tx) * w00 + tx * w10) + ty * ((1.0 - tx) * w01 + tx * w11);
    float wu = ((1.0 - ty) * (w10 - w00) + ty * (w11 - w01)) / du;
    float wv = ((1.0 - tx) * (w01 - w00) + tx * (w11 - w10)) / dv;
    return vec3(w, wu, wv);
}

// eqs 3-6: landing point C -> shifted vertex A'
vec3 through_screen(vec3 a, vec3 c, inout bool ok) {
    vec3 dcp = c - u_proj;
    float den2 = dot(dcp, u_no);
    if (abs(den2) < u_min_cos * length(dcp)) { ok = false; return a; }
    float s2 = dot(u_ro - u_proj, u_no) / den2;
    if (s2 <= 0.0) { ok = false; return a; }
    vec3 ch = s2 * c + (1.0 - s2) * u_proj;
    float s3 = dot(a - ch, u_no) / dot(u_eye - ch, u_no);
    return s3 * u_eye + (1.0 - s3) * ch;
}

vec3 correct(vec3 a, out bool valid) {
    valid = true;
    if (u_mode == 0) return a;
    vec3 dva = u_eye - a;
    vec3 c;
    bool ok = true;
    bool on = true;
    if (u_mode == 1) {
        float den = dot(dva, u_ns);
        if (abs(den) < u_min_cos * length(dva)) { valid = false; return a; }
        float s1 = dot(u_rs - a, u_ns) / den;
        c = s1 * u_eye + (1.0 - s1) * a;
    } else if (u_mode == 2) {
        float best = -1e30;
        bool any_ok = false;
        c = a;
        for (int i = 0; i < 4; ++i) {
            if (u_usable[i] == 0) continue;
            vec3 n = u_tn[i];
            float den = dot(dva, n);
            if (abs(den) < u_min_cos * length(dva)) continue;
            float s1 = dot(u_q - a, n) / den;
            vec3 x = a + s1 * dva;
            vec3 e1 = u_c[i] - u_q;
            vec3 e2 = u_c[(i + 1) % 4] - u_q;
            vec3 d = x - u_q;
            float d11 = dot(e1, e1), d12 = dot(e1, e2), d22 = dot(e2, e2);
            float dd1 = dot(d, e1), dd2 = dot(d, e2);
            float det = d11 * d22 - d12 * d12;
            float b1 = (d22 * dd1 - d12 * dd2) / det;
            float b2 = (d11 * dd2 - d12 * dd1) / det;
            float bmin = min(min(b1, b2), 1.0 - b1 - b2);
            bool inside = bmin >= -1e-6;
            float score = inside ? 1e6 + s1 : bmin;
            if (score > best) { best = score; c = x; any_ok = true; on = inside; }
        }
        if (!any_ok) { valid = false; return a; }
    } else {
        vec3 d = normalize(a - u_eye);
        float dn = -dot(d, u_n);
        if (abs(dn) < u_min_cos) { valid = false; return a; }
        vec3 vo = u_eye - u_o;
        float t = dot(vo, u_n) / dn;
        float du = dot(d, u_eu), dv = dot(d, u_ev);
        float pu = dot(vo, u_eu), pv = dot(vo, u_ev);
        float h = 0.0;
        for (int it = 0; it < 4; ++it) {  // 4 = correction._NEWTON_ITERS
            vec3 w = membrane(pu + t * du, pv + t * dv);
            h = (-dot(vo, u_n) + t * dn) - w.x;
            float dh = dn - w.y * du - w.z * dv;
            if (abs(dh) < 1e-9) dh = 1e-9;
            t -= clamp(h / dh, -0.1, 0.1);
        }
        h = (-dot(vo, u_n) + t * dn) - membrane(pu + t * du, pv + t * dv).x;
        if (abs(h) >= 1e-6) { valid = false; return a; }
        c = u_eye + t * d;
        on = abs(pu + t * du) <= u_a && abs(pv + t * dv) <= u_b;
    }
    vec3 ah = through_screen(a, c, ok);
    valid = ok && on;
    return ok ? ah : a;
}

void main() {
    bool valid;
    vec3 ah = correct(in_pos, valid);
    v_corrected = ah;
    v_valid = valid ? 1.0 : 0.0;
    v_normal = in_normal;
    v_world = in_pos;
    // where the projector must aim: the screen point on the line V-A'
    vec3 dva = ah - u_eye;
    float s = dot(u_ro - u_eye, u_no) / dot(dva, u_no);
    vec3 x = u_eye + s * dva;
    vec3 pc = transpose(u_Rp) * (x - u_proj);
    vec2 xn = pc.xy / pc.z;
    if (u_distort == 1) {    // OpenCV's model (cv::projectPoints): radial k1 k2 k3, tangential p1 p2
        float r2 = dot(xn, xn);
        float radial = 1.0 + r2 * (u_D[0] + r2 * (u_D[1] + r2 * u_D[4]));
        float xy = xn.x * xn.y;
        xn = xn * radial + vec2(2.0 * u_D[2] * xy + u_D[3] * (r2 + 2.0 * xn.x * xn.x),
                                u_D[2] * (r2 + 2.0 * xn.y * xn.y) + 2.0 * u_D[3] * xy);
    }
    vec3 pix = u_Kp * vec3(xn, 1.0);
    vec2 uv = pix.xy / pix.z;
    v_pixel = uv;
    float dist = dot(u_eye - in_pos, u_no);
    gl_Position = vec4((2.0 * uv.x + 1.0) / u_size.x - 1.0,
                       1.0 - (2.0 * uv.y + 1.0) / u_size.y,
                       2.0 * (dist - u_near) / (u_far - u_near) - 1.0, 1.0);
}
