"""GLSL 3.30 sources of the renderer."""

FULLSCREEN_VS = """
#version 330
out vec2 v_uv;
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    v_uv = p;
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

# Blinn-Phong lighting shared by the per-pixel and per-vertex surface programs.
LIGHTING = """
uniform int u_ortho;
uniform vec3 u_eye;
uniform vec3 u_view_back;       // unit vector towards the viewer (orthographic)
uniform int u_light_kind;       // 0 point, 1 spot, 2 directional
uniform vec3 u_light_pos;
uniform vec3 u_light_dir;       // from the light towards the scene
uniform float u_spot_cos;
uniform float u_light_intensity;
uniform vec3 u_light_color;
uniform float u_headlight;
uniform vec4 u_material;        // ambient, diffuse, specular, shininess
uniform int u_shadows;
uniform sampler2DShadow u_shadow_map;
uniform float u_shadow_bias;
uniform vec3 u_color;

float shadow_factor(vec4 lpos) {
    vec3 p = lpos.xyz / lpos.w * 0.5 + 0.5;
    if (p.z >= 1.0 || p.x <= 0.0 || p.x >= 1.0 || p.y <= 0.0 || p.y >= 1.0) return 1.0;
    vec2 texel = 1.0 / vec2(textureSize(u_shadow_map, 0));
    float s = 0.0;
    for (int x = -1; x <= 1; ++x)
        for (int y = -1; y <= 1; ++y)
            s += texture(u_shadow_map, vec3(p.xy + vec2(x, y) * texel, p.z - u_shadow_bias));
    return s / 9.0;
}

vec3 shade(vec3 pos, vec3 nrm, vec4 lpos) {
    vec3 V = u_ortho == 1 ? u_view_back : normalize(u_eye - pos);
    vec3 N = normalize(nrm);
    if (dot(N, V) < 0.0) N = -N;                      // two-sided (inside views, open meshes)
    vec3 L;
    float atten = u_light_intensity;
    if (u_light_kind == 2) {
        L = -u_light_dir;
    } else {
        L = normalize(u_light_pos - pos);
        if (u_light_kind == 1) atten *= smoothstep(u_spot_cos, u_spot_cos + 0.03, dot(-L, u_light_dir));
    }
    if (u_shadows == 1) atten *= shadow_factor(lpos);
    float kd = max(dot(N, L), 0.0);
    vec3 H = normalize(L + V);
    float ks = kd > 0.0 ? pow(max(dot(N, H), 0.0), u_material.w) : 0.0;
    float kdh = max(dot(N, V), 0.0);
    float ksh = pow(kdh, u_material.w);
    vec3 c = u_color * (u_material.x + u_material.y * (atten * kd * u_light_color + u_headlight * kdh))
           + u_material.z * (atten * ks * u_light_color + u_headlight * ksh);
    return min(c, vec3(1.0));
}
"""

_SURFACE_OUT = """
uniform float u_opacity;
uniform int u_pass;             // 0 opaque, 1 weighted blended OIT, 2 flat colour
layout(location = 0) out vec4 out0;
layout(location = 1) out vec4 out1;
void write_colour(vec3 c) {
    if (u_pass == 2) { out0 = vec4(u_color, 1.0); out1 = vec4(0.0); return; }
    if (u_pass == 0) { out0 = vec4(c, 1.0); out1 = vec4(0.0); return; }
    // McGuire & Bavoil 2013, weight eq. (10); revealage accumulated as a sum of
    // -log(1 - a) so that one additive blend function serves both targets.
    float a = u_opacity;
    float z = gl_FragCoord.z;
    float w = clamp(a * max(1e-2, 3e3 * pow(1.0 - z, 3.0)), 1e-2, 3e3);
    out0 = vec4(c * a, a) * w;
    out1 = vec4(-log(max(1.0 - a, 1e-4)), 0.0, 0.0, 0.0);
}
"""

# Per-pixel (Phong-interpolated) lighting.
SURFACE_VS = """
#version 330
uniform mat4 u_vp;
uniform mat4 u_light_vp;
in vec3 in_pos;
in vec3 in_normal;
out vec3 v_pos;
out vec3 v_normal;
out vec4 v_lpos;
void main() {
    v_pos = in_pos;
    v_normal = in_normal;
    v_lpos = u_light_vp * vec4(in_pos, 1.0);
    gl_Position = u_vp * vec4(in_pos, 1.0);
}
"""

SURFACE_FS = "#version 330\n" + LIGHTING + _SURFACE_OUT + """
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_lpos;
void main() {
    if (u_pass == 2) { write_colour(u_color); return; }
    write_colour(shade(v_pos, v_normal, v_lpos));
}
"""

# Per-vertex (Gouraud) lighting: used automatically when the mesh's triangles are
# about pixel-sized or smaller, where it looks the same as per-pixel lighting but
# costs far less on software rasterisers (llvmpipe shades whole 4x4 blocks per
# tiny triangle).
SURFACE_VERTEX_VS = "#version 330\n" + LIGHTING + """
uniform mat4 u_vp;
uniform mat4 u_light_vp;
in vec3 in_pos;
in vec3 in_normal;
out vec3 v_color;
void main() {
    v_color = shade(in_pos, in_normal, u_light_vp * vec4(in_pos, 1.0));
    gl_Position = u_vp * vec4(in_pos, 1.0);
}
"""

SURFACE_VERTEX_FS = "#version 330\nuniform vec3 u_color;\n" + _SURFACE_OUT + """
in vec3 v_color;
void main() { write_colour(v_color); }
"""

DEPTH_VS = """
#version 330
uniform mat4 u_vp;
in vec3 in_pos;
void main() { gl_Position = u_vp * vec4(in_pos, 1.0); }
"""

DEPTH_FS = """
#version 330
void main() { }
"""

OIT_COMPOSITE_FS = """
#version 330
uniform sampler2D u_opaque;
uniform sampler2D u_accum;
uniform sampler2D u_reveal;
in vec2 v_uv;
out vec4 f_color;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec3 bg = texelFetch(u_opaque, p, 0).rgb;
    vec4 acc = texelFetch(u_accum, p, 0);
    float reveal = exp(-texelFetch(u_reveal, p, 0).r);
    vec3 avg = acc.rgb / max(acc.a, 1e-5);
    f_color = vec4(bg * reveal + avg * (1.0 - reveal), 1.0);
}
"""

FXAA_FS = """
#version 330
// FXAA (Lottes), the compact 'console' variant; the luma neighbourhood is read with
// texelFetch (unfiltered), filtered taps only on edges.
uniform sampler2D u_tex;
uniform vec2 u_inv;
in vec2 v_uv;
out vec4 f_color;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    ivec2 mx = textureSize(u_tex, 0) - 1;
    vec3 lw = vec3(0.299, 0.587, 0.114);
    vec3 rgbM = texelFetch(u_tex, p, 0).rgb;
    float lNW = dot(texelFetch(u_tex, clamp(p + ivec2(-1, -1), ivec2(0), mx), 0).rgb, lw);
    float lNE = dot(texelFetch(u_tex, clamp(p + ivec2(1, -1), ivec2(0), mx), 0).rgb, lw);
    float lSW = dot(texelFetch(u_tex, clamp(p + ivec2(-1, 1), ivec2(0), mx), 0).rgb, lw);
    float lSE = dot(texelFetch(u_tex, clamp(p + ivec2(1, 1), ivec2(0), mx), 0).rgb, lw);
    float lM = dot(rgbM, lw);
    float lMin = min(lM, min(min(lNW, lNE), min(lSW, lSE)));
    float lMax = max(lM, max(max(lNW, lNE), max(lSW, lSE)));
    if (lMax - lMin < max(0.0312, lMax * 0.125)) { f_color = vec4(rgbM, 1.0); return; }
    vec2 dir = vec2(-((lNW + lNE) - (lSW + lSE)), (lNW + lSW) - (lNE + lSE));
    float reduce = max((lNW + lNE + lSW + lSE) * (0.25 / 8.0), 1.0 / 128.0);
    float rcpMin = 1.0 / (min(abs(dir.x), abs(dir.y)) + reduce);
    dir = clamp(dir * rcpMin, vec2(-8.0), vec2(8.0)) * u_inv;
    vec3 rgbA = 0.5 * (texture(u_tex, v_uv + dir * (1.0 / 3.0 - 0.5)).rgb + texture(u_tex, v_uv + dir * (2.0 / 3.0 - 0.5)).rgb);
    vec3 rgbB = rgbA * 0.5 + 0.25 * (texture(u_tex, v_uv - dir * 0.5).rgb + texture(u_tex, v_uv + dir * 0.5).rgb);
    float lB = dot(rgbB, lw);
    f_color = vec4((lB < lMin || lB > lMax) ? rgbA : rgbB, 1.0);
}
"""

SLICE_VS = """
#version 330
uniform mat4 u_vp;
in vec3 in_pos;
in vec3 in_tex;
out vec3 v_tex;
void main() { v_tex = in_tex; gl_Position = u_vp * vec4(in_pos, 1.0); }
"""

SLICE_FS = """
#version 330
uniform sampler3D u_vol;
uniform vec2 u_window;   // normalised low, high
in vec3 v_tex;
layout(location = 0) out vec4 out0;
layout(location = 1) out vec4 out1;
void main() {
    float v = texture(u_vol, v_tex).r;
    float g = clamp((v - u_window.x) / max(u_window.y - u_window.x, 1e-6), 0.0, 1.0);
    out0 = vec4(vec3(g), 1.0);
    out1 = vec4(0.0);
}
"""

# Empty-space skipping by proxy geometry: the boundary faces of the occupied bricks
# (bricks where some value can be visible) are rasterised twice, keeping the nearest
# and the farthest depth per pixel; each ray then only samples between them. This
# keeps the sampling loop free of per-sample bookkeeping, which matters on SIMD
# software rasterisers (llvmpipe runs 8 rays in lock-step: a brick-walking loop with
# divergent exits measured 5x slower than a plain loop).
PROXY_VS = """
#version 330
uniform mat4 u_vp;
in vec3 in_pos;
void main() { gl_Position = u_vp * vec4(in_pos, 1.0); }
"""

# Ray casting in voxel-index space (voxel centres at integer coordinates).
RAYCAST_FS = """
#version 330
//DEFINES
uniform sampler3D u_vol;
uniform sampler2D u_tf;         // 1 x N RGBA, alpha already corrected for the step
uniform sampler2D u_depth;      // scene depth (surfaces), full resolution
uniform sampler2D u_near;       // proxy: nearest occupied-brick face depth
uniform sampler2D u_far;        // proxy: farthest occupied-brick face depth
uniform sampler3D u_grad;       // xyz = unit gradient (index space), w = edge weight
uniform mat4 u_inv_vp;
uniform mat4 u_world_to_vox;
uniform mat3 u_grad_to_world;
uniform mat3 u_vox_to_world;
uniform vec2 u_tf_scale;        // table lookup: x * v + y
uniform vec3 u_dims;
uniform vec3 u_crop_lo;
uniform vec3 u_crop_hi;
uniform int u_mode;             // 0 MIP, 1 MinIP, 2 DVR
uniform float u_step;           // voxels
uniform vec2 u_window;          // normalised low, high (MIP/MinIP)
uniform vec3 u_light_dir;       // world, towards the light
uniform float u_light_intensity;
uniform float u_headlight;
uniform vec4 u_material;
uniform int u_use_depth;
uniform int u_jitter;
uniform int u_skip;             // 1: use the proxy depths, 2: also the near one is valid
in vec2 v_uv;
out vec4 f_color;

vec3 unproject(vec2 ndc, float z) {
    vec4 p = u_inv_vp * vec4(ndc, z, 1.0);
    return (u_world_to_vox * vec4(p.xyz / p.w, 1.0)).xyz;
}

float sample_vol(vec3 p) { return texture(u_vol, (p + 0.5) / u_dims).r; }

void main() {
    vec2 ndc = v_uv * 2.0 - 1.0;
    vec3 o = unproject(ndc, -1.0);
    vec3 far_p = unproject(ndc, 1.0);
    vec3 d = far_p - o;
    float tmax_ray = length(d);
    d /= tmax_ray;
    if (u_use_depth == 1) {
        float zd = texture(u_depth, v_uv).r;
        if (zd < 1.0) tmax_ray = dot(unproject(ndc, zd * 2.0 - 1.0) - o, d);
    }
    vec3 invd = 1.0 / d;
    vec3 ta = (u_crop_lo - o) * invd, tb = (u_crop_hi - o) * invd;
    vec3 tmn = min(ta, tb), tmx = max(ta, tb);
    float t0 = max(max(tmn.x, tmn.y), max(tmn.z, 0.0));
    float t1 = min(min(tmx.x, tmx.y), min(tmx.z, tmax_ray));
    if (t1 <= t0) { f_color = vec4(0.0); return; }
    float best = u_mode == 1 ? 1.0 : 0.0;
    float tbox = t0;
    if (u_skip >= 1) {
        ivec2 px = ivec2(gl_FragCoord.xy);
        float zf = texelFetch(u_far, px, 0).r;
        if (zf <= 0.0) {
            t1 = -1.0;                                      // no occupied brick on this ray
        } else {
            t1 = min(t1, dot(unproject(ndc, zf * 2.0 - 1.0) - o, d) + 1.0);
            if (u_skip == 2) {
                float zn = texelFetch(u_near, px, 0).r;
                t0 = max(t0, dot(unproject(ndc, zn * 2.0 - 1.0) - o, d) - 1.0);
            }
        }
    }
    float jit = 0.5;
    if (u_jitter == 1) jit = fract(sin(dot(gl_FragCoord.xy, vec2(12.9898, 78.233))) * 43758.5453);
    // samples on the lattice t = box entry + (k + jitter) * step: skipping does not move them
    float t = tbox + (max(ceil((t0 - tbox) / u_step - jit), 0.0) + jit) * u_step;
    if (u_mode == 0) {
        for (; t < t1; t += u_step) best = max(best, sample_vol(o + d * t));
    } else if (u_mode == 1) {
        for (; t < t1; t += u_step) best = min(best, sample_vol(o + d * t));
    } else {
        vec4 acc = vec4(0.0);
        vec3 V = -normalize(u_vox_to_world * d);
        vec3 L = normalize(u_light_dir);
        vec3 H = normalize(L + V);
        float amb_dif = u_material.x + u_material.y;
        for (; t < t1; t += u_step) {
            vec3 q = o + d * t;
            float v = sample_vol(q);
            vec4 c = texture(u_tf, vec2(v * u_tf_scale.x + u_tf_scale.y, 0.5));
            if (c.a > 0.002) {
                vec3 col = c.rgb * amb_dif;
#ifdef SHADING
                // precomputed gradient (one fetch instead of six central differences)
                vec4 gt = texture(u_grad, (q + 0.5) / u_dims);
                if (gt.w > 0.02) {                           // homogeneous regions: unlit colour
                    vec3 N = normalize(u_grad_to_world * gt.xyz);
                    if (dot(N, V) < 0.0) N = -N;
                    float kd = max(dot(N, L), 0.0), kdh = max(dot(N, V), 0.0);
                    float ks = kd > 0.0 ? pow(max(dot(N, H), 0.0), u_material.w) : 0.0;
                    float kh2 = kdh * kdh;
                    vec3 lit = c.rgb * (u_material.x + u_material.y * (u_light_intensity * kd + u_headlight * kdh))
                             + u_material.z * (u_light_intensity * ks + u_headlight * kh2 * kh2);
                    col = mix(col, lit, gt.w);
                }
#endif
                acc.rgb += (1.0 - acc.a) * c.a * min(col, vec3(1.0));
                acc.a += (1.0 - acc.a) * c.a;
                if (acc.a > 0.95) break;                     // early ray termination
            }
        }
        f_color = acc;
        return;
    }
    float gv = clamp((best - u_window.x) / max(u_window.y - u_window.x, 1e-6), 0.0, 1.0);
    f_color = vec4(vec3(gv), 1.0);
}
"""

VOLUME_COMPOSITE_FS = """
#version 330
uniform sampler2D u_scene;
uniform sampler2D u_vol;        // premultiplied RGBA (possibly lower resolution)
in vec2 v_uv;
out vec4 f_color;
void main() {
    vec3 s = texelFetch(u_scene, ivec2(gl_FragCoord.xy), 0).rgb;
    vec4 v = texture(u_vol, v_uv);
    f_color = vec4(v.rgb + (1.0 - v.a) * s, 1.0);
}
"""
