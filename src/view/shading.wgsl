// Per-vertex PRT shading (seeds 000 §4.2, 001 §4).
//
// Vertex: E = k · Σ_i L_i t_i(v)  +  bit(v, step) · max(n_seen·s, 0) · sun_rgb / π
// (n_seen: the normal turned toward the eye, the side of the surface the eye sees;
// k: the share of the transfer of the side the fragment shows, by its
// triangle's winding as the bake tells sides: the vertex's front share or
// the rest; 1 without shares)
// Fragment: radiance = albedo · E, written to an HDR target; alpha is the transmittance
// of the glass in front (1 here; the glass pass lowers it).

const PI: f32 = 3.14159265358979;
const MAX_COEFFS: u32 = 256u;

struct Frame {
    view_proj: mat4x4<f32>,
    // xyz: unit direction toward the sun; w unused.
    sun_dir: vec4<f32>,
    // rgb: sun irradiance; w: 1 = sun term on.
    sun_rgb: vec4<f32>,
    // x: coefficients per channel (order²), y: channels (1 or 3),
    // z: mask words per vertex, w: time-lapse step.
    counts: vec4<u32>,
    // xyz: the eye, world units; w: 1 = `front_shares` holds each vertex's front share.
    eye: vec4<f32>,
    // Lighting SH, rgb per coefficient, index l(l+1)+m.
    sh: array<vec4<f32>, MAX_COEFFS>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
// [vertex][channel][coeff], f32.
@group(0) @binding(1) var<storage, read> transfer: array<f32>;
// Sun bits: step k of vertex v is bit k%32 of word v·W + k/32.
@group(0) @binding(2) var<storage, read> masks: array<u32>;
// Window mode: per vertex, the share of its light that reached its front side.
@group(0) @binding(3) var<storage, read> front_shares: array<f32>;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) albedo: vec3<f32>,
    @location(3) source: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    // E of the triangle's front (the side its winding faces) and of its back.
    @location(0) light: vec3<f32>,
    @location(1) albedo: vec3<f32>,
    @location(2) light_back: vec3<f32>,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    return shade_vertex(v);
}

// The PRT shading of a vertex (also the panel's, panel.wgsl).
fn shade_vertex(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = frame.view_proj * vec4<f32>(v.position, 1.0);
    let sky = sky_dot(v);
    let sun = sun_light(v);
    let share = vertex_front_share(v);
    out.light = side_share(share, true) * sky + sun;
    out.light_back = side_share(share, false) * sky + sun;
    out.albedo = v.albedo;
    return out;
}

// A vertex's front share (1 when the bundle has none: frame.eye.w = 0).
fn vertex_front_share(v: VertexIn) -> f32 {
    if (frame.eye.w > 0.5) {
        return front_shares[v.source];
    }
    return 1.0;
}

// The share of a receiver's light on one side of its surface: the front
// share on the front (the side the winding faces), the rest on the back;
// all of it when the bundle keeps no sides.
fn side_share(front_share: f32, front: bool) -> f32 {
    if (frame.eye.w < 0.5) {
        return 1.0;
    }
    return select(1.0 - front_share, front_share, front);
}

// A vertex's transfer dotted with the lighting SH.
fn sky_dot(v: VertexIn) -> vec3<f32> {
    let n2 = frame.counts.x;
    let channels = frame.counts.y;
    let base = v.source * channels * n2;
    var light = vec3<f32>(0.0);
    if (channels == 3u) {
        for (var i = 0u; i < n2; i++) {
            let t = vec3<f32>(transfer[base + i], transfer[base + n2 + i], transfer[base + 2u * n2 + i]);
            light += t * frame.sh[i].xyz;
        }
    } else {
        for (var i = 0u; i < n2; i++) {
            light += transfer[base + i] * frame.sh[i].xyz;
        }
    }
    return light;
}

// The sun term of a vertex: its bit of the time-lapse step times the cosine
// and the sun's irradiance over π (zero when the sun is off).
fn sun_light(v: VertexIn) -> vec3<f32> {
    if (frame.sun_rgb.w < 0.5) {
        return vec3<f32>(0.0);
    }
    let step = frame.counts.w;
    let word = masks[v.source * frame.counts.z + step / 32u];
    let bit = (word >> (step % 32u)) & 1u;
    return f32(bit) * sun_cosine(v.normal, v.position) * frame.sun_rgb.xyz / PI;
}

// The sun's cosine on the side of a surface (normal n, at p) that the eye
// sees: a wall lit by the sun on its outer face is dark from inside, whatever
// its normal's direction (window-mode bits are for either side); 0 when no
// step is shown.
fn sun_cosine(n: vec3<f32>, p: vec3<f32>) -> f32 {
    if (frame.sun_rgb.w < 0.5) {
        return 0.0;
    }
    let seen = select(-n, n, dot(n, frame.eye.xyz - p) >= 0.0);
    return max(dot(seen, frame.sun_dir.xyz), 0.0);
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    return vec4<f32>(in.albedo * select(in.light_back, in.light, front), 1.0);
}

// Window glass (drawn after the backdrop, depth test "less", no depth write):
// it adds nothing and lets τ of what is behind it through. It writes only
// alpha with a "min" blend, so the HDR pixel's alpha is the smallest τ of the
// glass in front of it and the tone-mapping pass scales the colour by it:
// coincident twin panes (double-sided CAD glass) do not square τ, as a ray
// through a window counts τ once in the bake. For glass copies the vertex
// albedo holds (τ, τ, τ).
struct GlassOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) transmittance: f32,
};

@vertex
fn vs_glass(v: VertexIn) -> GlassOut {
    var out: GlassOut;
    out.clip = frame.view_proj * vec4<f32>(v.position, 1.0);
    out.transmittance = v.albedo.x;
    return out;
}

@fragment
fn fs_glass(in: GlassOut) -> @location(0) vec4<f32> {
    return vec4<f32>(0.0, 0.0, 0.0, in.transmittance);
}
