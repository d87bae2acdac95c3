// The backdrop (see backdrop.rs): a full-screen triangle at the far plane,
// drawn after the geometry with depth test "less or equal", so it fills only
// the pixels no geometry covers. Per pixel: the view ray's direction, turned
// into the environment's frame (Rᵀ·d), then the env map (bilinear between
// texel centres) or the Preetham sky (+ the sun disc), clamped to the HDR
// target's largest value. Alpha 1: nothing in front attenuates it (glass
// lowers alpha later, see shading.wgsl).

const PI: f32 = 3.14159265358979;
const HDR_MAX: f32 = 65504.0;

struct Backdrop {
    forward: vec4<f32>,
    right: vec4<f32>,           // camera right · tan(fov/2) · aspect
    up: vec4<f32>,              // camera up · tan(fov/2)
    rotation: array<vec4<f32>, 3>, // columns of R
    mode: vec4<u32>,            // x: 0 black, 1 env map, 2 sky; y, z: env map width, height
    perez: array<vec4<f32>, 6>, // Y, x, y: [A B C D] [E scale _ _]
    sun: vec4<f32>,             // toward the sun (sky frame), w: cos of the disc radius
    zenith: vec4<f32>,          // zenith (sky frame), w: radiance scale
    disc: vec4<f32>,            // disc radiance (scaled)
};

@group(0) @binding(0) var<uniform> bd: Backdrop;
@group(0) @binding(1) var env: texture_2d<f32>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) ndc: vec2<f32>,
};

@vertex
fn vs_backdrop(@builtin(vertex_index) index: u32) -> VertexOut {
    let uv = vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u));
    let ndc = uv * 2.0 - 1.0;
    var out: VertexOut;
    out.clip = vec4<f32>(ndc, 1.0, 1.0);
    out.ndc = ndc;
    return out;
}

fn texel(col: i32, row: i32) -> vec3<f32> {
    let w = i32(bd.mode.y);
    let h = i32(bd.mode.z);
    return textureLoad(env, vec2<i32>(((col % w) + w) % w, clamp(row, 0, h - 1)), 0).rgb;
}

fn env_radiance(d: vec3<f32>) -> vec3<f32> {
    let size = vec2<f32>(f32(bd.mode.y), f32(bd.mode.z));
    let v = acos(clamp(d.y, -1.0, 1.0)) / PI;
    let u = fract(atan2(d.x, -d.z) / (2.0 * PI) + 0.5);
    let p = vec2<f32>(u, v) * size - 0.5;
    let f = floor(p);
    let t = p - f;
    let c = vec2<i32>(f);
    let top = mix(texel(c.x, c.y), texel(c.x + 1, c.y), t.x);
    let bottom = mix(texel(c.x, c.y + 1), texel(c.x + 1, c.y + 1), t.x);
    return mix(top, bottom, t.y);
}

fn perez(k: u32, cos_theta: f32, gamma: f32, cos_gamma: f32) -> f32 {
    let p = bd.perez[2u * k];
    let q = bd.perez[2u * k + 1u];
    return q.y * (1.0 + p.x * exp(p.y / cos_theta)) * (1.0 + p.z * exp(p.w * gamma) + q.x * cos_gamma * cos_gamma);
}

fn sky_radiance(d: vec3<f32>) -> vec3<f32> {
    var rgb = vec3<f32>(0.0);
    let cos_theta = dot(d, bd.zenith.xyz);
    let cos_gamma = clamp(dot(d, bd.sun.xyz), -1.0, 1.0);
    if (cos_theta > 0.0) {
        let gamma = acos(cos_gamma);
        let luminance = perez(0u, cos_theta, gamma, cos_gamma);
        let x = perez(1u, cos_theta, gamma, cos_gamma);
        let y = perez(2u, cos_theta, gamma, cos_gamma);
        if (y > 0.0 && luminance > 0.0) {
            let xyz = vec3<f32>(x / y * luminance, luminance, max(1.0 - x - y, 0.0) / y * luminance);
            // CIE XYZ → linear sRGB (columns; the sky module's matrix).
            let m = mat3x3<f32>(
                vec3<f32>(3.2404542, -0.9692660, 0.0556434),
                vec3<f32>(-1.5371385, 1.8760108, -0.2040259),
                vec3<f32>(-0.4985314, 0.0415560, 1.0572252),
            );
            rgb = max(m * xyz, vec3<f32>(0.0)) * bd.zenith.w;
        }
    }
    if (cos_gamma >= bd.sun.w) {
        rgb += bd.disc.rgb;
    }
    return rgb;
}

@fragment
fn fs_backdrop(in: VertexOut) -> @location(0) vec4<f32> {
    let world = normalize(bd.forward.xyz + in.ndc.x * bd.right.xyz + in.ndc.y * bd.up.xyz);
    let d = normalize(vec3<f32>(dot(bd.rotation[0].xyz, world), dot(bd.rotation[1].xyz, world), dot(bd.rotation[2].xyz, world)));
    var rgb = vec3<f32>(0.0);
    if (bd.mode.x == 1u) {
        rgb = env_radiance(d);
    } else if (bd.mode.x == 2u) {
        rgb = sky_radiance(d);
    }
    return vec4<f32>(min(rgb, vec3<f32>(HDR_MAX)), 1.0);
}
