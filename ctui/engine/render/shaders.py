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

SURFACE_FS = """
#version 330
uniform vec3 u_color;
uniform float u_opacity;
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
uniform int u_pass;             // 0 opaque, 1 weighted blended OIT, 2 flat colour
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_lpos;
layout(location = 0) out vec4 out0;
layout(location = 1) out vec4 out1;

float shadow_factor() {
    vec3 p = v_lpos.xyz / v_lpos.w * 0.5 + 0.5;
    if (p.z >= 1.0 || p.x <= 0.0 || p.x >= 1.0 || p.y <= 0.0 || p.y >= 1.0) return 1.0;
    vec2 texel = 1.0 / vec2(textureSize(u_shadow_map, 0));
    float s = 0.0;
    for (int x = -1; x <= 1; ++x)
        for (int y = -1; y <= 1; ++y)
            s += texture(u_shadow_map, vec3(p.xy + vec2(x, y) * texel, p.z - u_shadow_bias));
    return s / 9.0;
}

void main() {
    if (u_pass == 2) { out0 = vec4(u_color, 1.0); out1 = vec4(0.0); return; }
    vec3 V = u_ortho == 1 ? u_view_back : normalize(u_eye - v_pos);
    vec3 N = normalize(v_normal);
    if (dot(N, V) < 0.0) N = -N;                      // two-sided (inside views, open meshes)
    vec3 L;
    float atten = u_light_intensity;
    if (u_light_kind == 2) {
        L = -u_light_dir;
    } else {
        L = normalize(u_light_pos - v_pos);
        if (u_light_kind == 1) atten *= smoothstep(u_spot_cos, u_spot_cos + 0.03, dot(-L, u_light_dir));
    }
    if (u_shadows == 1) atten *= shadow_factor();
    float kd = max(dot(N, L), 0.0);
    vec3 H = normalize(L + V);
    float ks = kd > 0.0 ? pow(max(dot(N, H), 0.0), u_material.w) : 0.0;
    float kdh = max(dot(N, V), 0.0);
    float ksh = pow(kdh, u_material.w);
    vec3 c = u_color * (u_material.x + u_material.y * (atten * kd * u_light_color + u_headlight * kdh))
           + u_material.z * (atten * ks * u_light_color + u_headlight * ksh);
    c = min(c, vec3(1.0));
    if (u_pass == 0) {
        out0 = vec4(c, 1.0);
        out1 = vec4(0.0);
    } else {
        // McGuire & Bavoil 2013, weight eq. (10); revealage accumulated as a sum of
        // -log(1 - a) so that one additive blend function serves both targets.
        float a = u_opacity;
        float z = gl_FragCoord.z;
        float w = clamp(a * max(1e-2, 3e3 * pow(1.0 - z, 3.0)), 1e-2, 3e3);
        out0 = vec4(c * a, a) * w;
        out1 = vec4(-log(max(1.0 - a, 1e-4)), 0.0, 0.0, 0.0);
    }
}
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
// FXAA (Lottes), the compact 'console' variant.
uniform sampler2D u_tex;
uniform vec2 u_inv;
in vec2 v_uv;
out vec4 f_color;
void main() {
    vec3 lw = vec3(0.299, 0.587, 0.114);
    vec3 rgbM = texture(u_tex, v_uv).rgb;
    vec3 rgbNW = texture(u_tex, v_uv + vec2(-1.0, -1.0) * u_inv).rgb;
    vec3 rgbNE = texture(u_tex, v_uv + vec2(1.0, -1.0) * u_inv).rgb;
    vec3 rgbSW = texture(u_tex, v_uv + vec2(-1.0, 1.0) * u_inv).rgb;
    vec3 rgbSE = texture(u_tex, v_uv + vec2(1.0, 1.0) * u_inv).rgb;
    float lM = dot(rgbM, lw), lNW = dot(rgbNW, lw), lNE = dot(rgbNE, lw), lSW = dot(rgbSW, lw), lSE = dot(rgbSE, lw);
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

# Ray casting in voxel-index space (voxel centres at integer coordinates). The outer
# loop walks the brick grid (empty-space skipping: a brick is skipped when its
# occupancy says no visible value can occur in it (DVR), or when its maximum cannot
# raise the running maximum (MIP) / its minimum cannot lower the running minimum
# (MinIP)); the inner loop samples inside one brick.
RAYCAST_FS = """
#version 330
uniform sampler3D u_vol;
uniform sampler3D u_bricks;     // rg = min, max of the brick (1-voxel apron), b = DVR occupancy
uniform sampler2D u_tf;         // 1 x N RGBA
uniform sampler2D u_depth;      // scene depth (surfaces), full resolution
uniform mat4 u_inv_vp;
uniform mat4 u_world_to_vox;
uniform mat3 u_grad_to_world;
uniform mat3 u_vox_to_world;
uniform vec2 u_tf_scale;       // table lookup: x * v + y
uniform vec3 u_dims;
uniform vec3 u_crop_lo;
uniform vec3 u_crop_hi;
uniform float u_brick;
uniform ivec3 u_nbricks;
uniform int u_mode;             // 0 MIP, 1 MinIP, 2 DVR
uniform float u_step;           // voxels
uniform vec2 u_window;          // normalised low, high (MIP/MinIP)
uniform int u_shading;
uniform vec3 u_light_dir;       // world, towards the light
uniform float u_light_intensity;
uniform float u_headlight;
uniform vec4 u_material;
uniform int u_use_depth;
uniform int u_jitter;
uniform int u_skip;
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

    float jit = 0.5;
    if (u_jitter == 1) jit = fract(sin(dot(gl_FragCoord.xy, vec2(12.9898, 78.233))) * 43758.5453);
    float t = t0 + u_step * jit;
    float best = u_mode == 1 ? 1.0 : 0.0;
    vec4 acc = vec4(0.0);
    vec3 V = -normalize(u_vox_to_world * d);
    vec3 L = normalize(u_light_dir);
    vec3 H = normalize(L + V);
    int guard = 0;
    while (t < t1 && guard < 100000) {
        vec3 p = o + d * t;
        vec3 bc = clamp(floor((p + 0.5) / u_brick), vec3(0.0), vec3(u_nbricks - 1));
        vec4 b = texelFetch(u_bricks, ivec3(bc), 0);
        vec3 blo = bc * u_brick - 0.5, bhi = blo + u_brick;
        vec3 te = ((mix(blo, bhi, step(0.0, d))) - o) * invd;
        float texit = min(min(te.x, te.y), min(te.z, t1));
        bool skip = u_skip == 1 && ((u_mode == 0 && b.g <= best) || (u_mode == 1 && b.r >= best) || (u_mode == 2 && b.b < 0.5));
        if (skip) {
            // keep samples on the ray's regular lattice
            t += max(ceil((texit - t) / u_step), 1.0) * u_step;
            guard++;
            continue;
        }
        for (; t < texit && guard < 100000; t += u_step) {
            guard++;
            vec3 q = o + d * t;
            float v = sample_vol(q);
            if (u_mode == 0) { best = max(best, v); }
            else if (u_mode == 1) { best = min(best, v); }
            else {
                vec4 c = texture(u_tf, vec2(v * u_tf_scale.x + u_tf_scale.y, 0.5));
                if (c.a > 0.001) {
                    float a = 1.0 - pow(1.0 - min(c.a, 0.999), u_step);
                    vec3 col = c.rgb;
                    if (u_shading == 1) {
                        vec3 g = vec3(sample_vol(q + vec3(1, 0, 0)) - sample_vol(q - vec3(1, 0, 0)),
                                      sample_vol(q + vec3(0, 1, 0)) - sample_vol(q - vec3(0, 1, 0)),
                                      sample_vol(q + vec3(0, 0, 1)) - sample_vol(q - vec3(0, 0, 1)));
                        vec3 gw = u_grad_to_world * g;
                        float gl = length(gw);
                        if (gl > 1e-5) {
                            vec3 N = -gw / gl;
                            if (dot(N, V) < 0.0) N = -N;
                            float kd = max(dot(N, L), 0.0), kdh = max(dot(N, V), 0.0);
                            float ks = kd > 0.0 ? pow(max(dot(N, H), 0.0), u_material.w) : 0.0;
                            float ksh = pow(kdh, u_material.w);
                            float lit_w = clamp(gl * 40.0, 0.0, 1.0);
                            vec3 lit = col * (u_material.x + u_material.y * (u_light_intensity * kd + u_headlight * kdh))
                                     + u_material.z * (u_light_intensity * ks + u_headlight * ksh);
                            col = mix(col * (u_material.x + u_material.y), lit, lit_w);
                        }
                    }
                    acc.rgb += (1.0 - acc.a) * a * min(col, vec3(1.0));
                    acc.a += (1.0 - acc.a) * a;
                    if (acc.a > 0.985) { t1 = -1.0; break; }   // early ray termination
                }
            }
        }
    }
    if (u_mode == 2) { f_color = acc; return; }
    float g = clamp((best - u_window.x) / max(u_window.y - u_window.x, 1e-6), 0.0, 1.0);
    f_color = vec4(vec3(g), 1.0);
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
