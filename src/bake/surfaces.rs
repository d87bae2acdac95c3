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
    /// `Window`, or its material name or group name matches any glob in `window_patterns`.
    pub fn resolve(mesh: &Mesh, window_patterns: &[String]) -> Result<Surfaces, PatternError> {
        let patterns = window_patterns
            .iter()
            .map(|p| glob::Pattern::new(p).map_err(|e| PatternError { pattern: p.clone(), message: e.to_string() }))
            .collect::<Result<Vec<_>, _>>()?;
        let matches = |name: &str| patterns.iter().any(|p| p.matches(name));
        let material_is_window: Vec<bool> =
            mesh.materials.iter().map(|m| m.role == MaterialRole::Window || matches(&m.name)).collect();
        let group_is_window: Vec<bool> = mesh.groups.iter().map(|g| matches(g)).collect();
        let mut window_names: Vec<String> = mesh
            .materials
            .iter()
            .zip(&material_is_window)
            .filter(|(_, &w)| w)
            .map(|(m, _)| format!("material {}", m.name))
            .collect();
        window_names.extend(mesh.groups.iter().zip(&group_is_window).filter(|(_, &w)| w).map(|(g, _)| format!("group {g}")));
        let triangle_count = mesh.triangle_count();
        let mut window_transmittance = Vec::with_capacity(triangle_count);
        let mut albedo = Vec::with_capacity(triangle_count);
        for t in 0..triangle_count {
            let material = &mesh.materials[mesh.tri_material[t] as usize];
            let is_window =
                material_is_window[mesh.tri_material[t] as usize] || group_is_window[mesh.tri_group[t] as usize];
            window_transmittance.push(is_window.then_some(material.transmittance.clamp(0.0, 1.0)));
            albedo.push(material.albedo.map(|a| a.clamp(0.0, 1.0)));
        }
        Ok(Surfaces { window_transmittance, albedo, window_names })
    }

    /// Number of window triangles.
    pub fn window_triangle_count(&self) -> usize {
        self.window_transmittance.iter().filter(|w| w.is_some()).count()
    }

    /// True when every opaque triangle's albedo is grey (one channel suffices).
    pub fn all_grey(&self) -> bool {
        self.albedo.iter().zip(&self.window_transmittance).filter(|(_, w)| w.is_none()).all(|(a, _)| {
            (a[0] - a[1]).abs() < 1e-6 && (a[1] - a[2]).abs() < 1e-6
        })
    }
}
