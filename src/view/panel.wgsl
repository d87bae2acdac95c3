// The LCD panel (view::panel), appended to shading.wgsl: the final-gathered
// reflected radiance of the texel under the fragment (nearest texel, as
// PanelTexture::at on the CPU), in the PRT shading's units.

@group(1) @binding(0) var panel_texture: texture_2d<f32>;

struct PanelOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) light: vec3<f32>,
    @location(1) albedo: vec3<f32>,
    // [0,1]² over the panel's texel grid, row 0 at the top.
    @location(2) texcoord: vec2<f32>,
};

@vertex
fn vs_panel(v: VertexIn, @location(4) texcoord: vec2<f32>) -> PanelOut {
    let shaded = shade_vertex(v);
    var out: PanelOut;
    out.clip = shaded.clip;
    out.light = shaded.light;
    out.albedo = shaded.albedo;
    out.texcoord = texcoord;
    return out;
}

@fragment
fn fs_panel(in: PanelOut) -> @location(0) vec4<f32> {
    let size = vec2<i32>(textureDimensions(panel_texture));
    let texel = clamp(vec2<i32>(floor(in.texcoord * vec2<f32>(size))), vec2<i32>(0), size - vec2<i32>(1));
    // The gathered radiance is everything the panel reflects toward the eye
    // (its BRDF's diffuse haze included), as `prtbake panel` reports it; the
    // PRT shading albedo · E stands in only until the first pass lands.
    let reflected = textureLoad(panel_texture, texel, 0).rgb;
    return vec4<f32>(reflected, 1.0);
}
