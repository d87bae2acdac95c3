//! A look-at perspective camera and the interactive controls that move it:
//! orbit around a target (left drag, wheel) and fly (WASD/QE, right drag).
//!
//! Clip space is wgpu's: right-handed view, depth 0..1, y up.

use glam::{Mat4, Vec3, Vec4};

/// A perspective camera looking from `eye` at `target`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    /// World up used to orient the image (+Y).
    pub up: Vec3,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
    /// Near and far clip distances (> 0, near < far).
    pub near: f32,
    pub far: f32,
}

impl Camera {
    /// A camera at `eye` looking at `target`, with clip planes for a scene of
    /// bounds `(lo, hi)`: far reaches past the whole scene, near is 10⁻⁴ of far
    /// (enough depth precision with a 32-bit float depth buffer).
    pub fn look_at(eye: Vec3, target: Vec3, bounds: (Vec3, Vec3)) -> Camera {
        let centre = (bounds.0 + bounds.1) * 0.5;
        let diagonal = (bounds.1 - bounds.0).length().max(1e-6);
        let far = (eye - centre).length() + diagonal * 1.5;
        Camera { eye, target, up: Vec3::Y, fov_y_deg: 50.0, near: far * 1e-4, far }
    }

    /// A view of the whole scene from the front-right and above (+X, +Y, +Z side).
    pub fn fit(bounds: (Vec3, Vec3)) -> Camera {
        let centre = (bounds.0 + bounds.1) * 0.5;
        let radius = ((bounds.1 - bounds.0).length() * 0.5).max(1e-6);
        let direction = Vec3::new(0.55, 0.45, 0.7).normalize();
        Camera::look_at(centre + direction * radius * 2.4, centre, bounds)
    }

    /// Parses `EX,EY,EZ,TX,TY,TZ` (six numbers: eye then target).
    pub fn parse_eye_target(text: &str) -> Result<(Vec3, Vec3), String> {
        let values: Vec<f32> = text
            .split(',')
            .map(|s| s.trim().parse::<f32>().map_err(|_| format!("--camera {text:?}: {s:?} is not a number")))
            .collect::<Result<_, _>>()?;
        if values.len() != 6 || values.iter().any(|v| !v.is_finite()) {
            return Err(format!("--camera {text:?}: expected six finite numbers EYE_X,EYE_Y,EYE_Z,TARGET_X,TARGET_Y,TARGET_Z"));
        }
        let (eye, target) = (Vec3::from_slice(&values[..3]), Vec3::from_slice(&values[3..]));
        if (eye - target).length() <= 0.0 {
            return Err(format!("--camera {text:?}: eye and target coincide"));
        }
        Ok((eye, target))
    }

    /// The camera as `--camera` text.
    pub fn to_arg(&self) -> String {
        let (e, t) = (self.eye, self.target);
        format!("{},{},{},{},{},{}", e.x, e.y, e.z, t.x, t.y, t.z)
    }

    /// An up vector not parallel to the view direction.
    fn safe_up(&self) -> Vec3 {
        let forward = (self.target - self.eye).normalize_or(Vec3::NEG_Z);
        if forward.cross(self.up).length_squared() < 1e-8 {
            Vec3::Z
        } else {
            self.up
        }
    }

    /// World → clip transform for an image of `aspect` = width / height.
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        // WebGPU clip space: right-handed view, depth 0..1, y up (glam's DirectX/WebGPU convention).
        let projection = glam::camera::rh::proj::directx::perspective(self.fov_y_deg.to_radians(), aspect, self.near, self.far);
        projection * glam::camera::rh::view::look_at_mat4(self.eye, self.target, self.safe_up().normalize())
    }

    /// Unit forward, and right and up scaled so that `forward + x·right + y·up`
    /// is the view ray through NDC `(x, y)` (what the backdrop pass draws).
    pub fn ray_basis(&self, aspect: f32) -> (Vec3, Vec3, Vec3) {
        let forward = (self.target - self.eye).normalize_or(Vec3::NEG_Z);
        let right = forward.cross(self.safe_up().normalize()).normalize();
        let up = right.cross(forward);
        let tan = (self.fov_y_deg.to_radians() * 0.5).tan();
        (forward, right * (tan * aspect), up * tan)
    }

    /// Pixel coordinates (x right, y down, pixel centres at +0.5) of a world
    /// point in a `width × height` image; `None` behind the camera.
    pub fn project(&self, point: Vec3, width: u32, height: u32) -> Option<(f32, f32)> {
        let clip = self.view_proj(width as f32 / height as f32) * point.extend(1.0);
        if clip.w <= 0.0 {
            return None;
        }
        let ndc = clip / clip.w;
        Some(((ndc.x + 1.0) * 0.5 * width as f32, (1.0 - ndc.y) * 0.5 * height as f32))
    }

    /// The ray through pixel position `(x, y)` (same coordinates as [`Camera::project`]):
    /// origin on the near plane and unit direction.
    pub fn pixel_ray(&self, x: f32, y: f32, width: u32, height: u32) -> (Vec3, Vec3) {
        let inverse = self.view_proj(width as f32 / height as f32).inverse();
        let ndc_x = x / width as f32 * 2.0 - 1.0;
        let ndc_y = 1.0 - y / height as f32 * 2.0;
        let unproject = |z: f32| {
            let p = inverse * Vec4::new(ndc_x, ndc_y, z, 1.0);
            p.truncate() / p.w
        };
        let (near, far) = (unproject(0.0), unproject(1.0));
        (near, (far - near).normalize())
    }
}

/// Interactive controls: orbit (yaw/pitch/distance around the target) and fly
/// (move eye and target together, or turn the view around the eye).
#[derive(Clone, Copy, Debug)]
pub struct CameraControl {
    pub camera: Camera,
    /// Units per second for fly moves (a fifth of the scene diagonal).
    pub speed: f32,
}

impl CameraControl {
    pub fn new(camera: Camera, bounds: (Vec3, Vec3)) -> CameraControl {
        CameraControl { camera, speed: ((bounds.1 - bounds.0).length() * 0.2).max(1e-3) }
    }

    fn offset_angles(&self) -> (f32, f32, f32) {
        let offset = self.camera.eye - self.camera.target;
        let distance = offset.length().max(1e-6);
        (offset.x.atan2(offset.z), (offset.y / distance).clamp(-1.0, 1.0).asin(), distance)
    }

    fn from_angles(yaw: f32, pitch: f32) -> Vec3 {
        Vec3::new(pitch.cos() * yaw.sin(), pitch.sin(), pitch.cos() * yaw.cos())
    }

    /// Orbits the eye around the target by `(dyaw, dpitch)` radians (pitch kept within ±89°).
    pub fn orbit(&mut self, dyaw: f32, dpitch: f32) {
        let (yaw, pitch, distance) = self.offset_angles();
        let pitch = (pitch + dpitch).clamp(-1.55, 1.55);
        self.camera.eye = self.camera.target + Self::from_angles(yaw + dyaw, pitch) * distance;
    }

    /// Turns the view direction around the eye (fly look) by `(dyaw, dpitch)` radians.
    pub fn look(&mut self, dyaw: f32, dpitch: f32) {
        let (yaw, pitch, distance) = self.offset_angles();
        let pitch = (pitch - dpitch).clamp(-1.55, 1.55);
        self.camera.target = self.camera.eye - Self::from_angles(yaw + dyaw, pitch) * distance;
    }

    /// Moves toward the target by `factor` of the distance (wheel); never past it.
    pub fn dolly(&mut self, factor: f32) {
        let offset = self.camera.eye - self.camera.target;
        self.camera.eye = self.camera.target + offset * (1.0 - factor).clamp(0.05, 20.0);
    }

    /// Flies eye and target together: `forward`, `right`, `up` in units of `speed · dt`.
    pub fn fly(&mut self, forward: f32, right: f32, up: f32, dt: f32) {
        let f = (self.camera.target - self.camera.eye).normalize_or(Vec3::NEG_Z);
        let r = f.cross(Vec3::Y).normalize_or(Vec3::X);
        let step = (f * forward + r * right + Vec3::Y * up) * self.speed * dt;
        self.camera.eye += step;
        self.camera.target += step;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_ray_goes_through_projected_point() {
        let bounds = (Vec3::splat(-1.0), Vec3::splat(1.0));
        let camera = Camera::look_at(Vec3::new(1.0, 2.0, 5.0), Vec3::ZERO, bounds);
        let point = Vec3::new(0.3, -0.2, 0.4);
        let (x, y) = camera.project(point, 160, 90).unwrap();
        let (origin, dir) = camera.pixel_ray(x, y, 160, 90);
        let to_point = point - origin;
        assert!(to_point.cross(dir).length() < 1e-4 * to_point.length(), "ray misses the point");
    }

    #[test]
    fn ray_basis_matches_pixel_rays() {
        let bounds = (Vec3::splat(-1.0), Vec3::splat(1.0));
        let camera = Camera::look_at(Vec3::new(1.0, 2.0, 5.0), Vec3::new(0.2, 0.1, -0.3), bounds);
        let (w, h) = (160, 90);
        let (forward, right, up) = camera.ray_basis(w as f32 / h as f32);
        for (x, y) in [(0.5, 0.5), (80.0, 45.0), (159.5, 12.25), (3.0, 89.5)] {
            let (_, dir) = camera.pixel_ray(x, y, w, h);
            let (ndc_x, ndc_y) = (x / w as f32 * 2.0 - 1.0, 1.0 - y / h as f32 * 2.0);
            let from_basis = (forward + right * ndc_x + up * ndc_y).normalize();
            assert!(from_basis.dot(dir) > 1.0 - 1e-6, "({x}, {y}): {from_basis} vs {dir}");
        }
    }

    #[test]
    fn orbit_keeps_distance_and_target() {
        let bounds = (Vec3::splat(-1.0), Vec3::splat(1.0));
        let mut control = CameraControl::new(Camera::fit(bounds), bounds);
        let before = (control.camera.eye - control.camera.target).length();
        control.orbit(0.7, -0.3);
        assert!(((control.camera.eye - control.camera.target).length() - before).abs() < 1e-4);
        assert_eq!(control.camera.target, Vec3::ZERO);
    }

    #[test]
    fn parse_camera_argument() {
        let (eye, target) = Camera::parse_eye_target("0,1.2,1.5, 0,0.9,-2").unwrap();
        assert_eq!(eye, Vec3::new(0.0, 1.2, 1.5));
        assert_eq!(target, Vec3::new(0.0, 0.9, -2.0));
        assert!(Camera::parse_eye_target("1,2,3").is_err());
        assert!(Camera::parse_eye_target("1,2,3,1,2,3").is_err());
    }
}
