// Tone mapping (see tonemap.rs for the formulas): exposure, then linear + gamma
// (seed 001), Drago's adaptive logarithmic mapping (seed 000 §5), or the
// photographic operator (key from the absolute adaptation luminance, filmic curve).
// The HDR pixel's radiance is rgb · alpha (alpha: transmittance of the glass in front).

struct Tone {
    exposure: f32,       // 2^stops
    gamma: f32,
    mode: u32,           // 0 linear, 1 Drago, 2 photographic
    srgb_target: u32,    // 1: the target encodes sRGB itself; output linear
    drago: vec4<f32>,    // x bias, y L_dmax
};

// [0] adapted log-average luminance, [1] adapted maximum, [2] target log-average, [3] target maximum,
// [4] adapted 99th percentile, [5] target 99th percentile.
struct Adaptation {
    values: array<f32, 6>,
};

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

@group(0) @binding(0) var hdr_in: texture_2d<f32>;
@group(0) @binding(1) var<storage, read> adapted: Adaptation;
@group(0) @binding(2) var<uniform> tone: Tone;

@vertex
fn vs_fullscreen(@builtin(vertex_index) index: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

fn srgb_to_linear(x: vec3<f32>) -> vec3<f32> {
    let low = x / 12.92;
    let high = pow((x + 0.055) / 1.055, vec3<f32>(2.4));
    return select(high, low, x <= vec3<f32>(0.04045));
}

fn drago(c: vec3<f32>) -> vec3<f32> {
    let scale = tone.exposure / max(adapted.values[0], 1e-20);
    let y = luminance(c) * scale;
    let y_max = max(adapted.values[1] * scale, 1e-6);
    let exponent = log(tone.drago.x) / log(0.5);
    let l_d = (tone.drago.y / 100.0) / (log(y_max + 1.0) / log(10.0)) * log(y + 1.0) / log(2.0 + 8.0 * pow(y / y_max, exponent));
    var ratio = 0.0;
    if (y > 0.0) {
        ratio = l_d / y;
    }
    return c * scale * ratio;
}

// Key value from the absolute adaptation luminance (Krawczyk et al. 2005).
fn photographic_key(l_a: f32) -> f32 {
    return 1.03 - 2.0 / (2.0 + log(l_a + 1.0) / log(10.0));
}

// ACES filmic fit (Narkowicz 2015), per channel.
fn filmic(x: vec3<f32>) -> vec3<f32> {
    return (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14);
}

// Filmic input the brightest 1% may reach before the exposure is lowered for
// them (filmic(5) = 0.985: just short of white).
const HIGHLIGHT: f32 = 5.0;

fn photographic(c: vec3<f32>) -> vec3<f32> {
    let l_a = max(adapted.values[0], 1e-20);
    let scale = photographic_key(l_a) / l_a;
    // Highlight guard: sunlit patches in a dim room would clip at the key's exposure.
    let guard = min(1.0, HIGHLIGHT / max(adapted.values[4] * scale, 1e-20));
    return filmic(c * (tone.exposure * scale * guard));
}

@fragment
fn fs_tonemap(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    let p = textureLoad(hdr_in, vec2<i32>(position.xy), 0);
    let c = max(p.rgb * p.a, vec3<f32>(0.0));
    var mapped: vec3<f32>;
    if (tone.mode == 1u) {
        mapped = drago(c);
    } else if (tone.mode == 2u) {
        mapped = photographic(c);
    } else {
        mapped = c * tone.exposure;
    }
    var display = pow(clamp(mapped, vec3<f32>(0.0), vec3<f32>(1.0)), vec3<f32>(1.0 / tone.gamma));
    if (tone.srgb_target == 1u) {
        display = srgb_to_linear(display);
    }
    return vec4<f32>(display, 1.0);
}
