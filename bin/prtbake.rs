//! The `prtbake` command line: parses arguments, checks them, and hands a
//! configuration to the library (`prtbake::cli`). Exit codes: 0 success,
//! 1 a check failed (`verify`), 2 error (bad input, bad arguments, I/O).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use prtbake::bake::{BakeParams, Channels, DirectionPattern, Mode, Sampling};
use prtbake::bundle::Quantization;
use prtbake::clean::{CleanParams, Tolerance};
use prtbake::cli::{self, Outcome};
use prtbake::mesh::UpAxis;

/// `bake --shard … --round`: a bounce, or adaptive allocation's pilot stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RoundArg {
    Bounce(u32),
    Pilot,
}

fn parse_round(text: &str) -> Result<RoundArg, String> {
    match text {
        "pilot" => Ok(RoundArg::Pilot),
        _ => text.parse().map(RoundArg::Bounce).map_err(|_| format!("expected a bounce number (0, 1, …) or `pilot`, not {text:?}")),
    }
}

/// `bake`'s adaptive allocation when `--adaptive` is not given (interior
/// sampling). With the default 32 rays it brings the Ferrari (window mode,
/// 3 bounces) to 4.5% relative L2 total error in about 13 s, where the
/// baseline centroid estimator gave 11.4% in about 13 s; `--rays 128 --adaptive 1` is the
/// final-quality setting (docs/speed-accuracy.md).
const DEFAULT_ADAPTIVE: f32 = 0.25;

#[derive(Parser)]
#[command(
    name = "prtbake",
    version,
    about = "Precomputed radiance transfer, baked offline",
    propagate_version = true,
    args_override_self = true
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum Up {
    Y,
    Z,
}

#[derive(Clone, Copy, ValueEnum)]
enum SamplingArg {
    Interior,
    Vertex,
}

#[derive(Clone, Copy, PartialEq, ValueEnum)]
enum QuantizeArg {
    F32,
    F16,
    I16,
    /// f16 grey transfer and one f16 tint per channel (rank-one colour; lossy, measured).
    F16Tinted,
    Auto,
}

#[derive(Clone, Copy, ValueEnum)]
enum PatternArg {
    Sobol,
    Random,
}

#[derive(clap::Args)]
struct BakeArgs {
    /// Mesh to bake (.obj, .gltf, .glb).
    mesh: PathBuf,
    /// Bundle to write (.prtb).
    #[arg(short, long)]
    output: PathBuf,
    /// SH order n: n² coefficients per channel.
    #[arg(long, default_value_t = 3)]
    order: usize,
    /// Rays per sample point (≤ 65536). The default is a fast bake (the Ferrari
    /// in window mode, 3 bounces: 4.5% total error); `--rays 128 --adaptive 1`
    /// a final one (2%).
    #[arg(long, default_value_t = 32)]
    rays: u32,
    #[arg(long, default_value_t = 1)]
    seed: u32,
    /// Worker threads (0 = all cores) [default: 0]. The output does not depend on it.
    #[arg(long, value_name = "T", value_parser = parse_threads)]
    threads: Option<usize>,
    /// Up axis of OBJ files (glTF is always +Y up).
    #[arg(long, value_enum, default_value_t = Up::Y)]
    up: Up,
    /// Interreflection bounces after the direct one.
    #[arg(long, default_value_t = 0)]
    bounces: u32,
    /// Light enters only through windows: materials or groups matching this glob (repeatable);
    /// glTF materials with KHR_materials_transmission count too. `PATTERN=TAU` sets the glass
    /// transmittance (default: the material's, 1 unless the file says otherwise).
    #[arg(long = "window", value_name = "PATTERN")]
    windows: Vec<String>,
    /// Window mode even without --window (materials with the window role only).
    #[arg(long)]
    window_mode: bool,
    /// Materials or groups (glob, repeatable) whose back side reflects nothing in bounces. By
    /// default a diffuse surface reflects on whichever side light reaches it (open mode, as a
    /// path tracer's two-sided diffuse; window mode reflects from both sides already).
    #[arg(long = "one-sided", value_name = "PATTERN")]
    one_sided: Vec<String>,
    /// Bounces read the light at a ray's hit from a fit to the hit triangle's own points instead of
    /// its corner vertices' one-ring means: less bias where light bends within a one-ring (corners),
    /// more noise per hit (docs/speed-accuracy.md). Not with --shard or --refine.
    #[arg(long)]
    gather_fit: bool,
    /// Filter the baked vertices, guided by the bake's own noise estimate: neighbours whose
    /// difference the noise explains are averaged, edges several standard errors high stay
    /// (K: strength in standard errors; 0 = off). It pays on finely tessellated meshes, where
    /// neighbours differ by noise, and costs where big triangles differ by light
    /// (docs/image-accuracy.md). Not with --shard or --refine.
    #[arg(long, value_name = "K", default_value_t = 0.0)]
    denoise: f32,
    /// Texel mode: also bake transfer per texel of a lightmap atlas at this size in world units,
    /// for light that vertices cannot hold (slat and contact shadows on big triangles): the
    /// mesh's own atlas (glTF TEXCOORD_1) when it has one, else one unwrapped by xatlas. The
    /// vertices are baked as without it. Not with --refine, --view-box.
    #[arg(long, value_name = "L")]
    texel_size: Option<f32>,
    /// With --texel-size: sample points per texel, spread over its footprint by area.
    #[arg(long, value_name = "N", default_value_t = prtbake::bake::texels::POINTS_PER_TEXEL, requires = "texel_size")]
    texel_points: u32,
    /// With --texel-size: unwrap a new atlas (xatlas) even where the mesh has its own (TEXCOORD_1).
    #[arg(long, requires = "texel_size")]
    unwrap: bool,
    /// With --texel-size: rays per vertex sample point (default: --rays, which the texels take).
    /// The picture reads the texels; the vertices serve tools that read vertices and, from
    /// bounce 1 on, the back sides of faces, so fewer rays there cut a texel bake's time.
    #[arg(long, value_name = "N", requires = "texel_size")]
    vertex_rays: Option<u32>,
    /// With --texel-size: after the texels' bounce 0, add about FACTOR × their points where the
    /// light is noisiest (a texel's points grow as √area × the spread of its neighbourhood), the
    /// base points' rays kept. 0 = off. Sharded, it adds the pilot stage (--round pilot).
    #[arg(long, value_name = "FACTOR", default_value_t = 0.0, requires = "texel_size")]
    texel_adaptive: f32,
    /// With --texel-size L and --max-error E: a texel size per chart, from L to 2^(N-1)·L (N in
    /// 2..=4). A pilot bake on an atlas of the coarsest texels measures each chart, and the charts
    /// whose light changes most get finer texels until the estimated resolution error (relative L2
    /// of the texels' DC) is within E. Unwrapped atlases only. With --shard every shard runs the
    /// pilot in round 0 (and the pilot stage) and keeps the choice with its hit records for the
    /// later rounds.
    #[arg(long, value_name = "N", requires_all = ["texel_size", "max_error"])]
    texel_levels: Option<u32>,
    /// Where rays start: inside triangles (default) or at vertices (leaks shadows; for comparison).
    #[arg(long, value_enum, default_value_t = SamplingArg::Interior)]
    sampling: SamplingArg,
    /// Interior samples per vertex on average (spread by area in rotation triples, ≥ 3 per triangle).
    #[arg(long, default_value_t = 2.0)]
    samples_per_vertex: f32,
    /// Adaptive allocation: after bounce 0's points, add about FACTOR × as many
    /// where their spread shows the most noise (a vertex's effective points grow
    /// as its noise; docs/speed-accuracy.md). 0 = off. Interior sampling only
    /// [default: 0.25; 0 with --sampling vertex]. Sharded, it (or --texel-adaptive) adds a pilot
    /// stage (--round pilot).
    #[arg(long, value_name = "FACTOR")]
    adaptive: Option<f32>,
    /// Colour channels: 1, 3, or auto (1 when every material is grey).
    #[arg(long, default_value = "auto", value_parser = ["auto", "1", "3"])]
    channels: String,
    /// Store each bounce separately as well as the total.
    #[arg(long)]
    store_bounces: bool,
    /// Direction pattern (random is for comparison only).
    #[arg(long, value_enum, default_value_t = PatternArg::Sobol)]
    pattern: PatternArg,
    /// Window mode: bounce 0 also aims `--rays` rays at the glass (panes by area,
    /// directions by solid angle), combined with the cosine rays by multiple
    /// importance sampling: far less noise where windows are small or far.
    #[arg(long)]
    window_sampling: bool,
    /// Window mode: keep the light through glass on sides of sample points that see
    /// the open sky (more than a quarter of their rays escape without meeting glass).
    /// By default such a side is outside the enclosure and gets none (no glow on a
    /// wall's outer face from a pane in front of it); keep it for window scenes
    /// with no enclosure.
    #[arg(long)]
    keep_outside_sides: bool,
    /// Memory for bounce 0's hit cache (8 bytes a ray), in MiB. Bounces ≥ 1
    /// gather from it; over it they re-trace the same rays instead (3–4×
    /// slower, same bytes).
    /// [default: half the memory available at start; 6144 where unknown]
    #[arg(long)]
    hit_cache_mib: Option<u64>,
    /// Transfer storage: f32, f16, i16 (per-vertex scale), f16-tinted (grey + per-channel tint), or auto (smallest within --max-error,
    /// or within 0.1% shaded error without it).
    /// [default: f32, or auto with --max-error]
    #[arg(long, value_enum)]
    quantize: Option<QuantizeArg>,
    /// Error budget, relative RMS of shaded radiance under reference skies (e.g. 0.01 = 1%):
    /// stores the lowest SH order, fewest channels and smallest quantization within it, and records
    /// the choice and its measured error in the bundle. Implies --quantize auto unless given.
    #[arg(long, value_name = "E")]
    max_error: Option<f64>,
    /// Store only triangles visible from this box, MINX,MINY,MINZ,MAXX,MAXY,MAXZ (world units, Y up
    /// after --up), found by ray casting; occlusion and bounces still use the whole scene.
    #[arg(long, value_name = "BOX", allow_hyphen_values = true)]
    view_box: Option<String>,
    /// With --view-box: viewpoints sampled in the box [default: 256].
    #[arg(long, requires = "view_box")]
    view_points: Option<u32>,
    /// With --view-box: rays per viewpoint (≤ 65536) [default: 16384].
    #[arg(long, requires = "view_box")]
    view_rays: Option<u32>,
    /// Clean the mesh first (CAD preset: weld, duplicates, overlaps, cracks, slivers, orientation).
    #[arg(long)]
    clean: bool,
    /// With --clean: split edges longer than this (world units), as `clean --max-edge` does.
    #[arg(long, requires = "clean")]
    max_edge: Option<f32>,
    /// With --clean: cut triangles where geometry passes through geometry and keep
    /// the two sides of each cut apart, as `clean --cut-intersections` does.
    #[arg(long, requires = "clean")]
    cut_intersections: bool,
    #[command(flatten)]
    refine: RefineArgs,
    /// Bake only shard K of N (K in 0..N): its share of the items, into a part (-o PART.prtp)
    /// that `prtbake merge` joins with the others, round by round (docs/scale.md).
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// With --shard: the round, i.e. the bounce baked (0..=--bounces), or `pilot`, adaptive
    /// allocation's first stage (bounce 0 at the base points, merged into the pilot every round
    /// reads with --pilot) [default: 0].
    #[arg(long, value_name = "R|pilot", requires = "shard", value_parser = parse_round)]
    round: Option<RoundArg>,
    /// With --shard and adaptive allocation (the default): the merged pilot (.prta) of this
    /// bake, which decides where the extra points go; every round 0..=--bounces reads it.
    #[arg(long, value_name = "FILE.prta", requires = "shard")]
    pilot: Option<PathBuf>,
    /// With --shard --round R ≥ 1: the merged layer of round R − 1 (.prtl) to gather from.
    #[arg(long, value_name = "FILE.prtl", requires = "shard")]
    layer: Option<PathBuf>,
    /// With --shard: the folder of this shard's hit records (hits-K-of-N.prth), written by
    /// round 0 and read by later rounds [default: the part's folder].
    #[arg(long, value_name = "DIR", requires = "shard")]
    shard_dir: Option<PathBuf>,
    /// Check these arguments as a bake of N shards would read them, print its plan on stdout
    /// (`shards=N`, `bounces=B`, `pilot=0|1`, `threads_given=0|1`, one per line) and exit
    /// without baking: what the launchers in scripts/ run, so they read every number as
    /// prtbake does.
    #[arg(long, value_name = "N", conflicts_with = "shard")]
    plan_shards: Option<u32>,
    /// Replace the output even if it is read-only.
    #[arg(long)]
    force: bool,
    /// Stats as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// No progress on stderr.
    #[arg(long)]
    quiet: bool,
}

/// Adaptive refinement (docs/refinement.md), shared by `bake` and `sun`.
#[derive(clap::Args)]
struct RefineArgs {
    /// Refine the mesh where its light changes: split edges whose two vertices differ by more
    /// than ERROR, re-bake the vertices around the splits, repeat. `bake`: shaded luminance under
    /// twelve clear skies, relative to the edge's own level or, where darker, the scene's mean
    /// (e.g. 0.1); `sun`: direct sun (bit × cosine) over the day, as a fraction of the sun's
    /// normal irradiance.
    #[arg(long, value_name = "ERROR", conflicts_with_all = ["shard"])]
    refine: Option<f64>,
    /// Refine (by largest error × edge length first) up to at most N vertices
    /// [default with --refine: 4× the input's vertices].
    #[arg(long, value_name = "N", conflicts_with_all = ["shard"])]
    max_vertices: Option<usize>,
    /// With --refine or --max-vertices: never split edges shorter than this (world units)
    /// [default: 2e-4 of the bounding-box diagonal].
    #[arg(long, value_name = "LENGTH")]
    min_edge: Option<f32>,
    /// `bake` with --refine or --max-vertices: a difference between an edge's vertices counts only
    /// past K standard errors of their estimates (each bounce's own spread), so noise is not split;
    /// 0 splits noise as light [default: 2].
    #[arg(long, value_name = "K")]
    refine_noise: Option<f64>,
}

impl RefineArgs {
    /// The request, when refinement was asked for; ranges checked.
    fn request(&self) -> anyhow::Result<Option<cli::bake_cmd::RefineRequest>> {
        if let Some(e) = self.refine {
            if !(e.is_finite() && e >= 0.0) {
                anyhow::bail!("--refine {e}: expected a finite error ≥ 0 (e.g. 0.1)");
            }
        }
        if let Some(m) = self.min_edge {
            if !(m.is_finite() && m >= 0.0) {
                anyhow::bail!("--min-edge {m}: expected a finite length ≥ 0");
            }
        }
        if let Some(k) = self.refine_noise {
            if !(k.is_finite() && k >= 0.0) {
                anyhow::bail!("--refine-noise {k}: expected a finite number of standard errors ≥ 0 (e.g. 2)");
            }
        }
        match self.max_vertices {
            Some(0) => anyhow::bail!("--max-vertices 0: expected at least one vertex"),
            Some(n) if n > prtbake::refine::MAX_VERTICES => anyhow::bail!(
                "--max-vertices {n}: at most {} (the refined mesh, its samples and its transfer must fit in memory; refine a part of the scene, or shard the bake)",
                prtbake::refine::MAX_VERTICES
            ),
            _ => {}
        }
        Ok(match (self.refine, self.max_vertices) {
            (None, None) if self.min_edge.is_some() => anyhow::bail!("--min-edge needs --refine or --max-vertices"),
            (None, None) if self.refine_noise.is_some() => anyhow::bail!("--refine-noise needs --refine or --max-vertices"),
            (None, None) => None,
            (error, max_vertices) => {
                Some(cli::bake_cmd::RefineRequest { error, max_vertices, min_edge: self.min_edge, noise_sigmas: self.refine_noise })
            }
        })
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum CleanPreset {
    /// Tessellated CAD: everything on, hard edges kept.
    Cad,
    /// Scans: smooth normals, no zipping of the scan's holes.
    Scan,
    /// Only weld, degenerate and duplicate removal.
    Minimal,
}

#[derive(clap::Args)]
struct CleanArgs {
    /// Mesh to clean (.obj, .gltf, .glb).
    input: PathBuf,
    /// Cleaned mesh (.obj or .glb, by extension).
    #[arg(short, long)]
    output: PathBuf,
    /// Write the full report as JSON here.
    #[arg(long)]
    report: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = CleanPreset::Cad)]
    preset: CleanPreset,
    /// Weld distance, absolute (world units); default 1e-6 of the bounding-box diagonal.
    #[arg(long)]
    weld_tolerance: Option<f32>,
    /// Vertices whose normals differ by more than this (degrees) stay apart.
    #[arg(long)]
    hard_edge_angle: Option<f32>,
    /// Split edges longer than this (world units), recursively.
    #[arg(long)]
    max_edge: Option<f32>,
    /// Cut triangles along the lines where other triangles pass through them (a wall
    /// running past a wall, a floor under and past a wall) and keep the two sides of
    /// each line apart, so the light outside does not bleed into the room.
    #[arg(long)]
    cut_intersections: bool,
    /// With --cut-intersections: cut every crossing, also those whose cut
    /// leaves triangles under 1° that cannot be repaired (by default those
    /// crossings are left uncut and listed in the report).
    #[arg(long, requires = "cut_intersections")]
    cut_every_crossing: bool,
    /// Keep one triangle per winding of a doubled sheet (two-sided surfaces).
    #[arg(long)]
    keep_two_sided: bool,
    /// Replace read-only outputs, and an existing .mtl that prtbake did not write.
    #[arg(long)]
    force: bool,
    #[arg(long, value_enum, default_value_t = Up::Y)]
    up: Up,
    /// The report as JSON on stdout.
    #[arg(long)]
    json: bool,
    #[arg(long)]
    quiet: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum LoopOrderArg {
    StepOuter,
    PointOuter,
}

#[derive(clap::Args)]
struct SunArgs {
    /// A mesh (.obj, .gltf, .glb): a new bundle; or a bundle (.prtb): sun sections added, the rest kept.
    input: PathBuf,
    /// Bundle to write (.prtb); may be the input bundle.
    #[arg(short, long)]
    output: PathBuf,
    /// Site latitude, degrees north (default: the Acropolis, 37.9715).
    #[arg(long, allow_hyphen_values = true)]
    lat: Option<f64>,
    /// Site longitude, degrees east (default: the Acropolis, 23.7267).
    #[arg(long, allow_hyphen_values = true)]
    lon: Option<f64>,
    /// Site elevation, metres (default 150).
    #[arg(long, allow_hyphen_values = true)]
    elevation: Option<f64>,
    /// Local date YYYY-MM-DD (default 2026-03-20, the March equinox).
    #[arg(long)]
    date: Option<String>,
    /// UTC offset ±HH:MM (default: Athens's on that date, +02:00 or +03:00).
    #[arg(long, allow_hyphen_values = true)]
    tz: Option<String>,
    /// First step, local HH:MM.
    #[arg(long, default_value = "06:57")]
    from: String,
    /// Last step, local HH:MM (included when it falls on a step).
    #[arg(long, default_value = "17:34")]
    to: String,
    /// Minutes between steps (default 7: 92 steps from 06:57 to 17:34).
    #[arg(long, conflicts_with = "steps")]
    step: Option<f64>,
    /// Number of steps evenly spread from --from to --to, both included (1..=1024).
    #[arg(long)]
    steps: Option<u32>,
    /// Sun directions instead of a date: one `x,y,z` per line toward the sun, in the input's axes.
    #[arg(long, value_name = "FILE.csv", conflicts_with_all = ["lat", "lon", "elevation", "date", "tz", "step", "steps"])]
    directions: Option<PathBuf>,
    /// Geographic north as X,Y,Z in the input's axes (default −Z for +Y up, +Y for +Z up).
    #[arg(long, allow_hyphen_values = true)]
    north: Option<String>,
    /// Up axis of OBJ files (glTF is always +Y up; bundles are already +Y up).
    #[arg(long, value_enum, default_value_t = Up::Y)]
    up: Up,
    /// Light enters only through windows: materials or groups matching this glob (repeatable).
    #[arg(long = "window", value_name = "PATTERN")]
    windows: Vec<String>,
    /// Window mode even without --window (materials with the window role only).
    #[arg(long)]
    window_mode: bool,
    /// Window mode: let the sun reach a sample through glass also from a side that sees
    /// more open sky than surfaces (outside the enclosure; dark by default, as in `bake`).
    #[arg(long)]
    keep_outside_sides: bool,
    /// Preetham sky turbidity, 2..=10.
    #[arg(long, default_value_t = 3.0)]
    turbidity: f64,
    /// SH order of the stored sky (bands l < n; 0 = no sky).
    #[arg(long, default_value_t = 3)]
    sky_order: usize,
    /// Interior samples per vertex on average (spread by area in rotation triples, ≥ 3 per triangle).
    #[arg(long, default_value_t = 2.0)]
    samples_per_vertex: f32,
    /// Seed of the sample placement (the same seed as `bake` gives the same points).
    #[arg(long, default_value_t = 1)]
    seed: u32,
    /// Worker threads (0 = all cores) [default: 0]. The output does not depend on it.
    #[arg(long, value_name = "T", value_parser = parse_threads)]
    threads: Option<usize>,
    /// Tracing loop nesting (for measurement; the masks are the same).
    #[arg(long, value_enum, default_value_t = LoopOrderArg::StepOuter)]
    loop_order: LoopOrderArg,
    /// Trace without the shadow cache (for measurement; the masks are the same).
    #[arg(long)]
    no_shadow_cache: bool,
    /// Trace one ray at a time instead of in packets of nearby points (for measurement; the masks are the same).
    #[arg(long)]
    no_packets: bool,
    #[command(flatten)]
    refine: RefineArgs,
    /// Texel mode: also a sun bit per texel of a lightmap atlas at this size in world units
    /// (e.g. 0.02), for a mesh or a per-vertex bundle (whose sky light stays per vertex): a
    /// mesh file's own atlas (glTF TEXCOORD_1) when it has one, else one unwrapped by xatlas
    /// (a bundle keeps no TEXCOORD_1); a texel bundle's own atlas is always used.
    #[arg(long, value_name = "L", conflicts_with = "refine")]
    texel_size: Option<f32>,
    /// With --texel-size: unwrap a new atlas (xatlas) even where the mesh has its own (TEXCOORD_1).
    #[arg(long, requires = "texel_size")]
    unwrap: bool,
    /// With --texel-size L and --max-error E: a texel size per chart of the new atlas, from L to
    /// 2^(N-1)·L (N in 2..=4). A pilot on an atlas of the coarsest texels (4 points each) measures
    /// each chart, and the charts where shadow edges pass get finer texels until the estimated
    /// error of the texels' lit shares (relative L2 over texels and steps) is within E. With
    /// --shard every shard runs the pilot and sizes the same charts.
    #[arg(long, value_name = "N", requires_all = ["texel_size", "max_error"])]
    texel_levels: Option<u32>,
    /// With --texel-levels: the budget of the texels' resolution error (e.g. 0.1 = 10%).
    #[arg(long, value_name = "E", requires = "texel_levels")]
    max_error: Option<f64>,
    /// Sample points per texel for its sun bits (default: a texel bundle's bake's, else 4).
    #[arg(long, value_name = "N")]
    texel_points: Option<u32>,
    /// With texels: also store each texel's sunlit share per step (4 bits, section TSUF), which
    /// the viewer reads instead of the bit, so a shadow edge falls inside a texel, not on its border.
    #[arg(long)]
    texel_fractions: bool,
    /// Trace only shard K of N (K in 0..N) into a part (-o PART.prtp); `prtbake merge` joins the parts.
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// Check these arguments as a sun bake of N shards would read them, print its plan on
    /// stdout (`shards=N`, `threads_given=0|1`) and exit: what scripts/slurm/submit-sun.sh runs.
    #[arg(long, value_name = "N", conflicts_with = "shard")]
    plan_shards: Option<u32>,
    /// Replace the output even if it is read-only.
    #[arg(long)]
    force: bool,
    /// Stats as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// No progress on stderr.
    #[arg(long)]
    quiet: bool,
}

#[derive(clap::Args)]
struct ViewArgs {
    /// Bundle to view (.prtb).
    bundle: PathBuf,
    /// Light with this equirect environment map (.exr or .hdr), projected once onto SH.
    #[arg(long, conflicts_with = "sky")]
    env: Option<PathBuf>,
    /// Light with the time lapse's sky SH from the bundle (default when it has one).
    #[arg(long)]
    sky: bool,
    /// Show the time-lapse step nearest this local time (HH:MM).
    #[arg(long, conflicts_with = "step")]
    time: Option<String>,
    /// Show time-lapse step K (0-based).
    #[arg(long)]
    step: Option<usize>,
    /// UTC offset for --time, +HH:MM (default +02:00, the default time line's).
    #[arg(long, allow_hyphen_values = true)]
    tz: Option<String>,
    /// Exposure in stops (radiance × 2^STOPS).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    exposure: f32,
    /// Turn the car under the sky about +Y (world up), degrees, counter-clockwise seen from above; the environment turns the other way.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    yaw: f32,
    /// Turn the car about +X, degrees (right-handed).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pitch: f32,
    /// Turn the car about +Z, degrees (right-handed).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    roll: f32,
    /// Tone mapping: photographic (key from the absolute adaptation luminance, filmic curve), drago (adaptive logarithmic, seed 000) or linear (exposure + gamma, seed 001).
    #[arg(long, default_value = "photographic", value_parser = ["photographic", "drago", "linear"])]
    tonemap: String,
    #[arg(long, default_value_t = 2.2)]
    gamma: f32,
    /// Transfer layers: total, direct, indirect, or bounces like 0,2 (needs --store-bounces at bake time).
    #[arg(long, default_value = "total")]
    layers: String,
    /// Do not draw materials or groups matching this glob (repeatable), glass included.
    #[arg(long, value_name = "PATTERN")]
    hide: Vec<String>,
    /// Render one frame offscreen into this PNG and exit (no window system needed).
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// Screenshot size, WxH.
    #[arg(long, default_value = "1280x720")]
    size: String,
    /// Camera eye and target: EX,EY,EZ,TX,TY,TZ (default: the whole scene).
    #[arg(long, allow_hyphen_values = true)]
    camera: Option<String>,
    /// Vertical field of view, degrees.
    #[arg(long, default_value_t = 50.0)]
    fov: f32,
    /// With --screenshot: render N timed frames and report frame time and GPU memory.
    #[arg(long, default_value_t = 0)]
    frames: u32,
    /// The LCD panel drawn with its final-gathered reflection: materials or groups matching this glob (default: materials with the panel role, if any).
    #[arg(long, value_name = "PATTERN")]
    panel: Option<String>,
    /// Texels of the panel's texture, WxH (default: 128 along the panel's long side, square texels).
    #[arg(long, value_name = "WxH")]
    panel_texels: Option<String>,
    /// With --screenshot: gather passes before the frame (pass 1: 2 samples per texel, each later pass doubles, at most +32; 0 = no panel texture). Default 12 (256 samples per texel).
    #[arg(long, value_name = "N")]
    panel_passes: Option<u32>,
    #[arg(long)]
    json: bool,
}

// Every subcommand takes negative numbers as values, so `--rays -1` gets a
// range error ("invalid value") instead of "unexpected argument".
#[derive(Subcommand)]
enum Command {
    /// Bake per-vertex SH transfer of a mesh into a bundle.
    #[command(allow_negative_numbers = true)]
    Bake(BakeArgs),
    /// Repair a mesh for PRT (duplicates, overlaps, cracks, T-junctions, slivers, winding) and report every change.
    #[command(allow_negative_numbers = true)]
    Clean(CleanArgs),
    /// Bake a day's sun-shadow bits per vertex, with per-step sun and sky, into a bundle.
    #[command(allow_negative_numbers = true)]
    Sun(SunArgs),
    /// Write a generated scene (the colonnade monument, a street of them, or the demo cabin) as .glb or .obj.
    #[command(allow_negative_numbers = true)]
    Generate {
        /// Scene name: colonnade, or cabin (the demo cabin with its injected defects).
        #[arg(value_parser = ["colonnade", "cabin"])]
        scene: String,
        #[arg(short, long)]
        output: PathBuf,
        /// Colonnade: small (tests), monument (≈786k triangles, the default), million (> 1M vertices).
        /// Cabin: small (11,738 triangles once cleaned, tests), demo (≈333k triangles, the default).
        #[arg(long, value_parser = ["small", "monument", "million", "demo"])]
        detail: Option<String>,
        /// Colonnades in a row along X, 46 m apart (a street; `--detail million --copies 2`: 5.05M triangles).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
        copies: u32,
        /// Replace read-only outputs, and an existing .mtl that prtbake did not write.
        #[arg(long)]
        force: bool,
    },
    /// Show what a bundle holds, or what a mesh is made of before baking: its materials and
    /// groups with triangles, areas and likely roles (glass, emitters), to choose --window.
    #[command(allow_negative_numbers = true)]
    Inspect {
        /// A bundle (.prtb) or a mesh (.obj, .gltf, .glb).
        bundle: PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// Bake analytic scenes and compare with closed forms (exit 1 on failure).
    #[command(allow_negative_numbers = true)]
    Verify {
        #[arg(long, default_value_t = 1024)]
        rays: u32,
        #[arg(long, default_value_t = 1)]
        seed: u32,
        #[arg(long, default_value_t = 0, value_parser = parse_threads)]
        threads: usize,
        #[arg(long)]
        json: bool,
    },
    /// Sweep rays, direction pattern, sampling, SH order and bounces on analytic scenes and the
    /// demo cabin; write speed-accuracy.csv/.svg and an equal-time summary.
    #[command(allow_negative_numbers = true)]
    Chart {
        /// Output folder (the cabin reference bake is cached here).
        #[arg(short, long, default_value = "chart-out")]
        output: PathBuf,
        /// A small sweep (seconds), for tests.
        #[arg(long)]
        quick: bool,
        /// The real scenes instead (the Ferrari in window mode, the grey-white
        /// room, the demo cabin; 3 bounces), total error against converged
        /// references cached in the output folder (about an hour to bake
        /// them once, minutes after).
        #[arg(long)]
        real: bool,
        /// With --real: the folder holding car-ferrari458/ and
        /// room-grey-white/ (scenes not found are skipped with a notice).
        #[arg(long, default_value = "../shared/data", requires = "real")]
        data: PathBuf,
        /// With --real: largest cache of bounce 0's hits, as `bake --hit-cache-mib` (the Ferrari's
        /// references need about 13,000 to gather from it; below that they re-trace, several times slower).
        /// [default: half the memory available at start]
        #[arg(long, requires = "real")]
        hit_cache_mib: Option<u64>,
        #[arg(long, default_value_t = 0, value_parser = parse_threads)]
        threads: usize,
        #[arg(long)]
        json: bool,
        /// Replace read-only outputs.
        #[arg(long)]
        force: bool,
    },
    /// The LCD panel's reflections by final gather (measured BRDF, PRT-lit interior, sky through the windows) and its contrast ratio.
    #[command(allow_negative_numbers = true)]
    Panel(PanelArgs),
    /// Generate the demo cabin, bake it in window mode and write a bundle and a summary.
    #[command(allow_negative_numbers = true)]
    Demo {
        /// Output folder.
        #[arg(short, long, default_value = "demo-out")]
        output: PathBuf,
        #[arg(long, default_value_t = 0, value_parser = parse_threads)]
        threads: usize,
        #[arg(long)]
        json: bool,
        #[arg(long)]
        quiet: bool,
    },
    /// Relight a bundle interactively (wgpu), or headlessly into a PNG with --screenshot.
    #[command(allow_negative_numbers = true)]
    View(ViewArgs),
    /// Join the parts of one round of a sharded bake (bake/sun --shard) into the next round's
    /// layer (.prtl) or, after the last round, the bundle (.prtb), byte-identical to one process.
    #[command(allow_negative_numbers = true)]
    Merge {
        /// Every part of the round (.prtp), in any order.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// The layer (.prtl) or bundle (.prtb) to write.
        #[arg(short, long)]
        output: PathBuf,
        /// Rounds ≥ 1: the merged layer of the round before, which the parts gathered from.
        #[arg(long, value_name = "FILE.prtl")]
        layer: Option<PathBuf>,
        #[arg(long, default_value_t = 0, value_parser = parse_threads)]
        threads: usize,
        /// Replace the output even if it is read-only.
        #[arg(long)]
        force: bool,
        #[arg(long)]
        json: bool,
    },
    /// Write the bundle's mesh as GLB with transfer and sun masks as _PRT_ vertex attributes (texel bundles: texels as textures on TEXCOORD_1).
    #[command(allow_negative_numbers = true)]
    Export {
        bundle: PathBuf,
        /// GLB to write.
        #[arg(short, long)]
        output: PathBuf,
        /// Transfer layer: total or a stored bounce index.
        #[arg(long, default_value = "total")]
        layer: String,
        #[arg(long)]
        json: bool,
        /// Replace the output even if it is read-only.
        #[arg(long)]
        force: bool,
    },
}

/// `--threads T`: a count ≥ 0 (0 = every core), with a message that says so.
fn parse_threads(text: &str) -> Result<usize, String> {
    text.trim().parse::<usize>().map_err(|_| format!("expected a number of threads, 0 or more (0 uses every core), not {text:?}"))
}

/// A panel's texels `WxH` (each 1..=4096), named by `flag` in the error.
fn parse_texels(flag: &str, text: Option<&str>) -> anyhow::Result<Option<(u32, u32)>> {
    let Some(text) = text else { return Ok(None) };
    let parsed = text.split_once(['x', 'X']).and_then(|(w, h)| Some((w.trim().parse::<u32>().ok()?, h.trim().parse::<u32>().ok()?)));
    match parsed {
        Some((w, h)) if (1..=4096).contains(&w) && (1..=4096).contains(&h) => Ok(Some((w, h))),
        _ => anyhow::bail!("{flag} {text:?}: expected WxH, each 1..=4096"),
    }
}

fn view_config(a: ViewArgs) -> anyhow::Result<cli::view_cmd::ViewConfig> {
    Ok(cli::view_cmd::ViewConfig {
        bundle: a.bundle,
        env: a.env,
        sky: a.sky,
        time: a.time,
        step: a.step,
        tz: a.tz,
        exposure: a.exposure,
        car_rotation_deg: [a.yaw, a.pitch, a.roll],
        tonemap: a.tonemap,
        gamma: a.gamma,
        layers: a.layers,
        hide: a.hide,
        screenshot: a.screenshot,
        size: a.size,
        camera: a.camera,
        fov_deg: a.fov,
        frames: a.frames,
        panel: a.panel,
        panel_texels: parse_texels("--panel-texels", a.panel_texels.as_deref())?,
        panel_passes: a.panel_passes,
        json: a.json,
    })
}

fn bake_config(a: BakeArgs) -> anyhow::Result<cli::bake_cmd::BakeConfig> {
    let channels = match a.channels.as_str() {
        "1" => Channels::One,
        "3" => Channels::Three,
        _ => Channels::Auto,
    };
    let adaptive = match (a.adaptive, a.sampling) {
        (Some(f), _) => f,
        (None, SamplingArg::Vertex) => 0.0,
        (None, SamplingArg::Interior) => DEFAULT_ADAPTIVE,
    };
    let params = BakeParams {
        order: a.order,
        rays: a.rays,
        seed: a.seed,
        mode: if a.window_mode || !a.windows.is_empty() { Mode::Window } else { Mode::Open },
        sampling: match a.sampling {
            SamplingArg::Interior => Sampling::Interior { samples_per_vertex: a.samples_per_vertex, max_per_triangle: 256 },
            SamplingArg::Vertex => Sampling::Vertex,
        },
        bounces: a.bounces,
        channels,
        store_bounces: a.store_bounces,
        adaptive,
        pattern: match a.pattern {
            PatternArg::Sobol => DirectionPattern::Sobol,
            PatternArg::Random => DirectionPattern::Random,
        },
        quiet: a.quiet || a.json,
        window_sampling: a.window_sampling,
        keep_outside_sides: a.keep_outside_sides,
        hit_cache_bytes: hit_cache_bytes(a.hit_cache_mib),
        gather_fit: a.gather_fit,
        denoise: a.denoise,
        ..BakeParams::default()
    };
    params.check()?;
    if a.gather_fit && a.shard.is_some() {
        anyhow::bail!("--gather-fit with --shard: a sharded bake's layers hold vertex rows only (bake it in one process)");
    }
    if a.gather_fit && (a.refine.refine.is_some() || a.refine.max_vertices.is_some()) {
        anyhow::bail!("--gather-fit with --refine: refinement's partial re-bakes gather from vertex rows (bake the refined mesh again with --gather-fit)");
    }
    if a.denoise > 0.0 && (a.refine.refine.is_some() || a.refine.max_vertices.is_some()) {
        anyhow::bail!(
            "--denoise with --refine: refinement's partial re-bakes keep vertices as baked (bake the refined mesh again with --denoise)"
        );
    }
    if let Some(e) = a.max_error {
        if !(e.is_finite() && e >= 0.0) {
            anyhow::bail!("--max-error {e}: expected a finite error ≥ 0 (e.g. 0.01 for 1%)");
        }
    }
    // --max-error alone lets the quantization be chosen too.
    let quantize = match a.quantize {
        None if a.max_error.is_some() => None,
        None | Some(QuantizeArg::F32) => Some(Quantization::F32),
        Some(QuantizeArg::F16) => Some(Quantization::F16),
        Some(QuantizeArg::I16) => Some(Quantization::I16PerVertexScale),
        Some(QuantizeArg::F16Tinted) => Some(Quantization::F16Tinted),
        Some(QuantizeArg::Auto) => None,
    };
    let shard = match &a.shard {
        Some(text) => Some(prtbake::shards::ShardRun {
            shard: prtbake::shards::Shard::parse(text)?,
            round: match a.round {
                Some(RoundArg::Bounce(r)) => r,
                _ => 0,
            },
            pilot_stage: a.round == Some(RoundArg::Pilot),
            pilot: a.pilot,
            layer: a.layer,
            shard_dir: a.shard_dir,
        }),
        None => None,
    };
    let clean = match a.clean {
        true => {
            let params = CleanParams { max_edge: a.max_edge, cut_intersections: a.cut_intersections, ..CleanParams::cad() };
            params.validate()?;
            Some(params)
        }
        false => None,
    };
    let refine = a.refine.request()?;
    if refine.is_some() && a.view_box.is_some() {
        anyhow::bail!("--refine/--max-vertices and --view-box cannot be combined: refine first, then cull");
    }
    let texels = match a.texel_size {
        Some(size) => {
            if !(size.is_finite() && size > 0.0) {
                anyhow::bail!("--texel-size {size}: expected a positive length in world units (e.g. 0.02 for 2 cm)");
            }
            if !(1..=256).contains(&a.texel_points) {
                anyhow::bail!("--texel-points {}: expected 1..=256", a.texel_points);
            }
            let with = |flag: &str, why: &str| anyhow::anyhow!("--texel-size with {flag}: {why}");
            if refine.is_some() {
                return Err(with("--refine", "texels already resolve the light where vertices cannot; refine or bake texels"));
            }
            if a.view_box.is_some() {
                return Err(with("--view-box", "culling compacts the vertices, not the atlas"));
            }
            if matches!(a.sampling, SamplingArg::Vertex) {
                return Err(with("--sampling vertex", "texels sample inside their triangles"));
            }
            if let Some(n) = a.vertex_rays.filter(|n| !(1..=prtbake::sampling::MAX_RAYS_PER_POINT).contains(n)) {
                anyhow::bail!("--vertex-rays {n}: expected 1..={}", prtbake::sampling::MAX_RAYS_PER_POINT);
            }
            let density = texel_density(a.texel_levels, a.max_error)?;
            if !(0.0..=16.0).contains(&a.texel_adaptive) {
                anyhow::bail!("--texel-adaptive {}: expected 0..=16 (extra points per base point)", a.texel_adaptive);
            }
            Some(cli::bake_cmd::TexelRequest {
                size,
                points: a.texel_points,
                unwrap: a.unwrap,
                density,
                vertex_rays: a.vertex_rays,
                adaptive: a.texel_adaptive,
            })
        }
        None => None,
    };
    Ok(cli::bake_cmd::BakeConfig {
        texels,
        refine,
        shard,
        input: a.mesh,
        output: a.output,
        up: up_axis(a.up),
        params,
        window_patterns: a.windows,
        one_sided_patterns: a.one_sided,
        threads: a.threads.unwrap_or(0),
        json: a.json,
        clean,
        storage: prtbake::bundle::StorageRequest { quantize, max_error: a.max_error },
        force: a.force,
        view_box: match &a.view_box {
            Some(text) => {
                let view_box = prtbake::bake::cull::ViewBox::parse(text).map_err(anyhow::Error::msg)?;
                let (view_points, view_rays) = (a.view_points.unwrap_or(256), a.view_rays.unwrap_or(16384));
                if !(1..=MAX_VIEW_POINTS).contains(&view_points) || view_rays == 0 || view_rays > 65536 {
                    anyhow::bail!("--view-points must be in 1..={MAX_VIEW_POINTS} and --view-rays in 1..=65536");
                }
                let params =
                    prtbake::bake::cull::CullParams { points: view_points, rays_per_point: view_rays, seed: a.seed, ..Default::default() };
                Some((view_box, params))
            }
            None => None,
        },
    })
}

/// Viewpoints sampled in a view box at most: 65,536 × 65,536 rays is already
/// 4.3·10⁹ rays, hours on a workstation.
const MAX_VIEW_POINTS: u32 = 65_536;

fn up_axis(up: Up) -> UpAxis {
    match up {
        Up::Y => UpAxis::Y,
        Up::Z => UpAxis::Z,
    }
}

fn clean_config(a: CleanArgs) -> anyhow::Result<cli::clean_cmd::CleanConfig> {
    let mut params = match a.preset {
        CleanPreset::Cad => CleanParams::cad(),
        CleanPreset::Scan => CleanParams::scan(None),
        CleanPreset::Minimal => CleanParams::minimal(),
    };
    if let Some(t) = a.weld_tolerance {
        params.weld_tolerance = Tolerance::Absolute(t);
    }
    if let Some(angle) = a.hard_edge_angle {
        params.hard_edge_angle_deg = angle;
    }
    params.max_edge = a.max_edge.or(params.max_edge);
    params.keep_two_sided = a.keep_two_sided;
    params.cut_intersections = a.cut_intersections;
    params.cut_every_crossing = a.cut_every_crossing;
    params.validate()?;
    Ok(cli::clean_cmd::CleanConfig {
        input: a.input,
        output: a.output,
        report: a.report,
        up: up_axis(a.up),
        params,
        json: a.json,
        quiet: a.quiet,
        force: a.force,
    })
}

/// `--texel-levels N` with the budget `--max-error E` (clap has checked that both come with --texel-size).
fn texel_density(levels: Option<u32>, max_error: Option<f64>) -> anyhow::Result<Option<prtbake::bake::texel_density::DensityRequest>> {
    let (Some(levels), Some(budget)) = (levels, max_error) else { return Ok(None) };
    let request = prtbake::bake::texel_density::DensityRequest { levels, budget };
    request.check().map_err(|e| anyhow::anyhow!("--texel-levels {levels} --max-error {budget}: {e}"))?;
    Ok(Some(request))
}

fn sun_config(a: SunArgs) -> anyhow::Result<cli::sun_cmd::SunConfig> {
    use anyhow::{bail, Context};
    use prtbake::sky;
    let up = match a.up {
        Up::Y => UpAxis::Y,
        Up::Z => UpAxis::Z,
    };
    let source = match a.directions {
        Some(path) => cli::sun_cmd::SunSource::Directions(path),
        None => {
            let acropolis = sky::Site::acropolis();
            let (lat, lon, elevation) = (
                a.lat.unwrap_or(acropolis.latitude_deg),
                a.lon.unwrap_or(acropolis.longitude_deg),
                a.elevation.unwrap_or(acropolis.elevation_m),
            );
            check_lat_lon(lat, lon)?;
            if !elevation.is_finite() || !(-500.0..=9000.0).contains(&elevation) {
                bail!("--elevation {elevation}: expected metres within -500..=9000");
            }
            let (date, tz_minutes) = date_and_tz(a.date.as_deref(), a.tz.as_deref())?;
            let steps = match (a.step, a.steps) {
                (_, Some(n)) => sky::StepSpec::Count(n),
                (Some(m), None) => sky::StepSpec::Step(m),
                (None, None) => sky::StepSpec::Step(7.0),
            };
            cli::sun_cmd::SunSource::Solar {
                site: sky::Site::new(lat, lon, elevation),
                date,
                tz_minutes,
                from_min: f64::from(sky::parse_hhmm(&a.from).context("--from")?),
                to_min: f64::from(sky::parse_hhmm(&a.to).context("--to")?),
                steps,
            }
        }
    };
    let north = a.north.as_deref().map(|text| parse_xyz("--north", text)).transpose()?;
    if !(2.0..=10.0).contains(&a.turbidity) {
        bail!("--turbidity {}: expected 2..=10", a.turbidity);
    }
    if a.sky_order > prtbake::sh::MAX_ORDER {
        bail!("--sky-order {}: expected 0..={}", a.sky_order, prtbake::sh::MAX_ORDER);
    }
    if a.refine.refine_noise.is_some() {
        bail!("--refine-noise: sun masks have no noise to discount (each bit is a vote of its samples); it applies to `bake --refine`");
    }
    let params = prtbake::bake::SunParams {
        mode: if a.window_mode || !a.windows.is_empty() { Mode::Window } else { Mode::Open },
        samples_per_vertex: a.samples_per_vertex,
        max_per_triangle: 256,
        seed: a.seed,
        keep_outside_sides: a.keep_outside_sides,
        loop_order: match a.loop_order {
            LoopOrderArg::StepOuter => prtbake::bake::LoopOrder::StepOuter,
            LoopOrderArg::PointOuter => prtbake::bake::LoopOrder::PointOuter,
        },
        shadow_cache: !a.no_shadow_cache,
        packets: !a.no_packets,
        quiet: a.quiet || a.json,
    };
    params.check()?;
    if let Some(size) = a.texel_size.filter(|s| !(s.is_finite() && *s > 0.0)) {
        bail!("--texel-size {size}: expected a positive length in world units (e.g. 0.02 for 2 cm)");
    }
    if let Some(n) = a.texel_points.filter(|n| !(1..=256).contains(n)) {
        bail!("--texel-points {n}: expected 1..=256");
    }
    Ok(cli::sun_cmd::SunConfig {
        texel_density: texel_density(a.texel_levels, a.max_error)?,
        texel_size: a.texel_size,
        texel_points: a.texel_points,
        texel_fractions: a.texel_fractions,
        unwrap: a.unwrap,
        refine: a.refine.request()?,
        shard: a.shard.as_deref().map(prtbake::shards::Shard::parse).transpose()?,
        input: a.input,
        output: a.output,
        up,
        source,
        north,
        turbidity: a.turbidity,
        sky_order: a.sky_order,
        params,
        window_patterns: a.windows,
        threads: a.threads.unwrap_or(0),
        json: a.json,
        force: a.force,
    })
}

#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("light").required(true).args(["env", "sky", "overcast"])))]
struct PanelArgs {
    /// A baked bundle (.prtb) with the panel among its materials.
    bundle: PathBuf,
    /// The panel: materials or groups whose name matches this glob (default: materials with the panel role).
    #[arg(long)]
    panel: Option<String>,
    /// The driver's eye, X,Y,Z in the bundle's frame (metres, +Y up).
    #[arg(long, allow_hyphen_values = true)]
    eye: String,
    /// Environment map (.exr or .hdr, equirect) outside the windows.
    #[arg(long, value_name = "MAP")]
    env: Option<PathBuf>,
    /// The Preetham clear sky and sun at --time (and --date, --tz, --lat, --lon).
    #[arg(long)]
    sky: bool,
    /// The CIE overcast sky (no sun) of --lux horizontal illuminance.
    #[arg(long)]
    overcast: bool,
    /// Horizontal illuminance of --overcast, lux.
    #[arg(long, default_value_t = 10_000.0, requires = "overcast")]
    lux: f64,
    /// Local time HH:MM of --sky.
    #[arg(long, requires = "sky")]
    time: Option<String>,
    /// Local date YYYY-MM-DD of --sky (default 2026-03-20).
    #[arg(long, requires = "sky")]
    date: Option<String>,
    /// UTC offset ±HH:MM of --sky (default: Athens's on that date).
    #[arg(long, allow_hyphen_values = true, requires = "sky")]
    tz: Option<String>,
    /// Latitude of --sky, degrees north (default: the Acropolis).
    #[arg(long, allow_hyphen_values = true, requires = "sky")]
    lat: Option<f64>,
    /// Longitude of --sky, degrees east (default: the Acropolis).
    #[arg(long, allow_hyphen_values = true, requires = "sky")]
    lon: Option<f64>,
    /// Preetham turbidity of --sky, 2..=10.
    #[arg(long, default_value_t = 3.0)]
    turbidity: f64,
    /// The car's heading: turned by this many degrees counter-clockwise (seen from above) under the sky or map.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    yaw: f32,
    /// The panel's BRDF: `antiglare` (the default coating), a text table or a MERL .binary file.
    #[arg(long, default_value = "antiglare")]
    brdf: String,
    /// Texels WxH (default: 256 along the panel's long side, square texels).
    #[arg(long)]
    texels: Option<String>,
    /// Samples per texel (1..=65536).
    #[arg(long, default_value_t = 256)]
    samples: u32,
    /// Seed of the sample streams.
    #[arg(long, default_value_t = 1)]
    seed: u32,
    /// Display white luminance, cd/m² (typical automotive LCD: 500).
    #[arg(long, default_value_t = 500.0)]
    display_white: f32,
    /// Display black luminance, cd/m² (typical: 0.5).
    #[arg(long, default_value_t = 0.5)]
    display_black: f32,
    /// Contrast ratio below which a texel counts as unreadable.
    #[arg(long, default_value_t = 3.0)]
    threshold: f32,
    /// Reflected radiance (.exr); the contrast-ratio map goes beside it as OUT.cr.png unless --contrast says otherwise.
    #[arg(short, long)]
    output: PathBuf,
    /// The contrast-ratio map (.png).
    #[arg(long)]
    contrast: Option<PathBuf>,
    /// Worker threads (0 = all cores). The output does not depend on it.
    #[arg(long, default_value_t = 0, value_parser = parse_threads)]
    threads: usize,
    /// Statistics as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// No progress on stderr.
    #[arg(long, short)]
    quiet: bool,
    /// Replace read-only outputs.
    #[arg(long)]
    force: bool,
}

fn check_lat_lon(lat: f64, lon: f64) -> anyhow::Result<()> {
    if !(-90.0..=90.0).contains(&lat) || !(-180.0..=180.0).contains(&lon) {
        anyhow::bail!("--lat {lat} / --lon {lon}: latitude must be within -90..=90 and longitude within -180..=180");
    }
    Ok(())
}

/// `--date` (default 2026-03-20) and `--tz` (default Athens's offset on that date).
fn date_and_tz(date: Option<&str>, tz: Option<&str>) -> anyhow::Result<(prtbake::sky::LocalDate, i32)> {
    let date = date.map(prtbake::sky::parse_date).transpose()?.unwrap_or_else(prtbake::sky::default_date);
    let tz = tz.map(prtbake::sky::parse_tz).transpose()?.unwrap_or_else(|| prtbake::sky::athens_utc_offset_minutes(date));
    Ok((date, tz))
}

fn parse_xyz(flag: &str, text: &str) -> anyhow::Result<glam::Vec3> {
    use anyhow::{bail, Context};
    let v: Vec<f32> = text
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{flag} {text:?}: expected X,Y,Z"))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        bail!("{flag} {text:?}: expected three finite numbers X,Y,Z");
    }
    Ok(glam::Vec3::new(v[0], v[1], v[2]))
}

fn panel_config(a: PanelArgs) -> anyhow::Result<cli::panel_cmd::PanelConfig> {
    use anyhow::{bail, Context};
    use cli::panel_cmd::PanelLight;
    use prtbake::sky;
    let light = if let Some(path) = a.env {
        PanelLight::Map { path, yaw_deg: a.yaw }
    } else if a.sky {
        let time = a.time.as_deref().context("--sky needs --time HH:MM")?;
        let acropolis = sky::Site::acropolis();
        let (lat, lon) = (a.lat.unwrap_or(acropolis.latitude_deg), a.lon.unwrap_or(acropolis.longitude_deg));
        check_lat_lon(lat, lon)?;
        if !(2.0..=10.0).contains(&a.turbidity) {
            bail!("--turbidity {}: expected 2..=10", a.turbidity);
        }
        let (date, tz_minutes) = date_and_tz(a.date.as_deref(), a.tz.as_deref())?;
        let site = sky::Site::new(lat, lon, acropolis.elevation_m);
        PanelLight::Sky {
            date,
            minutes: sky::parse_hhmm(time).context("--time")?,
            tz_minutes,
            site,
            turbidity: a.turbidity,
            yaw_deg: a.yaw,
        }
    } else {
        if !(a.lux.is_finite() && a.lux > 0.0) {
            bail!("--lux {}: expected a positive illuminance", a.lux);
        }
        PanelLight::Overcast { lux: a.lux }
    };
    if !a.yaw.is_finite() {
        bail!("--yaw {}: expected degrees", a.yaw);
    }
    let texels = parse_texels("--texels", a.texels.as_deref())?;
    let (white, black) = (a.display_white, a.display_black);
    if !(white.is_finite() && black.is_finite() && black >= 0.0 && white > black) {
        bail!("--display-white {white} / --display-black {black}: expected 0 <= black < white (cd/m²)");
    }
    if !(a.threshold.is_finite() && a.threshold >= 1.0) {
        bail!("--threshold {}: expected a contrast ratio >= 1", a.threshold);
    }
    let contrast = a.contrast.unwrap_or_else(|| cli::panel_cmd::contrast_path(&a.output));
    Ok(cli::panel_cmd::PanelConfig {
        bundle: a.bundle,
        panel: a.panel,
        eye: parse_xyz("--eye", &a.eye)?,
        light,
        brdf: (a.brdf != "antiglare").then(|| PathBuf::from(&a.brdf)),
        texels,
        samples: a.samples,
        seed: a.seed,
        display: prtbake::panel::Display { white_cd_m2: white, black_cd_m2: black },
        threshold: a.threshold,
        output: a.output,
        contrast,
        threads: a.threads,
        json: a.json,
        quiet: a.quiet,
        force: a.force,
    })
}

fn run(command: Command) -> anyhow::Result<Outcome> {
    match command {
        Command::Bake(args) => {
            let plan = args.plan_shards;
            let threads_given = args.threads.is_some();
            let config = bake_config(args)?;
            match (plan, &config.shard) {
                (Some(n), _) => {
                    let bake = (config.params.bounces, cli::shard_cmd::has_pilot_stage(&config));
                    cli::shard_cmd::print_plan(n, &config.output, Some(bake), threads_given).map(|_| Outcome::Ok)
                }
                (None, Some(shard)) => cli::shard_cmd::run_transfer(&config, shard).map(|_| Outcome::Ok),
                (None, None) => cli::bake_cmd::run(&config).map(|_| Outcome::Ok),
            }
        }
        Command::Clean(args) => cli::clean_cmd::run(&clean_config(args)?).map(|_| Outcome::Ok),
        Command::Sun(args) => {
            let plan = args.plan_shards;
            let threads_given = args.threads.is_some();
            let config = sun_config(args)?;
            match (plan, config.shard) {
                (Some(n), _) => cli::shard_cmd::print_plan(n, &config.output, None, threads_given).map(|_| Outcome::Ok),
                (None, Some(shard)) => cli::shard_cmd::run_sun(&config, shard).map(|_| Outcome::Ok),
                (None, None) => cli::sun_cmd::run(&config).map(|_| Outcome::Ok),
            }
        }
        Command::Generate { scene, output, detail, copies, force } => {
            cli::generate_cmd::run(&scene, &output, detail.as_deref(), copies, force).map(|_| Outcome::Ok)
        }
        Command::Inspect { bundle, json } => cli::inspect_cmd::run(&bundle, json).map(|_| Outcome::Ok),
        Command::Verify { rays, seed, threads, json } => cli::verify_cmd::run(prtbake::verify::VerifyParams { rays, seed }, threads, json),
        Command::Chart { output, quick, real: true, data, hit_cache_mib, threads, json, force } => {
            cli::chart_cmd::run_real(&output, &data, hit_cache_bytes(hit_cache_mib), quick, threads, json, force)
        }
        Command::Chart { output, quick, real: false, threads, json, force, .. } => {
            cli::chart_cmd::run(&output, quick, threads, json, force)
        }
        Command::Demo { output, threads, json, quiet } => cli::demo_cmd::run(&output, threads, json, quiet),
        Command::View(args) => cli::view_cmd::run(&view_config(args)?).map(|_| Outcome::Ok),
        Command::Panel(args) => cli::panel_cmd::run(&panel_config(args)?).map(|_| Outcome::Ok),
        Command::Merge { parts, output, layer, threads, force, json } => {
            cli::merge_cmd::run(&cli::merge_cmd::MergeConfig { parts, output, layer, threads, json, force }).map(|_| Outcome::Ok)
        }
        Command::Export { bundle, output, layer, json, force } => {
            cli::export_cmd::run(&bundle, &output, cli::export_cmd::parse_layer(&layer)?, json, force).map(|_| Outcome::Ok)
        }
    }
}

fn main() -> ExitCode {
    // Die quietly on a closed pipe (`prtbake inspect … | head`), like other Unix tools,
    // instead of panicking on the failed write.
    #[cfg(target_os = "linux")]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Ctrl-C or SIGTERM removes this run's temporary outputs and exits 130/143.
    if let Err(e) = prtbake::files::install_interrupt_cleanup() {
        eprintln!("warning: cannot install the interrupt handler ({e}); an interrupted run may leave .prtbake-*.tmp files");
    }
    let parsed = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    match run(parsed.command) {
        Ok(Outcome::Ok) => ExitCode::SUCCESS,
        Ok(Outcome::CheckFailed) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            ExitCode::from(2)
        }
    }
}

/// `--hit-cache-mib` in bytes, or half the memory available now when not given.
fn hit_cache_bytes(mib: Option<u64>) -> u64 {
    mib.map_or_else(prtbake::bake::transfer::available_hit_cache_bytes, |mib| mib.saturating_mul(1 << 20))
}

/// The error and its causes, joined with ": ". Library errors already put
/// their I/O cause in their own message, so a cause the text so far already
/// contains is not repeated.
fn error_chain(e: &anyhow::Error) -> String {
    let mut message = e.to_string();
    for cause in e.chain().skip(1) {
        let text = cause.to_string();
        if !message.contains(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
    }
    message
}
