// Texel mode (view::scene::LightmapScene), appended to shading.wgsl: the
// opaque draws take their sky light from the texels instead of the vertices.
// The texture holds each texel's irradiance E = Σ_i L_i t_i (the vertex
// shader's dot product, done per texel on the CPU), A = 1 where the texel
// holds light. A fragment reads the four texels around it bilinearly, over
// those that hold light only: charts are packed 2 texels apart, so the
// reads never mix two charts, and a chart's rim needs no dilated copy.
// With sun bits per texel (TEXEL_SUN, a constant the renderer appends), A
// is 1 plus the texel's sunlit share at the frame's step (its bit, or its
// stored fraction): A − 1 read bilinearly over the same texels is the
// fragment's sun visibility, times its own cosine, so a slat's shadow edge
// is drawn at the texel size, not the triangle's (inside a texel, with
// fractions).
// With side shares per texel (TEXEL_SIDES, also appended), the sky light is
// scaled by the seen side's share, read bilinearly over the same texels.
// With the sun's bits on an atlas of their own (SUN_ATLAS, appended too;
// section TSAT: finer texels than the transfer's), the sunlit share comes
// from a second texture (binding 2, R = 1 + share, 0 off its texels) at the
// second atlas position, read bilinearly over its own texels alike.
// Without them the sun term is per vertex, as in shading.wgsl. A bundle with
// texel sun bits but no texel transfer (TEXEL_SKY false, also a constant the
// renderer appends) keeps the sky term per vertex.

@group(1) @binding(0) var lightmap: texture_2d<f32>;
// R: each texel's front share (1 without TEXEL_SIDES).
@group(1) @binding(1) var side_shares: texture_2d<f32>;
// R: 1 + the sunlit share on the sun's own atlas, 0 off its texels (1 × 1 without SUN_ATLAS).
@group(1) @binding(2) var sun_texels: texture_2d<f32>;

struct LightmapOut {
    @builtin(position) clip: vec4<f32>,
    // The per-vertex sun term (without texel sun bits) plus the per-vertex
    // sky term (without texel transfer), of the triangle's front and back.
    @location(0) vertex_light: vec3<f32>,
    @location(5) vertex_light_back: vec3<f32>,
    @location(1) albedo: vec3<f32>,
    // Position in the atlas, texels (xy), and in the sun's own atlas (zw).
    @location(2) texcoord: vec4<f32>,
    @location(3) normal: vec3<f32>,
    @location(4) position: vec3<f32>,
};

@vertex
fn vs_lightmap(v: VertexIn, @location(4) texcoord: vec4<f32>) -> LightmapOut {
    var out: LightmapOut;
    out.clip = frame.view_proj * vec4<f32>(v.position, 1.0);
    out.vertex_light = vec3<f32>(0.0);
    out.vertex_light_back = vec3<f32>(0.0);
    if (!TEXEL_SUN) {
        out.vertex_light += sun_light(v);
        out.vertex_light_back += sun_light(v);
    }
    if (!TEXEL_SKY) {
        let sky = sky_dot(v);
        let share = vertex_front_share(v);
        out.vertex_light += side_share(share, true) * sky;
        out.vertex_light_back += side_share(share, false) * sky;
    }
    out.albedo = v.albedo;
    out.texcoord = texcoord;
    out.normal = v.normal;
    out.position = v.position;
    return out;
}

// The sunlit share at `texcoord` on the sun's own atlas: bilinear over the
// four texels around it that are covered (R ≥ 1), as the transfer's.
fn own_atlas_sun(texcoord: vec2<f32>) -> f32 {
    let size = vec2<i32>(textureDimensions(sun_texels));
    let p = texcoord - vec2<f32>(0.5);
    let corner = vec2<i32>(floor(p));
    let f = p - floor(p);
    var sun_sum = 0.0;
    var weight = 0.0;
    for (var dy = 0; dy < 2; dy++) {
        for (var dx = 0; dx < 2; dx++) {
            let texel = clamp(corner + vec2<i32>(dx, dy), vec2<i32>(0), size - vec2<i32>(1));
            let w = select(1.0 - f.x, f.x, dx == 1) * select(1.0 - f.y, f.y, dy == 1);
            let s = textureLoad(sun_texels, texel, 0).r;
            let holds = min(s, 1.0);
            sun_sum += w * max(s - 1.0, 0.0);
            weight += w * holds;
        }
    }
    if (weight > 1e-6) {
        return sun_sum / weight;
    }
    let texel = clamp(vec2<i32>(floor(texcoord)), vec2<i32>(0), size - vec2<i32>(1));
    return max(textureLoad(sun_texels, texel, 0).r - 1.0, 0.0);
}

@fragment
fn fs_lightmap(in: LightmapOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    let size = vec2<i32>(textureDimensions(lightmap));
    // Texel (x, y) covers [x, x+1) × [y, y+1): its centre is at +0.5.
    let p = in.texcoord.xy - vec2<f32>(0.5);
    let corner = vec2<i32>(floor(p));
    let f = p - floor(p);
    var sum = vec3<f32>(0.0);
    var sun_sum = 0.0;
    var share_sum = 0.0;
    var weight = 0.0;
    for (var dy = 0; dy < 2; dy++) {
        for (var dx = 0; dx < 2; dx++) {
            let texel = clamp(corner + vec2<i32>(dx, dy), vec2<i32>(0), size - vec2<i32>(1));
            let w = select(1.0 - f.x, f.x, dx == 1) * select(1.0 - f.y, f.y, dy == 1);
            let s = textureLoad(lightmap, texel, 0);
            let holds = min(s.a, 1.0);
            sum += w * holds * s.rgb;
            sun_sum += w * max(s.a - 1.0, 0.0);
            share_sum += w * holds * textureLoad(side_shares, texel, 0).r;
            weight += w * holds;
        }
    }
    var e = vec3<f32>(0.0);
    var visibility = 0.0;
    var share = 1.0;
    if (weight > 1e-6) {
        e = sum / weight;
        visibility = sun_sum / weight;
        share = share_sum / weight;
    } else {
        // No neighbour holds light: the texel under the fragment, whatever it holds.
        let texel = clamp(vec2<i32>(floor(in.texcoord.xy)), vec2<i32>(0), size - vec2<i32>(1));
        let s = textureLoad(lightmap, texel, 0);
        e = s.rgb;
        visibility = max(s.a - 1.0, 0.0);
        share = textureLoad(side_shares, texel, 0).r;
    }
    var light = select(in.vertex_light_back, in.vertex_light, front);
    if (TEXEL_SKY) {
        if (TEXEL_SIDES) {
            e *= select(1.0 - share, share, front);
        }
        light += e;
    }
    if (SUN_ATLAS) {
        visibility = own_atlas_sun(in.texcoord.zw);
    }
    if (TEXEL_SUN) {
        light += visibility * sun_cosine(normalize(in.normal), in.position) * frame.sun_rgb.xyz / PI;
    }
    return vec4<f32>(in.albedo * light, 1.0);
}
