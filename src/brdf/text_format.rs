//! The text format of a measured isotropic BRDF table (docs/panel.md, "BRDF
//! formats"): a `prtbake-brdf 1` line, the three axes of the grid, then one
//! `theta_in theta_out delta_phi r g b` line per grid point. Every refusal
//! names the file and the line; nothing here panics on any input.

use super::BrdfError;
use std::path::Path;

/// The first word of a table file.
pub const MAGIC: &str = "prtbake-brdf";
/// The format version this reader understands.
pub const VERSION: u32 = 1;
/// Largest number of nodes on one axis (0.1° steps over 180°).
pub const MAX_AXIS_NODES: usize = 1801;
/// Largest grid (θ_in × θ_out × Δφ nodes): 4 Mi points, about 100 MB once
/// loaded with its sampling tables; a 1° grid is 91 × 91 × 181 = 1.5 Mi.
pub const MAX_GRID_POINTS: usize = 1 << 22;
/// Largest accepted BRDF value, in 1/sr (a mirror-like peak measured at
/// 0.01 sr is 1e2; beyond 1e9 the sums in f32 lose the rest of the table).
pub const MAX_VALUE: f64 = 1e9;
/// Closest two nodes of an axis may be, in degrees.
pub const MIN_NODE_SPACING_DEG: f64 = 0.01;
/// A sample's coordinate matches a node within this many degrees.
const NODE_TOLERANCE_DEG: f64 = 1e-4;

/// The three axes, in the order of a sample line.
const AXES: [(&str, f64); 3] = [("theta_in_deg", 90.0), ("theta_out_deg", 90.0), ("delta_phi_deg", 180.0)];

/// A parsed table: node positions in degrees and RGB values in 1/sr.
#[derive(Clone, Debug, PartialEq)]
pub struct TableGrid {
    pub theta_in_deg: Vec<f32>,
    pub theta_out_deg: Vec<f32>,
    pub delta_phi_deg: Vec<f32>,
    /// `values[(out · n_in + in) · n_phi + phi]`: θ_out outermost, since the
    /// sampler works on one θ_out row at a time.
    pub values: Vec<[f32; 3]>,
}

/// Where each grid point's sample was given, while reading.
struct Samples {
    axes: [Vec<f64>; 3],
    values: Vec<[f32; 3]>,
    /// 1-based line of each point's sample, 0 while missing.
    line_of: Vec<u32>,
}

/// Parses a table read from `path` (named in errors).
pub fn parse_table(bytes: &[u8], path: &Path) -> Result<TableGrid, BrdfError> {
    let at = |line: usize, message: String| BrdfError::Line { path: path.to_path_buf(), line, message };
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let mut header_seen = false;
    let mut axes: [Option<(Vec<f64>, usize)>; 3] = [None, None, None];
    let mut samples: Option<Samples> = None;
    for (index, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = index + 1;
        let text = std::str::from_utf8(raw).map_err(|_| at(line, "not UTF-8 text".into()))?;
        let content = text.split('#').next().unwrap_or("").trim();
        let Some(first) = content.split_ascii_whitespace().next() else { continue };
        if !header_seen {
            parse_header(content).map_err(|m| at(line, m))?;
            header_seen = true;
        } else if first.parse::<f64>().is_err() && first.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
            let axis = AXES.iter().position(|(name, _)| *name == first).ok_or_else(|| {
                at(
                    line,
                    format!("unknown keyword {:?} (expected theta_in_deg, theta_out_deg, delta_phi_deg or a sample line)", excerpt(first)),
                )
            })?;
            if let Some((_, earlier)) = &axes[axis] {
                return Err(at(line, format!("{first} given twice (first on line {earlier})")));
            }
            axes[axis] = Some((parse_axis(content, AXES[axis]).map_err(|m| at(line, m))?, line));
            if axes.iter().all(Option::is_some) {
                let declared = axes.clone().map(|a| a.map(|(nodes, _)| nodes).unwrap_or_default());
                samples = Some(Samples::new(declared).map_err(|m| at(line, m))?);
            }
        } else {
            let Some(samples) = samples.as_mut() else {
                let missing: Vec<&str> = AXES.iter().zip(&axes).filter(|(_, a)| a.is_none()).map(|((name, _), _)| *name).collect();
                return Err(at(line, format!("sample line before the grid is declared (missing {})", missing.join(", "))));
            };
            samples.add(content, line).map_err(|m| at(line, m))?;
        }
    }
    let whole = |message: String| BrdfError::Malformed { path: path.to_path_buf(), message };
    if !header_seen {
        return Err(whole(format!("no `{MAGIC} {VERSION}` line: not a BRDF table (MERL files are read when named *.binary)")));
    }
    let Some(samples) = samples else {
        let missing: Vec<&str> = AXES.iter().zip(&axes).filter(|(_, a)| a.is_none()).map(|((name, _), _)| *name).collect();
        return Err(whole(format!("the grid is not declared (missing {})", missing.join(", "))));
    };
    samples.finish().map_err(whole)
}

/// Checks `prtbake-brdf 1`.
fn parse_header(content: &str) -> Result<(), String> {
    let tokens: Vec<&str> = content.split_ascii_whitespace().collect();
    if tokens.first() != Some(&MAGIC) {
        return Err(format!("expected `{MAGIC} {VERSION}` before anything but comments, found {:?}", excerpt(content)));
    }
    match tokens[1..] {
        [v] if v.parse::<u32>() == Ok(VERSION) => Ok(()),
        [v] => Err(format!("unsupported version {:?} (this prtbake reads version {VERSION})", excerpt(v))),
        _ => Err(format!("expected `{MAGIC} {VERSION}`, found {:?}", excerpt(content))),
    }
}

/// The nodes of one axis line: finite, within [0, max], increasing by at
/// least [`MIN_NODE_SPACING_DEG`], at most [`MAX_AXIS_NODES`].
fn parse_axis(content: &str, (name, max): (&str, f64)) -> Result<Vec<f64>, String> {
    let mut nodes = Vec::new();
    for token in content.split_ascii_whitespace().skip(1) {
        if nodes.len() == MAX_AXIS_NODES {
            return Err(format!("{name}: more than {MAX_AXIS_NODES} values"));
        }
        let x = token
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{name}: {:?} is not a finite number", excerpt(token)))?;
        if !(0.0..=max).contains(&x) {
            return Err(format!("{name}: {x} is outside [0, {max}] degrees"));
        }
        if let Some(&last) = nodes.last() {
            if x < last + MIN_NODE_SPACING_DEG {
                return Err(format!("{name}: values must increase by at least {MIN_NODE_SPACING_DEG} degrees, found {last} then {x}"));
            }
        }
        nodes.push(x);
    }
    if nodes.is_empty() {
        return Err(format!("{name}: no values"));
    }
    Ok(nodes)
}

impl Samples {
    fn new(axes: [Vec<f64>; 3]) -> Result<Samples, String> {
        let [a, b, c] = [axes[0].len(), axes[1].len(), axes[2].len()];
        let count = a.checked_mul(b).and_then(|ab| ab.checked_mul(c)).filter(|&n| n <= MAX_GRID_POINTS);
        let count = count.ok_or_else(|| format!("grid of {a} × {b} × {c} points is over the limit of {MAX_GRID_POINTS}"))?;
        Ok(Samples { axes, values: vec![[0.0; 3]; count], line_of: vec![0; count] })
    }

    /// One `theta_in theta_out delta_phi r g b` line.
    fn add(&mut self, content: &str, line: usize) -> Result<(), String> {
        let fields: Vec<&str> = content.split_ascii_whitespace().collect();
        if fields.len() != 6 {
            return Err(format!("expected 6 fields `theta_in theta_out delta_phi r g b`, found {}", fields.len()));
        }
        let mut node = [0usize; 3];
        for (axis, field) in fields[..3].iter().enumerate() {
            let name = AXES[axis].0.trim_end_matches("_deg");
            let x = field
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{name} {:?} is not a finite number", excerpt(field)))?;
            node[axis] = nearest_node(&self.axes[axis], x).ok_or_else(|| format!("{name} {x} is not a node of {}", AXES[axis].0))?;
        }
        let mut rgb = [0.0f32; 3];
        for ((slot, field), channel) in rgb.iter_mut().zip(&fields[3..]).zip(["r", "g", "b"]) {
            let v = field
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("{channel} value {:?} is not a finite number", excerpt(field)))?;
            if v < 0.0 {
                return Err(format!("{channel} value {v} is negative (a BRDF is ≥ 0; write 0 for unmeasured points)"));
            }
            if v > MAX_VALUE {
                return Err(format!("{channel} value {v} is over {MAX_VALUE:e} 1/sr"));
            }
            *slot = v as f32;
        }
        let [n_in, n_phi] = [self.axes[0].len(), self.axes[2].len()];
        let index = (node[1] * n_in + node[0]) * n_phi + node[2];
        if self.line_of[index] != 0 {
            return Err(format!(
                "duplicate sample for theta_in {} theta_out {} delta_phi {} (first on line {})",
                fields[0], fields[1], fields[2], self.line_of[index]
            ));
        }
        self.line_of[index] = u32::try_from(line).unwrap_or(u32::MAX);
        self.values[index] = rgb;
        Ok(())
    }

    /// Every grid point must have its sample.
    fn finish(self) -> Result<TableGrid, String> {
        let missing = self.line_of.iter().filter(|&&l| l == 0).count();
        if let Some(first) = self.line_of.iter().position(|&l| l == 0) {
            let [n_in, n_phi] = [self.axes[0].len(), self.axes[2].len()];
            let (out, rest) = (first / (n_in * n_phi), first % (n_in * n_phi));
            let (i, p) = (rest / n_phi, rest % n_phi);
            return Err(format!(
                "{missing} of {} grid points have no sample line; the first is theta_in {} theta_out {} delta_phi {}",
                self.line_of.len(),
                self.axes[0][i],
                self.axes[1][out],
                self.axes[2][p]
            ));
        }
        let to_f32 = |v: &Vec<f64>| v.iter().map(|&x| x as f32).collect();
        Ok(TableGrid {
            theta_in_deg: to_f32(&self.axes[0]),
            theta_out_deg: to_f32(&self.axes[1]),
            delta_phi_deg: to_f32(&self.axes[2]),
            values: self.values,
        })
    }
}

/// Index of the node within [`NODE_TOLERANCE_DEG`] of `x`, if any.
fn nearest_node(nodes: &[f64], x: f64) -> Option<usize> {
    let above = nodes.partition_point(|&n| n < x);
    [above.checked_sub(1), Some(above)]
        .into_iter()
        .flatten()
        .filter(|&i| i < nodes.len())
        .find(|&i| (nodes[i] - x).abs() <= NODE_TOLERANCE_DEG)
}

/// At most 40 characters of `s`, for messages about hostile lines.
fn excerpt(s: &str) -> String {
    match s.char_indices().nth(40) {
        Some((cut, _)) => format!("{}…", &s[..cut]),
        None => s.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Brdf, TabulatedBrdf};
    use super::*;

    const SMALL: &str = "# a 2 x 2 x 2 table\nprtbake-brdf 1\ntheta_in_deg 0 60\ntheta_out_deg 0 60\ndelta_phi_deg 0 180\n\
        0 0 0 0.1 0.2 0.3\n0 0 180 0.1 0.2 0.3\n60 0 0 0.1 0.2 0.3\n60 0 180 0.1 0.2 0.3\n\
        0 60 0 0.1 0.2 0.3\n0 60 180 0.1 0.2 0.3\n60 60 0 0.1 0.2 0.3\n60 60 180 1 2 3 # peak\n";

    fn refusal(text: &str) -> String {
        parse_table(text.as_bytes(), Path::new("panel.brdf")).map(|_| ()).unwrap_err().to_string()
    }

    /// `SMALL` with line `line` (1-based) replaced.
    fn with_line(line: usize, replacement: &str) -> String {
        SMALL.lines().enumerate().map(|(i, l)| if i + 1 == line { replacement } else { l }).collect::<Vec<_>>().join("\n")
    }

    #[test]
    fn the_small_table_parses_with_comments_crlf_and_a_bom() {
        let grid = parse_table(SMALL.as_bytes(), Path::new("panel.brdf")).unwrap();
        assert_eq!(grid.theta_in_deg, [0.0, 60.0]);
        assert_eq!(grid.values[7], [1.0, 2.0, 3.0]);
        let crlf = format!("\u{feff}{}", SMALL.replace('\n', "\r\n"));
        assert_eq!(parse_table(crlf.as_bytes(), Path::new("panel.brdf")).unwrap(), grid);
    }

    #[test]
    fn bad_lines_are_refused_naming_the_file_and_line() {
        let cases = [
            (with_line(6, "0 0 0 nan 0.2 0.3"), "panel.brdf:6: r value \"nan\" is not a finite number"),
            (with_line(7, "0 0 180 0.1 -0.2 0.3"), "panel.brdf:7: g value -0.2 is negative"),
            (with_line(8, "60 0 0 0.1 0.2"), "panel.brdf:8: expected 6 fields `theta_in theta_out delta_phi r g b`, found 5"),
            (with_line(8, "60 0 0 0.1 0.2 0.3 0.4"), "panel.brdf:8: expected 6 fields"),
            (with_line(9, "60 0 180 0.1 0.2 inf"), "panel.brdf:9: b value \"inf\" is not a finite number"),
            (with_line(9, "60 0 180 0.1 0.2 1e10"), "panel.brdf:9: b value 10000000000 is over"),
            (with_line(10, "30 60 0 0.1 0.2 0.3"), "panel.brdf:10: theta_in 30 is not a node of theta_in_deg"),
            (
                with_line(10, "0 0 0 0.1 0.2 0.3"),
                "panel.brdf:10: duplicate sample for theta_in 0 theta_out 0 delta_phi 0 (first on line 6)",
            ),
            (with_line(10, "thetain 0 0"), "panel.brdf:10: unknown keyword \"thetain\""),
            (with_line(2, "prtbake-brdf 2"), "panel.brdf:2: unsupported version \"2\""),
            (with_line(2, "0 0 0 1 1 1"), "panel.brdf:2: expected `prtbake-brdf 1`"),
            (with_line(3, "theta_in_deg 0 95"), "panel.brdf:3: theta_in_deg: 95 is outside [0, 90] degrees"),
            (with_line(4, "theta_out_deg 60 0"), "panel.brdf:4: theta_out_deg: values must increase"),
            (with_line(5, "delta_phi_deg"), "panel.brdf:5: delta_phi_deg: no values"),
            (with_line(5, "delta_phi_deg 0 x"), "panel.brdf:5: delta_phi_deg: \"x\" is not a finite number"),
            (with_line(5, "theta_in_deg 0 60"), "panel.brdf:5: theta_in_deg given twice (first on line 3)"),
            (with_line(5, "# no delta_phi"), "panel.brdf:6: sample line before the grid is declared (missing delta_phi_deg)"),
            (with_line(13, "60 60 180 1 2 3 \u{fffd}"), "panel.brdf:13: expected 6 fields"),
            (
                with_line(13, "# last sample gone"),
                "panel.brdf: 1 of 8 grid points have no sample line; the first is theta_in 60 theta_out 60 delta_phi 180",
            ),
            (String::new(), "panel.brdf: no `prtbake-brdf 1` line"),
            ("prtbake-brdf 1\ntheta_in_deg 0\n".into(), "panel.brdf: the grid is not declared (missing theta_out_deg, delta_phi_deg)"),
        ];
        for (text, expected) in cases {
            let message = refusal(&text);
            assert!(message.starts_with(expected), "expected {expected:?}, got {message:?}");
        }
        let mut bytes = SMALL.as_bytes().to_vec();
        bytes.splice(0..0, b"# caf\xe9\n".iter().copied());
        let message = parse_table(&bytes, Path::new("panel.brdf")).unwrap_err().to_string();
        assert_eq!(message, "panel.brdf:1: not UTF-8 text");
    }

    #[test]
    fn oversized_grids_are_refused_before_allocating() {
        let axis = |name: &str, n: usize, step: f64| {
            format!("{name} {}", (0..n).map(|k| (k as f64 * step).to_string()).collect::<Vec<_>>().join(" "))
        };
        let text = format!(
            "prtbake-brdf 1\n{}\n{}\n{}\n",
            axis("theta_in_deg", 1801, 0.05),
            axis("theta_out_deg", 1801, 0.05),
            axis("delta_phi_deg", 3, 1.0)
        );
        assert_eq!(refusal(&text), "panel.brdf:4: grid of 1801 × 1801 × 3 points is over the limit of 4194304");
        let text = format!("prtbake-brdf 1\n{}\n", axis("delta_phi_deg", 1802, 0.05));
        assert_eq!(refusal(&text), "panel.brdf:2: delta_phi_deg: more than 1801 values");
    }

    #[test]
    fn loading_a_file_names_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("short.brdf");
        std::fs::write(&path, with_line(8, "60 0 0 0.1 0.2")).unwrap();
        let message = TabulatedBrdf::load(&path).unwrap_err().to_string();
        assert_eq!(message, format!("{}:8: expected 6 fields `theta_in theta_out delta_phi r g b`, found 5", path.display()));
        let message = TabulatedBrdf::load(&dir.path().join("missing.brdf")).unwrap_err().to_string();
        assert!(message.starts_with(&format!("{}: cannot read", dir.path().join("missing.brdf").display())), "{message}");
        let message = TabulatedBrdf::load(dir.path()).unwrap_err().to_string();
        assert!(message.contains("a directory"), "{message}");
    }

    #[test]
    fn mutated_tables_are_loaded_or_refused_never_panic() {
        let base = SMALL.as_bytes();
        let mut accepted = 0;
        for case in 0..20_000u32 {
            let mut bytes = base.to_vec();
            let h = |k: u32| crate::sampling::hash_seed(&[case, k]) as usize;
            for k in 0..1 + h(0) % 4 {
                let at = h(10 + k as u32) % bytes.len().max(1);
                match h(20 + k as u32) % 4 {
                    0 => bytes[at] = b"0123456789 .-e#\nnx"[h(30 + k as u32) % 18],
                    1 => bytes[at] = h(40 + k as u32) as u8,
                    2 => drop(bytes.remove(at)),
                    _ => bytes.truncate(at),
                }
                if bytes.is_empty() {
                    break;
                }
            }
            if let Ok(brdf) = TabulatedBrdf::parse(&bytes, Path::new("fuzz.brdf")) {
                accepted += 1;
                let wo = glam::Vec3::new(0.3, 0.1, 0.9).normalize();
                let f = brdf.eval(glam::Vec3::new(-0.2, 0.4, 0.8).normalize(), wo);
                assert!(f.iter().all(|x| x.is_finite() && *x >= 0.0), "{f:?}");
                if let Some(s) = brdf.sample(wo, [0.37, 0.81]) {
                    assert!(s.pdf.is_finite() && s.pdf > 0.0 && s.wi.z > 0.0);
                }
            }
        }
        println!("text table fuzzing: {accepted} of 20000 mutated tables accepted");
        assert!(accepted > 0);
    }
}
