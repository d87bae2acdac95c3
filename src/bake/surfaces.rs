//! What each triangle is to light: opaque with an albedo, or a window with a
//! glass transmittance. Windows come from material roles (glTF
//! KHR_materials_transmission) and from `--window` globs on material or group names.

use crate::mesh::{MaterialRole, Mesh};

/// Per-triangle optical roles, resolved once before the bake.
#[derive(Clone, Debug)]
pub struct Surfaces {
    /// Window transmittance per triangle; `None` for opaque triangles.
    pub window_transmittance: Vec<Option<f32>>,
    /// Albedo (linear RGB) per triangle.
    pub albedo: Vec<[f32; 3]>,
    /// Names of the materials and groups that became windows, for the report.
    pub window_names: Vec<String>,
    /// Per triangle: its back side reflects nothing in bounces (`--one-sided`);
    /// otherwise a diffuse surface reflects on whichever side light reaches it.
    pub one_sided: Vec<bool>,
}

/// Error for a malformed `--window` pattern.
#[derive(Debug, thiserror::Error)]
#[error("invalid --window pattern {pattern:?}: {message}")]
pub struct PatternError {
    pub pattern: String,
    pub message: String,
}

impl Surfaces {
    /// Resolves roles. A triangle is a window when its material has role
    /// `Window`, or its material name or group name matches any glob in
    /// `window_patterns`. A pattern may end in `=TAU` to set the glass
    /// transmittance of what it matches (`Glass_Gray=0.7`); otherwise the
    /// material's own (1 unless the file says otherwise) applies.
    pub fn resolve(mesh: &Mesh, window_patterns: &[String]) -> Result<Surfaces, PatternError> {
        let patterns = window_patterns.iter().map(|p| parse_pattern(p)).collect::<Result<Vec<_>, _>>()?;
        let matches = |name: &str| patterns.iter().any(|(p, _)| p.matches(name));
        // The transmittance the first matching pattern sets, if any.
        let tau_of = |name: &str| patterns.iter().find(|(p, _)| p.matches(name)).and_then(|(_, tau)| *tau);
        let material_is_window: Vec<bool> = mesh.materials.iter().map(|m| m.role == MaterialRole::Window || matches(&m.name)).collect();
        let group_is_window: Vec<bool> = mesh.groups.iter().map(|g| matches(g)).collect();
        let mut window_names: Vec<String> =
            mesh.materials.iter().zip(&material_is_window).filter(|(_, &w)| w).map(|(m, _)| format!("material {}", m.name)).collect();
        window_names.extend(mesh.groups.iter().zip(&group_is_window).filter(|(_, &w)| w).map(|(g, _)| format!("group {g}")));
        let triangle_count = mesh.triangle_count();
        let mut window_transmittance = Vec::with_capacity(triangle_count);
        let mut albedo = Vec::with_capacity(triangle_count);
        for t in 0..triangle_count {
            let material = &mesh.materials[mesh.tri_material[t] as usize];
            let group = &mesh.groups[mesh.tri_group[t] as usize];
            let is_window = material_is_window[mesh.tri_material[t] as usize] || group_is_window[mesh.tri_group[t] as usize];
            let tau = tau_of(&material.name).or_else(|| tau_of(group)).unwrap_or(material.transmittance);
            window_transmittance.push(is_window.then_some(tau.clamp(0.0, 1.0)));
            albedo.push(material.albedo.map(|a| a.clamp(0.0, 1.0)));
        }
        Ok(Surfaces { window_transmittance, albedo, window_names, one_sided: vec![false; triangle_count] })
    }

    /// These surfaces with the triangles whose material or group name matches
    /// a glob of `patterns` made one-sided (`--one-sided`).
    pub fn with_one_sided(mut self, mesh: &Mesh, patterns: &[String]) -> Result<Surfaces, PatternError> {
        let patterns = patterns.iter().map(|p| parse_pattern(p)).collect::<Result<Vec<_>, _>>()?;
        if let Some((glob, Some(_))) = patterns.iter().find(|(_, tau)| tau.is_some()) {
            return Err(PatternError { pattern: glob.as_str().into(), message: "a one-sided pattern takes no =TAU".into() });
        }
        let matches = |name: &str| patterns.iter().any(|(p, _)| p.matches(name));
        let by_material: Vec<bool> = mesh.materials.iter().map(|m| matches(&m.name)).collect();
        let by_group: Vec<bool> = mesh.groups.iter().map(|g| matches(g)).collect();
        self.one_sided = (0..mesh.triangle_count())
            .map(|t| by_material[mesh.tri_material[t] as usize] || by_group[mesh.tri_group[t] as usize])
            .collect();
        Ok(self)
    }

    /// `mesh` with the window role (and the pattern's transmittance) on every
    /// material that `window_patterns` match by name, so a bundle says which
    /// glass was a window (`inspect`, the viewer, the panel gather) without
    /// its patterns. A pattern that matches only group names cannot be a
    /// material role; META `window_patterns` keeps those.
    pub fn with_window_roles(mesh: &Mesh, window_patterns: &[String]) -> Result<Mesh, PatternError> {
        let patterns = window_patterns.iter().map(|p| parse_pattern(p)).collect::<Result<Vec<_>, _>>()?;
        let mut marked = mesh.clone();
        for material in &mut marked.materials {
            if let Some((_, tau)) = patterns.iter().find(|(p, _)| p.matches(&material.name)) {
                material.role = MaterialRole::Window;
                material.transmittance = tau.unwrap_or(material.transmittance).clamp(0.0, 1.0);
            }
        }
        Ok(marked)
    }

    /// Number of window triangles.
    pub fn window_triangle_count(&self) -> usize {
        self.window_transmittance.iter().filter(|w| w.is_some()).count()
    }

    /// True when every opaque triangle's albedo is grey (one channel suffices).
    pub fn all_grey(&self) -> bool {
        self.albedo
            .iter()
            .zip(&self.window_transmittance)
            .filter(|(_, w)| w.is_none())
            .all(|(a, _)| (a[0] - a[1]).abs() < 1e-6 && (a[1] - a[2]).abs() < 1e-6)
    }
}

/// Splits `PATTERN[=TAU]` into a glob and an optional transmittance in [0, 1].
fn parse_pattern(text: &str) -> Result<(glob::Pattern, Option<f32>), PatternError> {
    let error = |message: String| PatternError { pattern: text.to_string(), message };
    let (glob_text, tau) = match text.rsplit_once('=') {
        Some((g, t)) => {
            let tau: f32 = t.trim().parse().map_err(|_| error(format!("transmittance {t:?} is not a number")))?;
            if !(0.0..=1.0).contains(&tau) {
                return Err(error(format!("transmittance {tau} is outside 0..=1")));
            }
            (g, Some(tau))
        }
        None => (text, None),
    };
    let pattern = glob::Pattern::new(glob_text).map_err(|e| error(e.to_string()))?;
    Ok((pattern, tau))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Material, MaterialRole};

    fn two_triangles() -> Mesh {
        let mut m = crate::verify::shapes::plane_grid(1, 1.0);
        m.materials = vec![Material::opaque("Body", 0.5), Material::opaque("Glass_Gray", 0.5)];
        m.tri_material = vec![0, 1];
        m
    }

    #[test]
    fn globs_select_windows_and_set_transmittance() {
        let m = two_triangles();
        let s = Surfaces::resolve(&m, &["Glass*".into()]).unwrap();
        assert_eq!(s.window_transmittance, vec![None, Some(1.0)]);
        let s = Surfaces::resolve(&m, &["Glass_Gray=0.7".into()]).unwrap();
        assert_eq!(s.window_transmittance, vec![None, Some(0.7)]);
        let s = Surfaces::resolve(&m, &[]).unwrap();
        assert_eq!(s.window_triangle_count(), 0);
        assert!(Surfaces::resolve(&m, &["Glass=1.5".into()]).is_err());
        assert!(Surfaces::resolve(&m, &["Glass=x".into()]).is_err());
        assert!(Surfaces::resolve(&m, &["[".into()]).is_err());
    }

    #[test]
    fn material_role_makes_a_window_without_patterns() {
        let mut m = two_triangles();
        m.materials[1].role = MaterialRole::Window;
        m.materials[1].transmittance = 0.4;
        let s = Surfaces::resolve(&m, &[]).unwrap();
        assert_eq!(s.window_transmittance, vec![None, Some(0.4)]);
    }
}
