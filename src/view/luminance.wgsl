// Luminance pass for the adaptive operators (see tonemap.rs): log-average,
// maximum and 99th-percentile luminance of the HDR frame (geometry, backdrop and what is seen
// through glass: radiance rgb · alpha; pixels of zero radiance left out) on a
// GRID×GRID point-sampled grid (the
// "low-resolution pass" of seed 000 §4.2), then temporal adaptation.

const GRID: u32 = 128u;
const THREADS: u32 = 256u;
const FLOOR: f32 = 1e-4;
// Histogram of log2(L / L_max) for the percentile: BINS bins of 1/BINS_PER_STOP stop below the maximum.
const BINS: u32 = 96u;
const BINS_PER_STOP: f32 = 4.0;


struct AdaptParams {
    dt: f32,
    tau_brighten: f32,
    tau_darken: f32,
    reset: u32,
};

// [0] adapted log-average luminance, [1] adapted maximum, [2] target log-average, [3] target maximum,
// [4] adapted 99th percentile, [5] target 99th percentile.
struct Adaptation {
    values: array<f32, 6>,
};

@group(0) @binding(0) var hdr: texture_2d<f32>;
@group(0) @binding(1) var<storage, read_write> adaptation: Adaptation;
@group(0) @binding(2) var<uniform> adapt: AdaptParams;

var<workgroup> partial_max: array<f32, THREADS>;
var<workgroup> partial_log: array<f32, THREADS>;
var<workgroup> partial_count: array<f32, THREADS>;
var<workgroup> histogram: array<atomic<u32>, BINS>;

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

// Luminance of grid point j.
fn grid_sample(j: u32, dims: vec2<u32>) -> f32 {
    let g = vec2<u32>(j % GRID, j / GRID);
    let p = vec2<u32>((vec2<f32>(g) + 0.5) * vec2<f32>(dims) / f32(GRID));
    let c = textureLoad(hdr, min(p, dims - 1u), 0);
    return luminance(max(c.rgb * c.a, vec3<f32>(0.0)));
}

@compute @workgroup_size(256)
fn cs_luminance(@builtin(local_invocation_index) i: u32) {
    let dims = textureDimensions(hdr);
    let per_thread = GRID * GRID / THREADS;
    // Maximum first: dark pixels are floored relative to it.
    var m = 0.0;
    for (var s = 0u; s < per_thread; s++) {
        m = max(m, grid_sample(i * per_thread + s, dims));
    }
    partial_max[i] = m;
    workgroupBarrier();
    for (var stride = THREADS / 2u; stride > 0u; stride /= 2u) {
        if (i < stride) {
            partial_max[i] = max(partial_max[i], partial_max[i + stride]);
        }
        workgroupBarrier();
    }
    let frame_max = partial_max[0];
    let floor_l = max(frame_max * FLOOR, 1e-30);
    if (i < BINS) {
        atomicStore(&histogram[i], 0u);
    }
    workgroupBarrier();
    var sum = 0.0;
    var count = 0.0;
    for (var s = 0u; s < per_thread; s++) {
        // Zero radiance is no scene at all (a black backdrop, the sky below the
        // horizon): it would drag the average to the floor, so it does not count.
        let l = grid_sample(i * per_thread + s, dims);
        if (l > 0.0) {
            sum += log(max(l, floor_l));
            count += 1.0;
            let stops_below = log2(frame_max / max(l, floor_l));
            atomicAdd(&histogram[min(u32(stops_below * BINS_PER_STOP), BINS - 1u)], 1u);
        }
    }
    partial_log[i] = sum;
    partial_count[i] = count;
    workgroupBarrier();
    for (var stride = THREADS / 2u; stride > 0u; stride /= 2u) {
        if (i < stride) {
            partial_log[i] += partial_log[i + stride];
            partial_count[i] += partial_count[i + stride];
        }
        workgroupBarrier();
    }
    if (i == 0u) {
        var target_log = log(max(adaptation.values[2], 1e-30));
        var target_max = adaptation.values[3];
        var target_p99 = adaptation.values[5];
        if (partial_count[0] > 0.0 && frame_max > 0.0) {
            target_log = partial_log[0] / partial_count[0];
            target_max = frame_max;
            // The brightest 1% of the covered samples: the bin where it is reached from the top (its upper edge).
            let wanted = u32(ceil(0.01 * partial_count[0]));
            var seen = 0u;
            var bin = 0u;
            loop {
                seen += atomicLoad(&histogram[bin]);
                if (seen >= wanted || bin == BINS - 1u) {
                    break;
                }
                bin += 1u;
            }
            target_p99 = frame_max * exp2(-f32(bin) / BINS_PER_STOP);
        }
        adaptation.values[2] = exp(target_log);
        adaptation.values[3] = target_max;
        adaptation.values[5] = target_p99;
        if (adapt.reset == 1u || adaptation.values[0] <= 0.0) {
            adaptation.values[0] = exp(target_log);
            adaptation.values[1] = target_max;
            adaptation.values[4] = target_p99;
        } else {
            let current = log(adaptation.values[0]);
            var tau = adapt.tau_darken;
            if (target_log > current) {
                tau = adapt.tau_brighten;
            }
            let k = 1.0 - exp(-adapt.dt / tau);
            adaptation.values[0] = exp(current + (target_log - current) * k);
            let current_max = log(max(adaptation.values[1], 1e-30));
            adaptation.values[1] = exp(current_max + (log(max(target_max, 1e-30)) - current_max) * k);
            let current_p99 = log(max(adaptation.values[4], 1e-30));
            adaptation.values[4] = exp(current_p99 + (log(max(target_p99, 1e-30)) - current_p99) * k);
        }
    }
}

