//! The one light of a scene: directional (irradiance `intensity` on a plane facing it) or a point
//! light (intensity with 1/r² falloff), as parameters and resolved, for `render.mesh`,
//! `sss.render`, `qh.render` and the planner.

use crate::support::geometry::{dot, normalize, sub, V3};
use mesoflow_runtime::NodeError;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct LightParams {
    /// Direction towards a directional light (world, need not be unit length).
    pub direction: [f64; 3],
    /// Position of a point light; when set the light is a point light with 1/r² falloff.
    pub position: Option<[f64; 3]>,
    /// Irradiance on a plane facing a directional light (or intensity of a point light).
    #[schemars(range(min = 0.0))]
    pub intensity: f64,
}

impl Default for LightParams {
    fn default() -> Self {
        LightParams {
            direction: [0.6, 0.7, 0.9],
            position: None,
            intensity: 3.0,
        }
    }
}

/// A checked light: unit direction, optional position, intensity.
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    /// Unit direction towards a directional light.
    pub direction: V3,
    /// Position of a point light (then `direction` only breaks ties at the light itself).
    pub position: Option<V3>,
    pub intensity: f64,
}

impl Light {
    /// Errors name the parameter `light`.
    pub fn new(p: &LightParams) -> Result<Light, NodeError> {
        let direction = normalize(p.direction)
            .ok_or_else(|| NodeError::param("light", "direction has zero length"))?;
        if !(p.intensity >= 0.0 && p.intensity.is_finite()) {
            return Err(NodeError::param(
                "light",
                "intensity must be finite and not negative",
            ));
        }
        if p.position.is_some_and(|q| q.iter().any(|v| !v.is_finite())) {
            return Err(NodeError::param("light", "position must be finite"));
        }
        Ok(Light {
            direction,
            position: p.position,
            intensity: p.intensity,
        })
    }

    /// Unit direction towards the light and the irradiance on a surface facing it, at `x`.
    pub fn at(&self, x: V3) -> (V3, f64) {
        match self.position {
            None => (self.direction, self.intensity),
            Some(q) => {
                let d = sub(q, x);
                let r2 = dot(d, d).max(1e-30);
                (normalize(d).unwrap_or(self.direction), self.intensity / r2)
            }
        }
    }

    /// How far along `l` (the direction `at` gave at `x`) the light lies: the length a shadow
    /// ray must clear; infinite for a directional light.
    pub fn reach(&self, x: V3, l: V3) -> f64 {
        self.position.map_or(f64::INFINITY, |q| dot(sub(q, x), l))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_light_falls_off_as_inverse_square() {
        let l = Light::new(&LightParams {
            position: Some([0.0, 0.0, 2.0]),
            intensity: 8.0,
            ..Default::default()
        })
        .unwrap();
        let (d, e) = l.at([0.0; 3]);
        assert_eq!(d, [0.0, 0.0, 1.0]);
        assert!((e - 2.0).abs() < 1e-12);
    }

    #[test]
    fn bad_lights_name_the_parameter() {
        for p in [
            LightParams {
                direction: [0.0; 3],
                ..Default::default()
            },
            LightParams {
                intensity: -1.0,
                ..Default::default()
            },
            LightParams {
                intensity: f64::NAN,
                ..Default::default()
            },
        ] {
            assert!(Light::new(&p).unwrap_err().to_string().contains("light"));
        }
    }
}
