//! Cameras: a pinhole (look-at, vertical field of view) or an orthographic view, as pixel rays.
//! Pixel (x, y) has its centre at (x + 0.5, y + 0.5), row 0 at the top. The renderer measures
//! depth as the distance `t` along the unit ray, for both projections.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::support::geometry::{add, cross, dot, mul, normalize, sub, V3};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct CameraParams {
    /// Camera position, world units.
    pub eye: [f64; 3],
    /// The point the camera looks at.
    pub target: [f64; 3],
    /// Up direction of the image (need not be orthogonal to the view).
    pub up: [f64; 3],
    /// Vertical field of view, degrees (pinhole).
    #[schemars(range(min = 0.01, max = 179.0))]
    pub fov: f64,
    /// Half the view's height in world units; when set, the camera is orthographic.
    pub orthographic: Option<f64>,
    /// Image [width, height] in pixels.
    pub resolution: [u32; 2],
}

impl Default for CameraParams {
    fn default() -> Self {
        CameraParams {
            eye: [0.0, 0.6, 3.2],
            target: [0.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov: 40.0,
            orthographic: None,
            resolution: [400, 300],
        }
    }
}

impl CameraParams {
    /// The centre of this view at `resolution` pixels and the same pixels per degree: the field
    /// of view (or an orthographic view's height) narrowed with the frame's height, so each
    /// pixel sees what the same pixel of the full view sees (a probe of the view's centre).
    pub fn centre_crop(&self, resolution: [u32; 2]) -> CameraParams {
        let ratio = resolution[1] as f64 / self.resolution[1].max(1) as f64;
        let mut c = self.clone();
        match self.orthographic {
            Some(h) => c.orthographic = Some(h * ratio),
            None => {
                let half = (self.fov.to_radians() * 0.5).tan() * ratio;
                c.fov = (2.0 * half.atan()).to_degrees();
            }
        }
        c.resolution = resolution;
        c
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub eye: V3,
    pub forward: V3,
    pub right: V3,
    pub up: V3,
    /// tan(fov/2) for a pinhole, the half height for an orthographic camera.
    pub half: f64,
    pub orthographic: bool,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    pub fn new(p: &CameraParams) -> Result<Camera, String> {
        let forward = normalize(sub(p.target, p.eye)).ok_or("eye and target coincide")?;
        let right =
            normalize(cross(forward, p.up)).ok_or("up is parallel to the view direction")?;
        let up = cross(right, forward);
        let [width, height] = p.resolution;
        if width == 0 || height == 0 {
            return Err(format!("resolution {width}×{height} has no pixels"));
        }
        let half = match p.orthographic {
            Some(h) if h > 0.0 && h.is_finite() => h,
            Some(h) => return Err(format!("orthographic half height {h} must be positive")),
            None if p.fov > 0.0 && p.fov < 179.0 => (p.fov.to_radians() * 0.5).tan(),
            None => return Err(format!("fov {}° is not in (0°, 179°)", p.fov)),
        };
        Ok(Camera {
            eye: p.eye,
            forward,
            right,
            up,
            half,
            orthographic: p.orthographic.is_some(),
            width,
            height,
        })
    }

    /// A camera looking along `dir` at a sphere (`centre`, `radius`), which fills its view:
    /// orthographic for a directional light, a pinhole at `from` for a point light.
    pub fn enclosing(
        centre: V3,
        radius: f64,
        dir: V3,
        from: Option<V3>,
        size: u32,
    ) -> Result<Camera, String> {
        let (eye, half, ortho) = match from {
            None => (sub(centre, mul(dir, 2.0 * radius + 1.0)), radius, true),
            Some(p) => {
                let dist = dot(sub(centre, p), sub(centre, p)).sqrt();
                if dist <= radius * 1.0001 {
                    return Err("the point light is inside the mesh's bounding sphere".into());
                }
                (p, (radius / dist).asin().tan() * 1.02, false)
            }
        };
        let up = if dir[1].abs() < 0.9 {
            [0.0, 1.0, 0.0]
        } else {
            [1.0, 0.0, 0.0]
        };
        let right = normalize(cross(dir, up)).ok_or("degenerate light direction")?;
        Ok(Camera {
            eye,
            forward: dir,
            right,
            up: cross(right, dir),
            half,
            orthographic: ortho,
            width: size,
            height: size,
        })
    }

    /// Screen offsets of pixel (x, y)'s centre: (horizontal, vertical) in units of `half`.
    fn screen(&self, x: f64, y: f64) -> (f64, f64) {
        let aspect = self.width as f64 / self.height as f64;
        (
            (2.0 * x / self.width as f64 - 1.0) * aspect,
            1.0 - 2.0 * y / self.height as f64,
        )
    }

    /// Origin and unit direction of the ray through pixel (x, y)'s centre.
    pub fn ray(&self, x: u32, y: u32) -> (V3, V3) {
        self.ray_at(x as f64 + 0.5, y as f64 + 0.5)
    }

    /// Origin and unit direction of the ray through continuous pixel coordinates (x, y) (pixel
    /// (i, j) spans [i, i + 1] × [j, j + 1]).
    pub fn ray_at(&self, x: f64, y: f64) -> (V3, V3) {
        let (sx, sy) = self.screen(x, y);
        if self.orthographic {
            let o = add(
                self.eye,
                add(
                    mul(self.right, sx * self.half),
                    mul(self.up, sy * self.half),
                ),
            );
            (o, self.forward)
        } else {
            let d = add(
                self.forward,
                add(
                    mul(self.right, sx * self.half),
                    mul(self.up, sy * self.half),
                ),
            );
            (self.eye, normalize(d).unwrap_or(self.forward))
        }
    }

    /// Continuous pixel coordinates of a world point and its distance along that pixel's ray;
    /// `None` behind a pinhole.
    pub fn project(&self, p: V3) -> Option<(f64, f64, f64)> {
        let rel = sub(p, self.eye);
        let z = dot(rel, self.forward);
        let (sx, sy, t) = if self.orthographic {
            (
                dot(rel, self.right) / self.half,
                dot(rel, self.up) / self.half,
                z,
            )
        } else {
            if z <= 0.0 {
                return None;
            }
            (
                dot(rel, self.right) / (z * self.half),
                dot(rel, self.up) / (z * self.half),
                dot(rel, rel).sqrt(),
            )
        };
        let aspect = self.width as f64 / self.height as f64;
        let x = (sx / aspect + 1.0) * 0.5 * self.width as f64;
        let y = (1.0 - sy) * 0.5 * self.height as f64;
        Some((x, y, t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_inverts_ray() {
        for ortho in [None, Some(1.5)] {
            let c = Camera::new(&CameraParams {
                orthographic: ortho,
                resolution: [64, 48],
                ..Default::default()
            })
            .unwrap();
            let (o, d) = c.ray(10, 30);
            let p = add(o, mul(d, 2.7));
            let (x, y, t) = c.project(p).unwrap();
            assert!(
                (x - 10.5).abs() < 1e-9 && (y - 30.5).abs() < 1e-9,
                "{x} {y}"
            );
            let expected_t = if ortho.is_some() {
                dot(sub(p, c.eye), c.forward)
            } else {
                2.7
            };
            assert!((t - expected_t).abs() < 1e-9);
        }
    }

    #[test]
    fn a_centre_crop_sees_the_full_view_s_centre_pixels() {
        // Pixel (x, y) of the crop is pixel (x + dx, y + dy) of the full view: the same ray.
        for ortho in [None, Some(1.5)] {
            let full = CameraParams {
                orthographic: ortho,
                resolution: [64, 48],
                ..Default::default()
            };
            let crop = full.centre_crop([16, 12]);
            let (f, c) = (Camera::new(&full).unwrap(), Camera::new(&crop).unwrap());
            let (of, df) = f.ray(24 + 3, 18 + 5);
            let (oc, dc) = c.ray(3, 5);
            for k in 0..3 {
                assert!((df[k] - dc[k]).abs() < 1e-12 && (of[k] - oc[k]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn bad_cameras_are_refused() {
        let p = CameraParams {
            eye: [0.0; 3],
            target: [0.0; 3],
            ..Default::default()
        };
        assert!(Camera::new(&p).unwrap_err().contains("coincide"));
        let p = CameraParams {
            resolution: [0, 4],
            ..Default::default()
        };
        assert!(Camera::new(&p).is_err());
    }
}
