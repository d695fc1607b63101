//! How much of the light the camera sees has crossed the object: the share of the power that
//! enters the surface where it faces away from the camera (issue 57's validity, from the scene).
//! A diffusion profile is least accurate there: on the translucent family's development scenes
//! the defaults were 9–16% too dark lit from behind, 13–16% too bright lit from the front
//! (docs/guide/translucency.md). Facing is judged by the normal against the direction to the
//! eye (or the orthographic view), without occlusion: an estimate from the scene, before a
//! pixel is rendered.

use crate::sss::octree::Source;
use crate::support::geometry::{dot, sub};
use crate::support::raytrace::camera::CameraParams;

/// The share of the entering light over which `sss.render` warns: most of it.
pub(super) const WARN: f64 = 0.5;

/// The share of the sources' power (summed over channels) entering where the surface faces away
/// from the camera; `None` without power. `sources` are in mm, the camera in world units of
/// `unit` mm.
pub(super) fn share(sources: &[Source], camera: &CameraParams, unit: f64) -> Option<f64> {
    let view = sub(camera.target, camera.eye);
    let (mut away, mut all) = (0.0, 0.0);
    for s in sources {
        let power: f64 = s.power.iter().sum();
        let to_eye = match camera.orthographic {
            Some(_) => view.map(|v| -v),
            None => sub(camera.eye, s.p.map(|v| v / unit)),
        };
        all += power;
        if dot(s.n, to_eye) <= 0.0 {
            away += power;
        }
    }
    (all > 0.0 && all.is_finite()).then(|| away / all)
}

/// The warning where the share is over [`WARN`].
pub(super) fn warning(share: f64) -> Option<String> {
    (share > WARN).then(|| {
        format!(
            "{:.0}% of the light enters where the camera does not see the surface (lit from behind): what the camera sees has crossed the object, where a diffusion profile is least accurate (the defaults were 9–16% too dark on back-lit development scenes); brute force (render.reference with the medium) or `mesoflow plan --against truth` measures it",
            share * 100.0
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn source(z: f64, nz: f64, power: f64) -> Source {
        Source {
            p: [0.0, 0.0, z],
            n: [0.0, 0.0, nz],
            power: [power; 3],
        }
    }

    #[test]
    fn the_share_is_the_power_entering_where_the_surface_faces_away() {
        let camera = CameraParams {
            eye: [0.0, 0.0, 5.0],
            target: [0.0, 0.0, 0.0],
            ..CameraParams::default()
        };
        // A front (facing the eye at +z) and a back (facing −z) sample, at 1 mm a unit.
        let front = source(1.0, 1.0, 1.0);
        let back = source(-1.0, -1.0, 3.0);
        assert_eq!(share(&[front, back], &camera, 1.0), Some(0.75));
        assert_eq!(share(&[front], &camera, 1.0), Some(0.0));
        assert!(warning(0.75).unwrap().starts_with("75%"));
        assert!(warning(0.25).is_none());
        // Positions are in mm: at 10 mm a unit the eye is 50 mm away, so a sample at 60 mm
        // facing +z faces away from it.
        let beyond = source(60.0, 1.0, 1.0);
        assert_eq!(share(&[beyond], &camera, 10.0), Some(1.0));
        assert_eq!(share(&[], &camera, 1.0), None);
    }
}
